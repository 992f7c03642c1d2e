"""core.layout_file: a dataset's layout.json reads back as the config's markers; bad files are
one-line errors naming the file and the key."""
import json

import pytest

from dockfactory.core.layout_file import LayoutFileError, read_layout_file, read_layout_sigmas
from dockfactory.generator.datasets.reader import Dataset


def test_a_datasets_layout_reads_back_as_its_markers(painted_source):
    got = read_layout_file(painted_source / "layout.json")
    want = Dataset.open(painted_source, full=False).markers()
    assert [m.id for m in got] == [m.id for m in want]
    for a, b in zip(got, want):
        assert a.section == b.section and a.index == b.index and a.diameter_mm == b.diameter_mm
        assert max(abs(u - v) for u, v in zip(a.center_mm, b.center_mm)) < 1e-12
        assert max(abs(u - v) for u, v in zip(a.normal, b.normal)) < 1e-12


def _first_of_each(markers, n: int) -> list:
    return [m for m in markers if m["index"] < n]


def _swap_sections(markers) -> None:
    """A and B's labels exchanged (ids too), positions kept: what a hand-edited layout gets wrong."""
    for m in markers:
        m["section"] = "B" if m["section"] == "A" else "A"
        m["id"] = m["section"] + str(m["index"])


def _write(tmp_path, edit):
    from dockfactory.core.config import load_config
    from dockfactory.core.resources import shipped_config
    from dockfactory.generator.datasets.folder import layout_record
    rec = layout_record(load_config(shipped_config("smoke")))
    edit(rec)
    path = tmp_path / "layout.json"
    path.write_text(json.dumps(rec))
    return path


@pytest.mark.parametrize("edit, where", [
    (lambda r: r["markers"][0].update(normal=[0, 0, 2]), "markers[0].normal"),
    (lambda r: r["markers"][1].update(center_mm=[1, 2]), "markers[1].center_mm"),
    (lambda r: r["markers"][1].update(center_mm=[1, 2, float("nan")]), "markers[1].center_mm"),
    (lambda r: r["markers"][2].update(section="C"), "markers[2].section"),
    (lambda r: r["markers"][2].pop("diameter_mm"), "markers[2].diameter_mm"),
    (lambda r: r["markers"][3].update(diameter_mm=-1), "markers[3].diameter_mm"),
    (lambda r: r["markers"][3].update(index=True), "markers[3].index"),
    (lambda r: r["markers"][4].update(id=r["markers"][0]["id"]), "used twice"),
    (lambda r: r.update(markers=[m for m in r["markers"] if m["section"] == "A"]), "section B: 0 markers"),
    (lambda r: r.update(markers={}), "markers: expected a list"),
    (lambda r: r.update(markers=_first_of_each(r["markers"], 4)), "section A: 4 markers, at least 6 needed"),
    (lambda r: r["markers"][5].update(center_mm=[-1e30, 0, 0]), "markers[5].center_mm"),
    (lambda r: r["markers"][5].update(diameter_mm=1e30), "markers[5].diameter_mm"),
    (lambda r: _swap_sections(r["markers"]), "are sections A and B swapped"),
    (lambda r: r["markers"][1].update(center_mm=r["markers"][0]["center_mm"]), "apart"),
], ids=["normal-length", "centre-short", "centre-nan", "section", "no-diameter", "negative-diameter",
        "bool-index", "duplicate-id", "no-B", "not-a-list", "four-per-section", "huge-coordinate",
        "huge-diameter", "swapped-sections", "overlapping"])
def test_bad_layouts_are_one_line_errors(tmp_path, edit, where):
    path = _write(tmp_path, edit)
    with pytest.raises(LayoutFileError) as exc:
        read_layout_file(path)
    msg = str(exc.value)
    assert str(path) in msg and where in msg and "\n" not in msg


@pytest.mark.parametrize("content", ["", "[]", "null", "{", "\xff"])
def test_unreadable_layouts(tmp_path, content):
    path = tmp_path / "layout.json"
    path.write_bytes(content.encode("latin-1"))
    with pytest.raises(LayoutFileError, match="layout"):
        read_layout_file(path)
    with pytest.raises(LayoutFileError, match="not found"):
        read_layout_file(tmp_path / "nope.json")


def test_a_layout_beyond_the_identification_limit_is_refused(tmp_path):
    from dockfactory.core.layout_file import MAX_MARKERS_PER_SECTION
    n = MAX_MARKERS_PER_SECTION + 1
    markers = [{"id": f"{s}{i}", "section": s, "index": i, "center_mm": [(-1 if s == "A" else 1) * (20 + 30 * i), 0, 300],
                "normal": [0, 0, 1], "diameter_mm": 12.0} for s, count in (("A", n), ("B", 6)) for i in range(count)]
    path = tmp_path / "layout.json"
    path.write_text(json.dumps({"markers": markers}))
    with pytest.raises(LayoutFileError, match=f"section A has {n} markers, at most {MAX_MARKERS_PER_SECTION} per section"):
        read_layout_file(path)


def test_sigma_mm_per_layout_and_per_marker(tmp_path):
    """A layout's ``sigma_mm`` applies to every marker, a marker's own overrides it; none stated:
    None (no layout term in the budget)."""
    assert read_layout_sigmas(_write(tmp_path, lambda r: None)) is None

    def edit(r):
        r["sigma_mm"] = 0.02
        r["markers"][3]["sigma_mm"] = 0.05
    path = _write(tmp_path, edit)
    markers, sigmas = read_layout_file(path), read_layout_sigmas(path)
    assert set(sigmas) == {m.id for m in markers}
    assert sigmas[markers[3].id] == 0.05
    assert all(v == 0.02 for k, v in sigmas.items() if k != markers[3].id)
    only = read_layout_sigmas(_write(tmp_path, lambda r: r["markers"][0].update(sigma_mm=0.01)))
    assert only[markers[0].id] == 0.01 and only[markers[1].id] == 0.0   # unstated: taken as exact


@pytest.mark.parametrize("edit, where", [
    (lambda r: r.update(sigma_mm=-0.01), "sigma_mm: expected a number in [0, 10] mm"),
    (lambda r: r.update(sigma_mm="0.02"), "sigma_mm: expected a number"),
    (lambda r: r.update(sigma_mm=True), "sigma_mm: expected a number"),
    (lambda r: r.update(sigma_mm=50.0), "sigma_mm: expected a number in [0, 10] mm"),
    (lambda r: r["markers"][2].update(sigma_mm=float("nan")), "markers[2].sigma_mm"),
], ids=["negative", "string", "bool", "huge", "marker-nan"])
def test_bad_sigma_mm_is_a_one_line_error(tmp_path, edit, where):
    path = _write(tmp_path, edit)
    read_layout_file(path)   # the markers themselves are fine
    with pytest.raises(LayoutFileError) as exc:
        read_layout_sigmas(path)
    msg = str(exc.value)
    assert str(path) in msg and where in msg and "\n" not in msg
