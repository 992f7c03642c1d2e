"""Helpers shared by the exporters: images placed (hard link, else copy) atomically. An image
behind a DVC cache link is placed from the cached file (a hard link to it is read-only, as DVC
makes its hardlink workspaces).

The exporters read a dataset through ``Dataset.open`` (generator.dataset_open): every frame id and
split that goes into an export path is a planned frame's, from a label whose bytes match the
manifest. So a tampered label can never make an exporter write (or read) outside the dataset.
"""
from __future__ import annotations

import os
import shutil
from pathlib import Path

from dockfactory.core.io import atomic_path
from dockfactory.generator.dataset import DatasetError, check_frame_id
from dockfactory.generator.dvc_links import cache_link, dvc_caches


def source_image(root, frame_id: str) -> Path:
    """The dataset's image of a (checked) frame id: the file itself, or the file a DVC cache link
    resolves to (``generator.dvc_links``; its bytes were checked when the dataset was opened);
    any other symlink is refused (it could point anywhere)."""
    path = Path(root) / "images" / f"{check_frame_id(frame_id, root)}.png"
    if path.is_symlink():
        target = cache_link(path, dvc_caches(root))
        if target is None:
            raise DatasetError(f"{path}: is a symlink; a dataset's files live inside it")
        return target
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
