"""Files a config names, read when it is loaded: a calibration file (core.config_calibration) and
part meshes (core.config_parts). Each is resolved into the config's own keys, so the config
(and a dataset's stored copy of it) holds what the file said, and its version id is the files'
content, not their paths.
"""
from __future__ import annotations

from dockfactory.core.config_calibration import resolve_calibration
from dockfactory.core.config_parts import resolve_parts


def resolve_config_files(data: dict, config_path) -> tuple[dict, str | None]:
    """(data, note): the config's TOML tables with its calibration file and part meshes read into
    them, and one note naming what was read (None when the config names no file). Raises the
    readers' one-line errors (CalibrationError, MeshError) naming the config, the key and the file."""
    data, cal = resolve_calibration(data, config_path)
    data, parts = resolve_parts(data, config_path)
    notes = [n for n in (cal, parts) if n]
    return data, (" and ".join(notes) if notes else None)
