"""YOLO export in the layout ultralytics reads (a copied or moved export folder keeps working).

exports/yolo/
  data.yaml                              train/val/test relative to the yaml (no ``path:`` key:
                                         ultralytics then resolves them against the yaml's folder)
  images/{train,val,test,repeat}/<id>.png   hard links to the dataset's images (else copies)
  labels/{train,val,test,repeat}/<id>.txt   one line per marker: class cx cy w h (normalised)

Why and how: docs/datasets.md, "The YOLO export's splits and boxes".
"""
from __future__ import annotations

from pathlib import Path

from dockfactory.core.io import write_text_atomic
from dockfactory.core.layout import CLASS_NAMES
from dockfactory.generator.datasets.reader import Dataset
from dockfactory.generator.exports.files import place_file, source_image
from dockfactory.generator.exports.registry import ExportFormat

YOLO_SPLITS = ("train", "val", "test")   # the splits data.yaml names; repeat is exported beside them


def exported_markers(label: dict, visible_threshold: float) -> list[dict]:
    """The label's marker records a YOLO export writes, in label order: a box in the image, visible
    fraction at least ``visible_threshold`` and legible (YOLO has no ignore regions)."""
    return [m for m in label["markers"] if m["bbox_px"] is not None
            and m.get("visible_fraction", 0.0) >= visible_threshold and m.get("legible", True)]


def box_fields(m: dict, w: int, h: int) -> str:
    """``class cx cy w h`` of marker record ``m``: its box in normalised continuous coordinates."""
    x0, y0, x1, y1 = m["bbox_px"]
    cx, cy = (x0 + x1) / 2 + 0.5, (y0 + y1) / 2 + 0.5     # OpenCV centres -> pixel-edge frame
    return f"{m['class_id']} {cx / w:.8f} {cy / h:.8f} {(x1 - x0) / w:.8f} {(y1 - y0) / h:.8f}"


def yolo_lines(label: dict, visible_threshold: float) -> list[str]:
    """One ``class cx cy w h`` line per exported marker of ``label``."""
    w, h = label["image"]["width"], label["image"]["height"]
    return [box_fields(m, w, h) for m in exported_markers(label, visible_threshold)]


def parse_yolo_line(line: str, w: int, h: int) -> tuple[int, list[float]]:
    """Inverse of :func:`yolo_lines` for one line: class id and bbox_px [x0, y0, x1, y1]."""
    c, cx, cy, bw, bh = line.split()
    cx, cy, bw, bh = float(cx) * w - 0.5, float(cy) * h - 0.5, float(bw) * w, float(bh) * h
    return int(c), [cx - bw / 2, cy - bh / 2, cx + bw / 2, cy + bh / 2]


def data_yaml(version_id: str, counts: dict[str, int], extra: str = "") -> str:
    """data.yaml text for split frame ``counts``: keys relative to the yaml, no ``path:``;
    ``extra``: more lines (the pose export's ``kpt_shape``)."""
    if counts.get("val"):
        val, note = "val", ""
    elif counts.get("train"):
        val, note = "train", "  # this dataset has no val split ([dataset] val_fraction): validating on train"
    else:
        val, note = "test", "  # no train frames: an evaluation-only dataset"
    names = "".join(f"  {i}: {n}\n" for i, n in enumerate(CLASS_NAMES))
    frames = ", ".join(f"{s} {counts.get(s, 0)}" for s in (*YOLO_SPLITS, "repeat"))
    return (f"# dockfactory dataset {version_id}: frames {frames}\n"
            f"# paths are relative to this file; labels/<split>/<id>.txt beside images/<split>/<id>.png\n"
            f"train: images/train\nval: images/{val}{note}\ntest: images/test\n"
            f"nc: {len(CLASS_NAMES)}\nnames:\n{names}{extra}")


def write_yolo_layout(root, out, lines_of, yaml_extra: str = "") -> Path:
    """The ultralytics layout of dataset ``root`` (a folder, or an opened Dataset) under ``out``:
    images, ``labels/<split>/<id>.txt`` holding ``lines_of(label, visible_threshold)`` (list of
    str), and data.yaml (with ``yaml_extra`` appended)."""
    out = Path(out)
    # intact and complete (opened here, or by the caller that exports several formats): its
    # frames are the plan's, ids and splits checked
    ds = root if isinstance(root, Dataset) else Dataset.open(root)
    ident = ds.identity
    threshold = ident["config"]["labels"]["visible_threshold"]
    counts: dict[str, int] = {}
    for split in YOLO_SPLITS:
        (out / "images" / split).mkdir(parents=True, exist_ok=True)
        (out / "labels" / split).mkdir(parents=True, exist_ok=True)
    for label in ds.labels_of():
        split, fid = label["spec"]["split"], label["frame_id"]
        place_file(source_image(ds.root, fid), out / "images" / split / f"{fid}.png")
        write_text_atomic(out / "labels" / split / f"{fid}.txt", "".join(l + "\n" for l in lines_of(label, threshold)))
        counts[split] = counts.get(split, 0) + 1
    write_text_atomic(out / "data.yaml", data_yaml(str(ident.get("version_id", "")), counts, yaml_extra))
    return out


def export_yolo(root, out) -> Path:
    """Write the YOLO (detection) export of dataset ``root`` into ``out`` (module docstring).

    Parameters
    ----------
    root : path or Dataset
        The dataset: its folder, or a Dataset already opened (by a caller writing several formats).
    out : path
        The export's folder (created; files in it are replaced).

    Returns
    -------
    Path
        ``out``.

    Raises
    ------
    DatasetError
        When the dataset is not intact and complete, or a file of it cannot be read.
    """
    return write_yolo_layout(root, out, yolo_lines)


FORMATS = (
    ExportFormat("yolo", export_yolo, "YOLO boxes in ultralytics' layout"),
)
