"""The Hugging Face view of a dataset: ``hf/<split>/metadata.jsonl`` beside hard links to the
split's images, the layout ``datasets``' ``imagefolder`` reads.

A line has one schema for every frame of every split (``imagefolder`` refuses metadata files
whose inferred features differ): floats are written as floats, no field is ever null.

The view is derived (never in the manifest): ``dockfactory dataset card DIR`` writes it again.

Why and how: docs/datasets.md, "The Hugging Face view's fields".
"""
from __future__ import annotations

import filecmp
import json
import os
import shutil
from pathlib import Path

from dockfactory.core.io import TMP_MARK, stale_temp, write_text_atomic
from dockfactory.core.names import CLASS_NAMES, POSE_NAMES, SPLITS
from dockfactory.generator.datasets.folder import DatasetError
from dockfactory.generator.datasets.reader import Dataset
from dockfactory.generator.exports.coco import COCO_SHIFT   # OpenCV pixel centres -> continuous coordinates
from dockfactory.generator.exports.files import folder_built_aside, place_file, source_image

HF_DIR = "hf"
# the metadata's features as the card declares them (datasets' YAML schema): what imagefolder would
# infer, with ``objects.category`` a ClassLabel of the markers' class names
F64, I64, STR = "float64", "int64", "string"
HF_FEATURES = (("image", "image"), ("frame_id", STR), ("split", STR), ("condition", STR), ("camera_unit", I64),
               ("width", I64), ("height", I64), ("focal_px", F64), ("principal_point", ("list", F64)),
               ("K", ("list", ("list", F64))), ("dist_coeffs", ("list", F64)),
               ("cam_from_d", ("list", ("list", F64))), ("d_from_b", ("list", ("list", F64))),
               ("pose", ("struct", tuple((k, F64) for k in POSE_NAMES))),
               ("objects", ("struct", (("marker_id", ("list", STR)), ("category", ("list", ("class_label", CLASS_NAMES))),
                                       ("bbox", ("list", ("list", F64))), ("center_px", ("list", ("list", F64))),
                                       ("visibility", ("list", I64)), ("visible_fraction", ("list", F64)),
                                       ("legible", ("list", "bool"))))),
               ("label_file", STR), ("label_sha256", STR))
HF_SPLIT_NAMES = {"train": "train", "val": "validation", "test": "test", "repeat": "repeat"}   # ours -> the hub's
STALE_VIEW_S = 6 * 3600.0


def _floats(values) -> list:
    return [_floats(v) if isinstance(v, (list, tuple)) else float(v) for v in values]


def _objects(label: dict) -> dict:
    keys = ("marker_id", "category", "bbox", "center_px", "visibility", "visible_fraction", "legible")
    out: dict = {k: [] for k in keys}
    for m in label["markers"]:
        if m.get("bbox_px") is None:
            continue
        x0, y0, x1, y1 = (float(v) for v in m["bbox_px"])
        out["marker_id"].append(str(m["id"]))
        out["category"].append(int(m["class_id"]))
        out["bbox"].append([x0 + COCO_SHIFT, y0 + COCO_SHIFT, x1 - x0, y1 - y0])
        out["center_px"].append(_floats(m["center_px"]))
        out["visibility"].append(int(m.get("visibility", 0)))
        out["visible_fraction"].append(float(m.get("visible_fraction", 0.0)))
        out["legible"].append(bool(m.get("legible", True)))
    return out


def metadata_row(label: dict, label_sha256: str) -> dict:
    """The metadata line of one frame (module docstring: the fields and their conventions)."""
    cam, spec, fid = label["camera"], label["spec"], label["frame_id"]
    pose = label["pose_b_in_d"]
    return {
        "file_name": f"{fid}.png", "frame_id": fid, "split": spec["split"], "condition": spec["condition"],
        "camera_unit": int(cam.get("unit", 0)), "width": int(label["image"]["width"]),
        "height": int(label["image"]["height"]), "focal_px": float(cam["focal_px"]),
        "principal_point": _floats(cam["principal_point"]), "K": _floats(cam["K"]),
        "dist_coeffs": _floats(cam.get("distortion", [0.0] * 5)), "cam_from_d": _floats(cam["cam_from_d"]),
        "d_from_b": _floats(label["d_from_b"]),
        "pose": {k: float(pose[k]) for k in ("x_mm", "y_mm", "z_mm", "alpha_deg", "beta_deg", "gamma_deg")},
        "objects": _objects(label),
        "label_file": f"labels/{fid}.json", "label_sha256": label_sha256,
    }


def _build(ds: Dataset, out: Path) -> dict[str, int]:
    """The view's files in folder ``out``; frames per split."""
    sha = {rec["path"]: rec["sha256"] for rec in ds.manifest["files"]}
    counts: dict[str, int] = {}
    for split in SPLITS:
        ids = ds.frames(split)
        if not ids:
            continue
        lines = []
        for fid in ids:
            place_file(source_image(ds.root, fid), out / split / f"{fid}.png")
            lines.append(json.dumps(metadata_row(ds.labels[fid], sha[f"labels/{fid}.json"]), allow_nan=False))
        write_text_atomic(out / split / "metadata.jsonl", "".join(ln + "\n" for ln in lines))
        counts[split] = len(ids)
    return counts


def _files(root: Path) -> list[str]:
    return sorted(p.relative_to(root).as_posix() for p in root.rglob("*") if not p.is_dir())


def _same_tree(old: Path, new: Path) -> bool:
    """True when ``old`` holds exactly ``new``'s files with the same bytes (an image that is the
    same file, through a DVC link or a hard link, is not read)."""
    if not old.is_dir() or old.is_symlink() or _files(old) != _files(new):
        return False
    return all(_same_bytes(old / rel, new / rel) for rel in _files(new))


def _same_bytes(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b) or filecmp.cmp(a, b, shallow=False)
    except OSError:   # a dangling link in the old view
        return False


def write_hf_view(ds: Dataset) -> dict[str, int]:
    """Write ``hf/`` of the complete dataset ``ds`` (module docstring): built aside, then swapped
    in by rename, and left untouched when it already holds the same files (so a DVC-tracked
    dataset stays clean).

    Parameters
    ----------
    ds : Dataset
        The opened, complete dataset.

    Returns
    -------
    dict
        Frames per split (non-empty splits only).

    Raises
    ------
    DatasetError
        ``hf`` is a symlink (the view is a folder inside the dataset).
    """
    root = ds.root
    final = root / HF_DIR
    if final.is_symlink():
        raise DatasetError(f"{final}: is a symlink; the dataset's Hugging Face view is a folder inside it")
    for left in root.glob(f".{HF_DIR}*{TMP_MARK}*"):   # built aside by a killed writer
        if stale_temp(left, STALE_VIEW_S, own=True):
            shutil.rmtree(left, ignore_errors=True)
    with folder_built_aside(final) as tmp:
        counts = _build(ds, tmp)
        if _same_tree(final, tmp):
            shutil.rmtree(tmp)   # nothing changes: final stays as it is
    return counts
