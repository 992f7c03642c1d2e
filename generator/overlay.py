"""Draw a frame's labels over its image, to look at a dataset (pure OpenCV)."""
from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np

from dockfactory.core.io import write_bytes_atomic
from dockfactory.generator.dataset import DatasetError

COLORS = {"A": (60, 60, 255), "B": (255, 160, 40)}  # BGR


def draw_overlay(root, frame_id: str, out) -> str:
    """Draw frame ``frame_id`` of dataset ``root`` into the PNG ``out``; DatasetError (one line)
    for a folder that is not a dataset, a frame it does not have, or an unreadable label/image."""
    root = Path(root)
    if not (root / "dataset.json").is_file():
        raise DatasetError(f"{root}: not a dockfactory dataset (no dataset.json)")
    label_path = root / "labels" / f"{frame_id}.json"
    image_path = root / "images" / f"{frame_id}.png"
    plain = frame_id and frame_id == Path(frame_id).name and not frame_id.startswith(".")
    if not plain or not label_path.is_file() or not image_path.is_file():
        raise DatasetError(f"{root}: no frame {frame_id!r} in this dataset (frame ids are the names "
                           f"of its labels/*.json with an image, e.g. 000000 or rep000_00)")
    try:
        label = json.loads(label_path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise DatasetError(f"{label_path}: unreadable label ({exc})") from None
    img = cv2.imread(str(image_path))
    if img is None:
        raise DatasetError(f"{image_path}: unreadable image")
    try:
        _draw(img, frame_id, label)
    except (KeyError, TypeError, ValueError, IndexError, AttributeError, cv2.error) as exc:
        raise DatasetError(f"{label_path}: not a frame label ({type(exc).__name__}: {exc})") from None
    ok, png = cv2.imencode(".png", img)
    if not ok:
        raise DatasetError(f"{image_path}: cannot encode the overlay as PNG")
    write_bytes_atomic(out, png.tobytes())
    return str(out)


def _draw(img, frame_id: str, label: dict) -> None:
    shift = 4  # sub-pixel drawing: coordinates in 1/16 px
    s = 1 << shift
    for m in label["markers"]:
        color = COLORS[m["section"]]
        if m.get("bbox_px"):
            x0, y0, x1, y1 = m["bbox_px"]
            cv2.rectangle(img, (round(x0 * s), round(y0 * s)), (round(x1 * s), round(y1 * s)),
                          color, 1, cv2.LINE_AA, shift)
        u, v = m["center_px"]
        if np.isfinite(u) and np.isfinite(v):
            cv2.drawMarker(img, (int(round(u)), int(round(v))), color, cv2.MARKER_CROSS, 8, 1)
            cv2.putText(img, f"{m['id']} v{m.get('visibility', '?')} {m.get('visible_fraction', 0):.2f}",
                        (int(u) + 12, int(v) - 8), cv2.FONT_HERSHEY_SIMPLEX, 0.4, color, 1, cv2.LINE_AA)
    p = label["pose_b_in_d"]
    text = (f"{frame_id} {','.join(label['conditions'])}  f={label['camera']['focal_px']:.0f}px  "
            f"X={p['x_mm']:.1f} Y={p['y_mm']:.1f} Z={p['z_mm']:.1f} mm  a={p['alpha_deg']:.2f} "
            f"b={p['beta_deg']:.2f} g={p['gamma_deg']:.2f} deg")
    cv2.putText(img, text, (10, 22), cv2.FONT_HERSHEY_SIMPLEX, 0.55, (255, 255, 255), 1, cv2.LINE_AA)
