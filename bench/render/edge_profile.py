"""What a render setting adds at a marker's edge: the colour score's profile across the disc's minor
axis, per side, one render of the same frames against another (default against the converged
reference).

    python -m bench.render.edge_profile DEF[+DEF] REF[+REF] [--markers A6,B5,B6,B2] [--exr]

DEF and REF: datasets of the same config but their render settings (the same scenes and cameras,
frame for frame). For each fully visible marker of the list in each test frame: the detector's
colour score (detector.centre.colour_score, on the stored 8-bit images, as the refinement reads
them) of both renders in a window around it, each pixel placed by the label's exact disc ellipse
(solver.disc_noise.disc_ellipses): its signed distance (px) outside the true edge along the minor
axis, on the side toward the image's top (+1) or bottom (-1), for pixels within 0.35 of the
semi-major axis of the minor axis line; the score normalised by the reference's median disc score.
With ``--exr`` the score is taken from the kept EXR instead (the render's linear radiance before the
camera chain: the same score on it), which separates what the render adds from what the sensor's
chain (noise, clipping, encoding) does to it.
Printed per marker and side: the reference's profile, and the mean per-frame difference DEF - REF
(x 1000) with its standard error over the frames, in 0.25 px bins from 2 px inside to 3 px outside.
A difference of opposite sign on the two sides of the edge moves the fitted edge there, and so the
centre along the minor axis; the same difference on both scenes is systematic, not noise.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import cv2
import numpy as np

from dockfactory.core.names import CLASS_CHANNELS
from dockfactory.detector.centre import colour_score
from dockfactory.generator.exr import read_compact
from dockfactory.solver.disc_noise import disc_ellipses

BINS = np.arange(-2.0, 3.01, 0.25)   # px outside the true edge along the minor axis
NEAR_MINOR = 0.35                    # pixels within this share of the semi-major axis of the minor axis line


def marker_geometry(label: dict, marker: dict) -> tuple[float, float, np.ndarray, np.ndarray]:
    """(minor semi-axis px, major semi-axis px, minor axis unit (2,), major axis unit (2,)) of a
    label marker's exact disc ellipse, the minor axis pointing toward the image's top."""
    cam = np.asarray(label["camera"]["cam_from_d"], dtype=float)
    c = np.asarray(marker["center_d_mm"]) @ cam[:3, :3].T + cam[:3, 3]
    n = np.asarray(marker["normal_d"]) @ cam[:3, :3].T
    w, v = np.linalg.eigh(disc_ellipses(c[None], n[None], [marker["diameter_mm"]], label["camera"]["focal_px"])[0])
    u_min = v[:, 0] if v[1, 0] <= 0 else -v[:, 0]
    return float(np.sqrt(w[0])), float(np.sqrt(w[1])), u_min, v[:, 1]


def linear_score(rgb: np.ndarray, class_id: int) -> np.ndarray:
    """colour_score's definition on linear radiance (h, w, 3): the class channel minus the mean of the others."""
    c = CLASS_CHANNELS[class_id]
    o1, o2 = (rgb[..., k] for k in range(3) if k != c)
    return rgb[..., c] - 0.5 * (o1 + o2)


def read_image(root: Path, frame_id: str, exr: bool) -> np.ndarray:
    """The frame's stored 8-bit RGB image, or its kept EXR's linear RGB (float64)."""
    if exr:
        return read_compact(root / "exr" / f"{frame_id}.exr").rgb.astype(np.float64)
    return cv2.imread(str(root / "images" / f"{frame_id}.png"))[..., ::-1]


def marker_profile(img_def: np.ndarray, img_ref: np.ndarray, label: dict, marker: dict) -> dict | None:
    """{(side, bin): (mean reference score, mean difference)} of one marker in one frame (normalised
    by the reference's median disc score); None near the image's border."""
    b, a, u_min, u_maj = marker_geometry(label, marker)
    cx, cy = marker["center_px"]
    x0, x1, y0, y1 = int(cx - a - 6), int(cx + a + 7), int(cy - a - 6), int(cy + a + 7)
    if x0 < 0 or y0 < 0 or x1 > img_def.shape[1] or y1 > img_def.shape[0]:
        return None
    score = colour_score if img_def.dtype == np.uint8 else linear_score
    sd = score(img_def[y0:y1, x0:x1], marker["class_id"])
    sr = score(img_ref[y0:y1, x0:x1], marker["class_id"])
    ys, xs = np.mgrid[y0:y1, x0:x1]
    e = np.stack([xs - cx, ys - cy], -1)
    t, u = e @ u_min, e @ u_maj
    disc = float(np.median(sr[(t / b) ** 2 + (u / a) ** 2 < 0.5]))
    out = {}
    for side in (1, -1):
        dist = side * t - b * np.sqrt(np.clip(1 - (u / a) ** 2, 0, 1))
        k = np.digitize(dist, BINS) - 1
        for j in range(len(BINS) - 1):
            sel = (np.abs(u) < NEAR_MINOR * a) & (side * t > 0) & (k == j)
            if sel.any():
                out[(side, j)] = (float(sr[sel].mean() / disc), float((sd[sel] - sr[sel]).mean() / disc))
    return out


def profiles(pairs: list[tuple[Path, Path]], ids: list[str], exr: bool = False) -> dict:
    """{(marker id, side, bin): [(reference, difference) per frame]} over the test frames of every pair."""
    acc: dict = {}
    for d, r in pairs:
        for path in sorted((d / "labels").glob("*.json")):
            label = json.loads(path.read_text())
            if label["spec"]["split"] != "test" or not (r / "labels" / path.name).exists():
                continue
            img_d, img_r = read_image(d, path.stem, exr), read_image(r, path.stem, exr)
            for m in label["markers"]:
                if m["id"] in ids and m.get("visible_fraction", 0.0) >= 0.99:
                    for (side, j), v in (marker_profile(img_d, img_r, label, m) or {}).items():
                        acc.setdefault((m["id"], side, j), []).append(v)
    return acc


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("default", help="dataset folder(s), joined by +")
    ap.add_argument("reference", help="the same frames rendered otherwise, joined by + in the same order")
    ap.add_argument("--markers", default="A6,B5,B6,B2")
    ap.add_argument("--exr", action="store_true", help="the kept EXR's linear radiance, not the stored image")
    args = ap.parse_args()
    pairs = list(zip(map(Path, args.default.split("+")), map(Path, args.reference.split("+"))))
    ids = args.markers.split(",")
    acc = profiles(pairs, ids, args.exr)
    print("| marker | side | row | " + " | ".join(f"{v:+.2f}" for v in BINS[:-1]) + " |")
    print("|" + " --- |" * (len(BINS) + 2))
    for mid in ids:
        for side in (1, -1):
            cells = {j: np.asarray(acc[(mid, side, j)]) for j in range(len(BINS) - 1) if (mid, side, j) in acc}
            ref = [f"{cells[j][:, 0].mean():.2f}" if j in cells else "" for j in range(len(BINS) - 1)]
            diff = [f"{1000 * cells[j][:, 1].mean():+.1f} ({1000 * cells[j][:, 1].std(ddof=1) / np.sqrt(len(cells[j])):.1f})"
                    if j in cells and len(cells[j]) > 1 else "" for j in range(len(BINS) - 1)]
            print(f"| {mid} | {side:+d} | reference | " + " | ".join(ref) + " |")
            print(f"| {mid} | {side:+d} | default - reference (x 1000, SE) | " + " | ".join(diff) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
