"""Layout files from measured marker coordinates: a CSV from a CMM or a laser tracker.

``units`` scales coordinates, diameters and sigmas to millimetres (mm, cm, m, in). The result
is a layout object in the format of ``core.layout_file`` and passes its checks before anything
is written (:func:`write_layout`); every problem is a one-line LayoutFileError naming the file,
the line and the column.

Why and how: docs/measure.md, "The layout CSV format".
"""
from __future__ import annotations

import csv
import json
import math
from pathlib import Path

from dockfactory.core.io import atomic_path
from dockfactory.core.layout_file import MAX_MARKERS, MAX_SIGMA_MM, LayoutFileError, read_layout_file
from dockfactory.core.user_files import check_regular_file

UNITS_MM = {"mm": 1.0, "cm": 10.0, "m": 1000.0, "in": 25.4}
SURFACES = ("cylinder",)
REQUIRED = ("id", "section", "x", "y", "z", "diameter")
ALIASES = {"diameter_mm": "diameter", "x_mm": "x", "y_mm": "y", "z_mm": "z"}
NORMAL = ("nx", "ny", "nz")
OPTIONAL = NORMAL + ("index", "sigma_mm")
MAX_CSV_BYTES = 1 << 20   # a layout of 64 markers is a few kilobytes


def _header(row: list[str], where: str) -> dict[str, int]:
    """{column name: position} of the header ``row``; LayoutFileError on a missing, repeated or
    unknown column."""
    names = [ALIASES.get(c.strip().lower(), c.strip().lower()) for c in row]
    for name in names:
        if name not in REQUIRED + OPTIONAL:
            raise LayoutFileError(f"{where}: column {name!r} is not one of {', '.join(REQUIRED + OPTIONAL)}")
        if names.count(name) > 1:
            raise LayoutFileError(f"{where}: column {name!r} appears twice")
    missing = [c for c in REQUIRED if c not in names]
    if missing:
        raise LayoutFileError(f"{where}: missing column(s) {', '.join(missing)} (the header row names them)")
    given = [c for c in NORMAL if c in names]
    if given and len(given) != 3:
        raise LayoutFileError(f"{where}: a normal needs all of nx, ny, nz; the header has {', '.join(given)}")
    return {n: i for i, n in enumerate(names)}


def _number(text: str, where: str, column: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value):
        raise LayoutFileError(f"{where}: {column}: expected a finite number, got {text!r}"[:300])
    return value


def _surface_normal(centre, surface: str, where: str) -> list[float]:
    """The outward normal of the section's ``surface`` at ``centre`` (mm, section frame)."""
    r = math.hypot(centre[1], centre[2])
    if r < 1e-6:
        raise LayoutFileError(f"{where}: the marker lies on the section's axis (y = z = 0): give its normal "
                              "(nx, ny, nz)")
    return [0.0, centre[1] / r, centre[2] / r]


def _marker(cells: list[str], cols: dict[str, int], where: str, scale: float, surface: str) -> dict:
    """The layout file's marker object of one CSV row (``scale``: mm per the file's unit)."""
    if len(cells) != len(cols):
        raise LayoutFileError(f"{where}: {len(cells)} values, the header has {len(cols)} columns")
    cell = {name: cells[i].strip() for name, i in cols.items()}
    if not cell["id"]:
        raise LayoutFileError(f"{where}: id: empty")
    section = cell["section"].upper()
    if section not in ("A", "B"):
        raise LayoutFileError(f"{where}: section: expected A or B, got {cell['section']!r}")
    centre = [_number(cell[c], where, c) * scale for c in ("x", "y", "z")]
    rec = {"id": cell["id"], "section": section, "center_mm": centre,
           "diameter_mm": _number(cell["diameter"], where, "diameter") * scale}
    given = [cell.get(c, "") for c in NORMAL]
    if any(given) and not all(given):
        raise LayoutFileError(f"{where}: nx, ny, nz: give all three or none (none: the {surface}'s normal)")
    rec["normal"] = _unit([_number(v, where, c) for v, c in zip(given, NORMAL)], where) if all(given) \
        else _surface_normal(centre, surface, where)
    if cell.get("index"):
        index = _number(cell["index"], where, "index")
        if index != int(index) or index < 0:
            raise LayoutFileError(f"{where}: index: expected an integer >= 0, got {cell['index']!r}")
        rec["index"] = int(index)
    if cell.get("sigma_mm"):
        rec["sigma_mm"] = _number(cell["sigma_mm"], where, "sigma_mm") * scale
    return rec


def _unit(v: list[float], where: str) -> list[float]:
    n = math.sqrt(sum(x * x for x in v))
    if n < 1e-9:
        raise LayoutFileError(f"{where}: nx, ny, nz: the normal is zero")
    return [x / n for x in v]


def _rows(path: Path) -> list[tuple[int, list[str]]]:
    """(line number, cells) of every non-empty, non-comment line of the CSV ``path``."""
    check_regular_file(path, "marker CSV")
    try:
        if path.stat().st_size > MAX_CSV_BYTES:
            raise LayoutFileError(f"{path}: {path.stat().st_size} bytes: not a marker table (at most {MAX_CSV_BYTES})")
        text = path.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise LayoutFileError(f"{path}: marker CSV not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise LayoutFileError(f"{path}: unreadable marker CSV ({type(exc).__name__})") from None
    lines = [(i, line) for i, line in enumerate(text.splitlines(), 1) if line.strip() and not line.lstrip().startswith("#")]
    try:
        return [(i, next(csv.reader([line]))) for i, line in lines]
    except csv.Error as exc:
        raise LayoutFileError(f"{path}: not a CSV table ({exc})") from None


def layout_from_csv(path, units: str = "mm", surface: str = "cylinder", sigma_mm: float | None = None) -> dict:
    """The layout object (``core.layout_file``'s format) of the marker CSV ``path`` (module
    docstring); ``sigma_mm`` the whole layout's 1-sigma coordinate uncertainty in mm (None: not
    stated). Rows are checked here; the layout's own checks run when it is written."""
    path = Path(path)
    if units not in UNITS_MM:
        raise LayoutFileError(f"units: expected one of {', '.join(UNITS_MM)}, got {units!r}")
    if surface not in SURFACES:
        raise LayoutFileError(f"surface: expected one of {', '.join(SURFACES)}, got {surface!r}")
    rows = _rows(path)
    if len(rows) < 2:
        raise LayoutFileError(f"{path}: expected a header row and one row per marker")
    cols = _header(rows[0][1], f"{path}:{rows[0][0]}")
    if len(rows) - 1 > MAX_MARKERS:
        raise LayoutFileError(f"{path}: {len(rows) - 1} markers, at most {MAX_MARKERS}")
    markers = [_marker(cells, cols, f"{path}:{line}", UNITS_MM[units], surface) for line, cells in rows[1:]]
    count = {"A": 0, "B": 0}
    for m in markers:
        m.setdefault("index", count[m["section"]])
        count[m["section"]] += 1
    out = {"markers": [{k: m[k] for k in ("id", "section", "index", "center_mm", "normal", "diameter_mm")}
                       | ({"sigma_mm": m["sigma_mm"]} if "sigma_mm" in m else {}) for m in markers],
           "frame": "each marker's section frame (A: D; B: B's frame)",
           "source": f"{path.name} ({units}; normals without a column: the {surface}'s)"}
    if sigma_mm is not None:
        if not (math.isfinite(sigma_mm) and 0 <= sigma_mm <= MAX_SIGMA_MM):
            raise LayoutFileError(f"sigma_mm: expected a number in [0, {MAX_SIGMA_MM:g}] mm, got {sigma_mm!r}")
        out["sigma_mm"] = float(sigma_mm)
    return out


def write_layout(layout: dict, out, source: str) -> tuple:
    """Write ``layout`` to ``out`` atomically after it passes every check of a layout file
    (``core.layout_file``: read back before it replaces ``out``); returns its markers. A layout
    that fails leaves ``out`` as it was: LayoutFileError naming ``source`` and the problem."""
    out = Path(out)
    with atomic_path(out) as tmp:
        tmp.write_text(json.dumps(layout, indent=1) + "\n", encoding="utf-8")
        try:
            markers = read_layout_file(tmp)
        except LayoutFileError as exc:
            raise LayoutFileError(str(exc).replace(str(tmp), source)) from None
    return markers
