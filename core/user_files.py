"""Paths a user names for reading: a folder, a fifo or a device is refused before it is opened.

Opening a fifo blocks until something writes to it (``verify --manifest fifo`` hung), and a
folder or a device gives an OS error deep inside a reader; each reader calls
:func:`check_regular_file` first and keeps its own messages for a missing or unreadable file.
"""
from __future__ import annotations

import hashlib
import stat
from pathlib import Path

from dockfactory.core.errors import DockfactoryError


def check_regular_file(path, what: str) -> None:
    """DockfactoryError naming ``path`` when it exists but is not a regular file (a folder, a
    fifo, a device, a socket); nothing when it is a regular file or does not exist (the caller
    says "not found" in its own words). ``what``: the kind of file expected, e.g. "layout"."""
    try:
        mode = Path(path).stat().st_mode
    except OSError:
        return
    if stat.S_ISDIR(mode):
        raise DockfactoryError(f"{path}: is a folder, not a {what} file")
    if not stat.S_ISREG(mode):
        kind = "fifo" if stat.S_ISFIFO(mode) else "socket" if stat.S_ISSOCK(mode) else "device"
        raise DockfactoryError(f"{path}: is a {kind}, not a {what} file")


def beside_config(name: str, config_path) -> Path:
    """The file ``name`` a config names: absolute as given, else relative to the config's folder."""
    return Path(name) if Path(name).is_absolute() else Path(config_path).parent / name


def short_digest(path: Path) -> str:
    """The first 16 hex digits of a file's sha256 (the one-line note a resolved config carries)."""
    return hashlib.sha256(path.read_bytes()).hexdigest()[:16]
