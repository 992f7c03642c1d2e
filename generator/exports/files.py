"""Helpers shared by the exporters: images placed (hard link, else copy) atomically. An image
behind a DVC cache link is placed from the cached file (a hard link to it is read-only, as DVC
makes its hardlink workspaces).

The exporters read a dataset through ``Dataset.open`` (generator.datasets.reader): every frame id and
split that goes into an export path is a planned frame's, from a label whose bytes match the
manifest. So a tampered label can never make an exporter write (or read) outside the dataset.
"""
from __future__ import annotations

import contextlib
import os
import shutil
from pathlib import Path

from dockfactory.core.io import atomic_path, temp_name
from dockfactory.generator.datasets.folder import DatasetError, check_frame_id
from dockfactory.generator.datasets.dvc_links import cache_link, dvc_caches


def source_image(root, frame_id: str) -> Path:
    """The dataset's image of a (checked) frame id: the file itself, or the file a DVC cache link
    resolves to (``generator.datasets.dvc_links``; its bytes were checked when the dataset was opened);
    any other symlink is refused (it could point anywhere)."""
    return _linked_or_own(Path(root) / "images" / f"{check_frame_id(frame_id, root)}.png", root)


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


def _linked_or_own(path: Path, root) -> Path:
    """``path`` itself, or the file a DVC cache link at ``path`` resolves to; any other symlink is
    refused (it could point anywhere)."""
    if path.is_symlink():
        target = cache_link(path, dvc_caches(root))
        if target is None:
            raise DatasetError(f"{path}: is a symlink; a dataset's files live inside it")
        return target
    return path


def source_exr(root, frame_id: str) -> Path:
    """The dataset's kept EXR of a (checked) frame id ([render] keep_exr); a link as for
    :func:`source_image`."""
    return _linked_or_own(Path(root) / "exr" / f"{check_frame_id(frame_id, root)}.exr", root)


@contextlib.contextmanager
def folder_built_aside(final: Path):
    """Yield a temporary folder beside ``final`` to build in; when the block ends it replaces
    ``final`` by rename (old or new, never partial: the old one steps aside, the new one takes
    its name, then the old one is removed). On an error the temporary folder is removed and
    ``final`` is untouched; so it is when the block removed the temporary folder itself (the
    caller found nothing to change)."""
    tmp, aside = final.with_name(temp_name(final.name)), final.with_name(temp_name(f"{final.name}.old"))
    try:
        yield tmp
        if tmp.exists():
            if final.exists():
                os.rename(final, aside)
            os.rename(tmp, final)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    shutil.rmtree(aside, ignore_errors=True)
