"""Layouts from measured coordinates (core.layout_csv, `dockfactory layout`): a CMM's CSV becomes
a layout file checked like every other; every bad row is one line naming file, line and column,
and nothing is written (an existing file keeps its bytes)."""
from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from cli_run import one_line_error, run_cli
from dockfactory.core.config import load_config
from dockfactory.core.layout_csv import layout_from_csv, write_layout
from dockfactory.core.layout_file import LayoutFileError, read_layout_file, read_layout_sigmas
from dockfactory.core.resources import shipped_config
from dockfactory.generator.datasets.folder import layout_record


@pytest.fixture(scope="module")
def factory_layout():
    return layout_record(load_config(shipped_config("quick")))


def _csv(path, header, rows):
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        w.writerows(rows)
    return path


def _rows(layout, normals=False, scale=1.0):
    out = []
    for m in layout["markers"]:
        row = [m["id"], m["section"]] + [v / scale for v in m["center_mm"]] + [m["diameter_mm"] / scale]
        out.append(row + (list(m["normal"]) if normals else []))
    return out


def test_a_cmm_table_without_normals_gives_the_factory_layout(tmp_path, factory_layout):
    """Coordinates only: each normal is the cylinder's outward radial at the marker, which is the
    factory's own normal (to 1e-9); the markers read back as the config's layout file does."""
    path = _csv(tmp_path / "m.csv", ["id", "section", "x", "y", "z", "diameter"], _rows(factory_layout))
    markers = write_layout(layout_from_csv(path), tmp_path / "layout.json", str(path))
    (tmp_path / "ref.json").write_text(json.dumps(factory_layout))
    ref = read_layout_file(tmp_path / "ref.json")
    assert [m.id for m in markers] == [m.id for m in ref] and [m.index for m in markers] == [m.index for m in ref]
    for a, b in zip(markers, ref):
        assert np.allclose(a.center_mm, b.center_mm, atol=1e-9) and np.allclose(a.normal, b.normal, atol=1e-9)
        assert a.diameter_mm == b.diameter_mm
    assert read_layout_sigmas(tmp_path / "layout.json") is None


def test_normals_units_and_sigmas(tmp_path, factory_layout):
    """Metres with given normals (scaled by 3, normalised here), a column order of its own, each
    marker's sigma and the layout's: millimetres out, sigmas where the budget reads them."""
    rows = [[r[6] * 3, r[7] * 3, r[8] * 3, r[5], r[0], r[1], r[2], r[3], r[4], 2e-5 if i == 0 else ""]
            for i, r in enumerate(_rows(factory_layout, normals=True, scale=1000.0))]
    path = _csv(tmp_path / "m.csv", [" NX", "NY ", "nz", "Diameter_mm", "ID", "section", "x", "y", "z", "sigma_mm"], rows)
    layout = layout_from_csv(path, units="m", sigma_mm=0.05)
    markers = write_layout(layout, tmp_path / "layout.json", str(path))
    for m, ref in zip(markers, factory_layout["markers"]):
        assert np.allclose(m.center_mm, ref["center_mm"], atol=1e-9) and np.allclose(m.normal, ref["normal"])
    sig = read_layout_sigmas(tmp_path / "layout.json")
    assert sig[markers[0].id] == pytest.approx(0.02) and sig[markers[1].id] == 0.05


@pytest.mark.parametrize("header, edit, message", [
    (["id", "section", "x", "y", "diameter"], None, r"m\.csv:1: missing column\(s\) z"),
    (["id", "section", "x", "y", "z", "diameter", "colour"], None, r"m\.csv:1: column 'colour' is not one of"),
    (["id", "section", "x", "y", "z", "diameter", "nx", "ny"], None, r"m\.csv:1: a normal needs all of nx, ny, nz"),
    (None, (4, 2, "12,5"), r"m\.csv:4: x: expected a finite number, got '12,5'"),
    (None, (3, 1, "C"), r"m\.csv:3: section: expected A or B, got 'C'"),
    (None, (6, 5, "nan"), r"m\.csv:6: diameter: expected a finite number, got 'nan'"),
])
def test_a_bad_table_is_one_line_naming_line_and_column(tmp_path, factory_layout, header, edit, message):
    rows = [[str(v) for v in r] for r in _rows(factory_layout)]
    if edit:
        line, col, value = edit
        rows[line - 2][col] = value
    path = _csv(tmp_path / "m.csv", header or ["id", "section", "x", "y", "z", "diameter"],
                [r[:len(header)] if header else r for r in rows])
    with pytest.raises(LayoutFileError, match=message):
        layout_from_csv(path)


@pytest.mark.parametrize("edit, message", [
    (lambda rows: rows[:5] + rows[7:], r"m\.csv: markers: .*at least"),              # A left with 5
    (lambda rows: [[r[0], r[1], -r[2] if r[1] == "A" and i == 0 else r[2]] + r[3:] for i, r in enumerate(rows)],
     r"m\.csv: markers: marker A0 of section A is at x = 50 mm.*swapped"),
    (lambda rows: rows + [rows[0]], r"m\.csv: markers: id 'A0' is used twice"),
])
def test_a_table_that_is_no_layout_writes_nothing(tmp_path, factory_layout, edit, message):
    """The layout's own checks (core.layout_file) run before the file replaces anything: the old
    layout keeps its bytes and no temporary is left."""
    path = _csv(tmp_path / "m.csv", ["id", "section", "x", "y", "z", "diameter"], edit(_rows(factory_layout)))
    out = tmp_path / "layout.json"
    out.write_text("old")
    with pytest.raises(LayoutFileError, match=message):
        write_layout(layout_from_csv(path), out, str(path))
    assert out.read_text() == "old" and sorted(p.name for p in tmp_path.iterdir()) == ["layout.json", "m.csv"]


def test_a_marker_on_the_axis_needs_its_normal(tmp_path, factory_layout):
    rows = _rows(factory_layout)
    rows[0][3:5] = [0.0, 0.0]
    path = _csv(tmp_path / "m.csv", ["id", "section", "x", "y", "z", "diameter"], rows)
    with pytest.raises(LayoutFileError, match=r"m\.csv:2: the marker lies on the section's axis"):
        layout_from_csv(path)


def test_the_command_line(tmp_path, capsys, factory_layout):
    """layout from-config writes the config's layout; from-csv of it (comments and blank lines
    ignored) the same markers; a bad file is exit 2 in one line."""
    code, out, _ = run_cli(["layout", "from-config", "quick", "--out", tmp_path / "cfg.json"], capsys)
    assert code == 0 and "14 markers (A 7, B 7)" in out
    assert json.loads((tmp_path / "cfg.json").read_text())["markers"] == factory_layout["markers"]
    path = tmp_path / "m.csv"
    _csv(path, ["id", "section", "x", "y", "z", "diameter"], _rows(factory_layout))
    path.write_text("# measured 2026-12-03, laser tracker\n\n" + path.read_text())
    code, out, _ = run_cli(["layout", "from-csv", path, "--out", tmp_path / "csv.json", "--sigma-mm", "0.03"], capsys)
    assert code == 0 and "sigma 0.03 mm" in out
    assert [m.id for m in read_layout_file(tmp_path / "csv.json")] == [m["id"] for m in factory_layout["markers"]]
    code, _, err = run_cli(["layout", "from-csv", tmp_path / "missing.csv", "--out", tmp_path / "x.json"], capsys)
    assert code == 2 and "missing.csv" in one_line_error(err) and not (tmp_path / "x.json").exists()
