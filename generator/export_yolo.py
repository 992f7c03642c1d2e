"""YOLO export in the layout ultralytics reads.

exports/yolo/
  images/{train,test,repeat}/<id>.png   (hard links to the dataset's images)
  labels/{train,test,repeat}/<id>.txt   one line per marker: class cx cy w h (normalised)
  train.txt, test.txt                   image lists
  data.yaml                             path, train, val, test, names [RedA, BlueB]
Boxes are the projected marker outlines clipped to the image; markers whose visible fraction is
below the dataset's visible_threshold, or whose colour is washed out (``legible`` false), are left
out (YOLO has no ignore regions).
"""
from __future__ import annotations

import json
from pathlib import Path

from dockfactory.core.io import load_labels, write_text_atomic
from dockfactory.core.layout import CLASS_NAMES
from dockfactory.generator.export_files import place_file


def yolo_lines(label: dict, visible_threshold: float) -> list[str]:
    w, h = label["image"]["width"], label["image"]["height"]
    lines = []
    for m in label["markers"]:
        if m["bbox_px"] is None or m.get("visible_fraction", 0.0) < visible_threshold or not m.get("legible", True):
            continue
        x0, y0, x1, y1 = m["bbox_px"]
        cx, cy = (x0 + x1) / 2 + 0.5, (y0 + y1) / 2 + 0.5     # OpenCV centres -> pixel-edge frame
        lines.append(f"{m['class_id']} {cx / w:.8f} {cy / h:.8f} {(x1 - x0) / w:.8f} {(y1 - y0) / h:.8f}")
    return lines


def parse_yolo_line(line: str, w: int, h: int) -> tuple[int, list[float]]:
    """Inverse of :func:`yolo_lines` for one line: class id and bbox_px [x0, y0, x1, y1]."""
    c, cx, cy, bw, bh = line.split()
    cx, cy, bw, bh = float(cx) * w - 0.5, float(cy) * h - 0.5, float(bw) * w, float(bh) * h
    return int(c), [cx - bw / 2, cy - bh / 2, cx + bw / 2, cy + bh / 2]


def export_yolo(root, out) -> Path:
    root, out = Path(root), Path(out)
    ident = json.loads((root / "dataset.json").read_text())
    threshold = ident["config"]["labels"]["visible_threshold"]
    lists: dict[str, list[str]] = {}
    for label in load_labels(root):
        split, fid = label["spec"]["split"], label["frame_id"]
        place_file(root / "images" / f"{fid}.png", out / "images" / split / f"{fid}.png")
        write_text_atomic(out / "labels" / split / f"{fid}.txt", "".join(l + "\n" for l in yolo_lines(label, threshold)))
        lists.setdefault(split, []).append(f"./images/{split}/{fid}.png")
    for split, items in lists.items():
        write_text_atomic(out / f"{split}.txt", "".join(i + "\n" for i in items))
    names = "".join(f"  {i}: {n}\n" for i, n in enumerate(CLASS_NAMES))
    write_text_atomic(out / "data.yaml",
                      f"# dockfactory dataset {ident['version_id']}\npath: {(root / 'exports' / 'yolo').resolve()}\n"
                      f"train: train.txt\nval: test.txt\ntest: test.txt\nnc: {len(CLASS_NAMES)}\nnames:\n{names}")
    return out
