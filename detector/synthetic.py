"""Tiny synthetic datasets in dockfactory's layout (no Blender): coloured discs in dark rings on noise.

For the detector's own tests (library level: ``train``, ``detect_dataset``): they are not
dockfactory datasets (no plan, no manifest), so ``Dataset.open`` and every command refuse them;
``SyntheticDataset`` is their stand-in for an opened dataset (detector.data.FrameSource). Discs are drawn with exact area coverage
(supersampled 8 x 8 per pixel) in the OpenCV pixel convention, so ``center_px`` and ``bbox_px``
of the labels are exact up to the supersampling.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from dockfactory.core.cv import cv2
import numpy as np

from dockfactory.core.io import write_bytes_atomic, write_json_atomic

RED, BLUE, RING = (200, 25, 25), (30, 50, 210), (25, 25, 25)


def disc_coverage(h: int, w: int, cx: float, cy: float, r: float, ss: int = 8) -> np.ndarray:
    """``(h, w) float32`` share of each pixel inside the circle (OpenCV convention, pixel (x, y)
    covers [x - 0.5, x + 0.5] x [y - 0.5, y + 0.5])."""
    off = (np.arange(ss) + 0.5) / ss - 0.5
    ys = np.arange(h)[:, None, None, None] + off[None, None, :, None]
    xs = np.arange(w)[None, :, None, None] + off[None, None, None, :]
    return (((xs - cx) ** 2 + (ys - cy) ** 2) <= r * r).mean(axis=(2, 3)).astype(np.float32)


def make_frame(rng: np.random.Generator, width: int, height: int, n_markers: int, r_range=(5.0, 9.0)):
    """(image (H, W, 3) uint8 RGB, markers list of label dicts)."""
    img = rng.normal(150, 25, (height, width, 3)).clip(0, 255).astype(np.float32)
    img = cv2.GaussianBlur(img, (0, 0), 1.5)
    markers, centres = [], []
    for k in range(200):
        if len(markers) == n_markers:
            break
        r = rng.uniform(*r_range)
        ring = r * 1.3
        cx, cy = rng.uniform(ring + 2, width - ring - 3), rng.uniform(ring + 2, height - ring - 3)
        if any(np.hypot(cx - x, cy - y) < ring + rr + 3 for x, y, rr in centres):
            continue
        centres.append((cx, cy, ring))
        cls = len(markers) % 2
        for rad, col in ((ring, RING), (r, RED if cls == 0 else BLUE)):
            a = disc_coverage(height, width, cx, cy, rad)[..., None]
            img = img * (1 - a) + np.array(col, np.float32) * a
        markers.append({"id": f"{'AB'[cls]}{len(markers)}", "section": "AB"[cls], "class_id": cls,
                        "center_px": [cx, cy], "bbox_px": [cx - r, cy - r, cx + r, cy + r],
                        "visible_pixels": int(np.pi * r * r), "visible_fraction": 1.0, "visibility": 2,
                        "in_frame": True, "area_px": float(np.pi * r * r), "area_in_frame_px": float(np.pi * r * r)})
    img = img + rng.normal(0, 3, img.shape)
    return img.clip(0, 255).round().astype(np.uint8), markers


@dataclass(frozen=True)
class SyntheticDataset:
    """A synthetic dataset folder, read like an opened dataset (labels in frame-id order)."""
    root: Path
    version_id: str

    def labels_of(self, split: str | None = None) -> list[dict]:
        labels = [json.loads(p.read_text()) for p in sorted((self.root / "labels").glob("*.json"))]
        return [lab for lab in labels if split is None or lab["spec"]["split"] == split]


def write_synthetic_dataset(root, frames: int = 4, width: int = 128, height: int = 128, markers: int = 4,
                            seed: int = 0, test_every: int = 0, r_range=(5.0, 9.0)) -> SyntheticDataset:
    """A dataset folder ``root`` with ``frames`` frames; every ``test_every``-th frame is 'test'
    (0: all 'train')."""
    root = Path(root)
    version = f"synthetic-{seed}-{frames}-{width}x{height}-{markers}"
    write_json_atomic(root / "synthetic.json", {"format": "dockfactory.synthetic/1", "version_id": version})
    for i in range(frames):
        rng = np.random.default_rng([seed, i])
        img, ms = make_frame(rng, width, height, markers, r_range)
        fid = f"{i:06d}"
        ok, png = cv2.imencode(".png", cv2.cvtColor(img, cv2.COLOR_RGB2BGR))
        write_bytes_atomic(root / "images" / f"{fid}.png", png.tobytes())
        split = "test" if test_every and i % test_every == test_every - 1 else "train"
        write_json_atomic(root / "labels" / f"{fid}.json", {
            "frame_id": fid, "spec": {"frame_id": fid, "index": i, "split": split,
                                      "condition": "normal" if i % 3 else "low_light"},
            "image": {"width": width, "height": height}, "markers": ms})
    return SyntheticDataset(root, version)
