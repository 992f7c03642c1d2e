"""Helpers shared by the exporters: labels checked against the plan, and images placed (hard link,
else copy) atomically.

Every frame id and split name that goes into an export path comes from a label file and is
checked first: the id must be a planned frame of the dataset (``frame_plan`` of its dataset.json)
and the label's file name, and the split the plan's split of that frame. So a tampered label can
never make an exporter write (or read) outside the dataset.
"""
from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

from dockfactory.core.config import config_from_dict
from dockfactory.core.io import atomic_path
from dockfactory.generator.dataset import DatasetError, check_frame_id, check_split, load_identity
from dockfactory.generator.sampler import frame_plan


def plan_splits(root, ident: dict) -> dict[str, str]:
    """frame id -> split of every planned frame of the dataset."""
    cfg = config_from_dict(ident["config"], str(Path(root) / "dataset.json"))
    return {s.frame_id: s.split for s in frame_plan(cfg)}


def checked_labels(root, ident: dict | None = None, split: str | None = None) -> list[dict]:
    """The dataset's labels (optionally one split) in frame-id order, each checked against the
    plan before any path is built from it (DatasetError naming the file otherwise)."""
    root = Path(root)
    ident = ident if ident is not None else load_identity(root, required=("config",))
    plan = plan_splits(root, ident)
    out = []
    for path in sorted((root / "labels").glob("*.json")):
        if path.is_symlink():
            raise DatasetError(f"{path}: is a symlink; a dataset's files live inside it")
        try:
            label = json.loads(path.read_text())
            fid, lsplit = label["frame_id"], label["spec"]["split"]
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise DatasetError(f"{path}: unreadable label ({type(exc).__name__}: {exc})") from None
        check_frame_id(fid, path)
        check_split(lsplit, path)
        if fid != path.stem:
            raise DatasetError(f"{path}: frame id {fid!r} does not match the file name")
        if fid not in plan:
            raise DatasetError(f"{path}: frame {fid} is not in this dataset's plan")
        if lsplit != plan[fid]:
            raise DatasetError(f"{path}: split {lsplit!r}, the plan puts frame {fid} in {plan[fid]!r}")
        if split is None or lsplit == split:
            out.append(label)
    return out


def source_image(root, frame_id: str) -> Path:
    """The dataset's image of a (checked) frame id; a symlink is refused (it could point anywhere)."""
    path = Path(root) / "images" / f"{check_frame_id(frame_id, root)}.png"
    if path.is_symlink():
        raise DatasetError(f"{path}: is a symlink; a dataset's files live inside it")
    return path


def place_file(src: Path, dst: Path) -> None:
    """Make ``dst`` hold ``src``'s bytes: a hard link when possible (no extra space), else a copy."""
    if src.is_symlink():
        raise DatasetError(f"{src}: is a symlink; a dataset's files live inside it")
    dst.parent.mkdir(parents=True, exist_ok=True)
    if dst.exists() and dst.stat().st_size == src.stat().st_size and os.path.samefile(src, dst):
        return
    with atomic_path(dst) as tmp:
        try:
            os.link(src, tmp, follow_symlinks=False)
        except OSError:
            shutil.copyfile(src, tmp)
