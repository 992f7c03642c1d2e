"""Helpers shared by the exporters: place an image (hard link, else copy) atomically."""
from __future__ import annotations

import os
import shutil
from pathlib import Path

from dockfactory.core.io import atomic_path


def place_file(src: Path, dst: Path) -> None:
    """Make ``dst`` hold ``src``'s bytes: a hard link when possible (no extra space), else a copy."""
    dst.parent.mkdir(parents=True, exist_ok=True)
    if dst.exists() and dst.stat().st_size == src.stat().st_size and os.path.samefile(src, dst):
        return
    with atomic_path(dst) as tmp:
        try:
            os.link(src, tmp)
        except OSError:
            shutil.copyfile(src, tmp)
