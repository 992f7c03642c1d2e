"""Draw a frame's labels over its image, to look at a dataset (pure OpenCV)."""
from __future__ import annotations

import json
from pathlib import Path

from dockfactory.core.cv import cv2
import numpy as np

from dockfactory.core.config import config_from_identity
from dockfactory.core.io import write_bytes_atomic
from dockfactory.generator.datasets.folder import DatasetError, load_identity
from dockfactory.generator.datasets.dvc_links import cache_link, dvc_caches
from dockfactory.generator.sampler import frame_plan

COLORS = {"A": (60, 60, 255), "B": (255, 160, 40)}  # BGR


def frame_files_to_show(root: Path, frame_id: str) -> tuple[Path, Path]:
    """(label, image) paths of a planned frame of the dataset at ``root`` (finished or still being
    rendered); DatasetError for a folder that is not a dataset, a frame id outside its plan, a
    frame not rendered yet, or a file that is a symlink other than a DVC cache link (a dataset's
    files live inside it)."""
    ident = load_identity(root, required=("config",))
    plan = {s.frame_id for s in frame_plan(config_from_identity(ident["config"], str(root / "dataset.json")))}
    if frame_id not in plan:
        raise DatasetError(f"{root}: no frame {frame_id!r} in this dataset's plan "
                           f"(frame ids look like 000000 or rep000_00; {len(plan)} planned)")
    label_path = root / "labels" / f"{frame_id}.json"
    image_path = root / "images" / f"{frame_id}.png"
    for path in (label_path, image_path):
        if path.parent.is_symlink() or (path.is_symlink() and cache_link(path, dvc_caches(root)) is None):
            raise DatasetError(f"{path}: is a symlink (not into a DVC cache); a dataset's files live inside it")
    if not label_path.is_file() or not image_path.is_file():
        raise DatasetError(f"{root}: frame {frame_id} is not rendered yet (no label or no image)")
    return label_path, image_path


OVERLAY_SUFFIXES = {".png": ".png", ".jpg": ".jpg", ".jpeg": ".jpg"}   # --out's suffix -> the format written


def draw_overlay(root, frame_id: str, out) -> str:
    """Draw frame ``frame_id`` of dataset ``root`` into ``out``, in the format its suffix names
    (.png, .jpg or .jpeg; another suffix is refused before any work); DatasetError (one line)
    for a folder that is not a dataset, a frame it does not have, or an unreadable label/image."""
    root = Path(root)
    fmt = OVERLAY_SUFFIXES.get(Path(out).suffix.lower())
    if fmt is None:
        raise DatasetError(f"--out {out}: unknown image type {Path(out).suffix or '(no suffix)'!r}; "
                           f"give a name ending in {', '.join(OVERLAY_SUFFIXES)}")
    label_path, image_path = frame_files_to_show(root, frame_id)
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
    ok, data = cv2.imencode(fmt, img, [cv2.IMWRITE_JPEG_QUALITY, 95] if fmt == ".jpg" else [])
    if not ok:
        raise DatasetError(f"{image_path}: cannot encode the overlay as {fmt[1:].upper()}")
    write_bytes_atomic(out, data.tobytes())
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
