"""Reading a marker layout file: the measured positions of the markers on a real pair of sections.

A layout is refused (LayoutFileError, one line naming the file, key and value) unless every
number is finite and of a docking section's size, each section's markers lie on its side of the
seam (A at x <= 0, B at x >= 0: swapped section labels are caught), and each section passes the
checks a config's layout passes (``core.layout.layout_problems``: at least 6 markers, no
overlapping discs, not coplanar, no symmetry that makes two markers interchangeable).

Why and how: docs/measure.md, "The layout file format".
"""
from __future__ import annotations

import json
import math
from pathlib import Path

from dockfactory.core.errors import DockfactoryError
from dockfactory.core.layout import Marker, layout_problems
from dockfactory.core.names import SECTIONS
from dockfactory.core.user_files import check_regular_file

MAX_MARKERS_PER_SECTION = 32   # identification's time grows about as markers^5 (bench/solver/solve_memory.py)
MAX_MARKERS = 2 * MAX_MARKERS_PER_SECTION
MAX_COORDINATE_MM = 1.0e5   # 100 m: a docking section is metres across, never more
MAX_DIAMETER_MM = 1.0e3
MAX_SIGMA_MM = 10.0   # a layout known worse than 1 cm is not a measured layout


class LayoutFileError(DockfactoryError):
    """A layout file that cannot be used; the message names the file and the key."""


def _numbers(value, path, key: str, n: int) -> tuple[float, ...]:
    if (not isinstance(value, list) or len(value) != n
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value)):
        raise LayoutFileError(f"{path}: {key}: expected {n} finite numbers, got {value!r}"[:300])
    return tuple(float(v) for v in value)


def _marker(rec, path, i: int) -> Marker:
    key = f"markers[{i}]"
    if not isinstance(rec, dict):
        raise LayoutFileError(f"{path}: {key}: expected an object")
    for name in ("id", "section", "index", "center_mm", "normal", "diameter_mm"):
        if name not in rec:
            raise LayoutFileError(f"{path}: {key}.{name}: missing")
    if not isinstance(rec["id"], str) or not rec["id"]:
        raise LayoutFileError(f"{path}: {key}.id: expected a non-empty string")
    if rec["section"] not in SECTIONS:
        raise LayoutFileError(f"{path}: {key}.section: expected one of {', '.join(SECTIONS)}, got {rec['section']!r}")
    if isinstance(rec["index"], bool) or not isinstance(rec["index"], int) or rec["index"] < 0:
        raise LayoutFileError(f"{path}: {key}.index: expected an integer >= 0, got {rec['index']!r}")
    normal = _numbers(rec["normal"], path, f"{key}.normal", 3)
    norm = math.sqrt(sum(v * v for v in normal))
    if not 0.99 < norm < 1.01:
        raise LayoutFileError(f"{path}: {key}.normal: expected a unit vector, its length is {norm:.4g}")
    d = rec["diameter_mm"]
    if isinstance(d, bool) or not isinstance(d, (int, float)) or not (math.isfinite(d) and 0 < d <= MAX_DIAMETER_MM):
        raise LayoutFileError(f"{path}: {key}.diameter_mm: expected a number in (0, {MAX_DIAMETER_MM:g}] mm, got {d!r}")
    centre = _numbers(rec["center_mm"], path, f"{key}.center_mm", 3)
    if max(abs(v) for v in centre) > MAX_COORDINATE_MM:
        raise LayoutFileError(f"{path}: {key}.center_mm: {list(centre)} is beyond {MAX_COORDINATE_MM:g} mm "
                              "of its section's frame (millimetres expected)")
    return Marker(rec["id"], rec["section"], rec["index"], centre, tuple(v / norm for v in normal), float(d))


def _wrong_side(markers) -> str | None:
    """Why the markers do not sit on their sections, or None. By the frames' construction A's
    body lies at x < 0 of D (+X points from A toward B) and B's at x > 0 of B's frame, so a
    marker on the wrong side means the layout's section labels (or its axis) are swapped."""
    for m in markers:
        if (m.center_mm[0] > 0) if m.section == "A" else (m.center_mm[0] < 0):
            want = "x <= 0 (A's body lies behind its docking face)" if m.section == "A" else \
                "x >= 0 (B's body lies beyond its docking face)"
            return (f"marker {m.id} of section {m.section} is at x = {m.center_mm[0]:g} mm, expected {want}: "
                    "are sections A and B swapped?")
    return None


def _sigma(value, path, key: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not (
            math.isfinite(value) and 0 <= value <= MAX_SIGMA_MM):
        raise LayoutFileError(f"{path}: {key}: expected a number in [0, {MAX_SIGMA_MM:g}] mm (the 1-sigma "
                              f"uncertainty of each marker coordinate), got {value!r}"[:300])
    return float(value)


def read_layout_sigmas(path) -> dict[str, float] | None:
    """{marker id: sigma_mm} of layout file ``path`` (module docstring): each marker's own
    ``sigma_mm``, else the layout's; None when the file states no ``sigma_mm`` at all. The file is
    checked as :func:`read_layout_file` checks it (one-line LayoutFileError)."""
    data, markers = _read(Path(path))
    top = data.get("sigma_mm")
    top = None if top is None else _sigma(top, path, "sigma_mm")
    own = {i: _sigma(rec["sigma_mm"], path, f"markers[{i}].sigma_mm")
           for i, rec in enumerate(data["markers"]) if rec.get("sigma_mm") is not None}
    if top is None and not own:
        return None
    return {m.id: own.get(i, top if top is not None else 0.0) for i, m in enumerate(markers)}


def read_layout_file(path) -> tuple[Marker, ...]:
    """The markers of layout file ``path`` (checked: one-line LayoutFileError otherwise)."""
    return _read(Path(path))[1]


def _read(path: Path) -> tuple[dict, tuple[Marker, ...]]:
    """(the file's JSON object, its checked markers)."""
    check_regular_file(path, "layout")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise LayoutFileError(f"{path}: layout file not found") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, RecursionError) as exc:
        raise LayoutFileError(f"{path}: unreadable layout file ({type(exc).__name__})") from None
    markers = data.get("markers") if isinstance(data, dict) else None
    if not isinstance(markers, list) or not markers or len(markers) > MAX_MARKERS:
        raise LayoutFileError(f"{path}: markers: expected a list of 1 to {MAX_MARKERS} marker objects")
    out = tuple(_marker(rec, path, i) for i, rec in enumerate(markers))
    ids = [m.id for m in out]
    dup = next((m for m in ids if ids.count(m) > 1), None)
    if dup is not None:
        raise LayoutFileError(f"{path}: markers: id {dup!r} is used twice")
    pairs = [(m.section, m.index) for m in out]
    twice = next((p for p in pairs if pairs.count(p) > 1), None)
    if twice is not None:
        raise LayoutFileError(f"{path}: markers: section {twice[0]} index {twice[1]} is used twice")
    for sec in SECTIONS:
        n = sum(m.section == sec for m in out)
        if n > MAX_MARKERS_PER_SECTION:
            raise LayoutFileError(f"{path}: markers: section {sec} has {n} markers, at most {MAX_MARKERS_PER_SECTION} "
                                  "per section can be identified")
    problems = [p for p in [_wrong_side(out)] if p] or layout_problems(out)
    if problems:
        raise LayoutFileError(f"{path}: markers: {problems[0]}"
                              + (f" (and {len(problems) - 1} more problems)" if len(problems) > 1 else ""))
    return data, out
