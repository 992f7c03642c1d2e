"""The speeds the README and docs quote come from timed runs (bench/results/speeds/speeds.json):
every quoted figure of a record appears in the README or docs/ and is its measurement rounded
(minutes, seconds a frame, frames/s), and every timing figure the README states (a number of
minutes, seconds, hours or frames/s) is one of the records' quoted phrases. A speed typed into the
README without a record, or a record the text no longer says, fails here."""
from __future__ import annotations

import json
import re

RECORDS = "bench/results/speeds/speeds.json"
TIMING = re.compile(r"\b\d+(?:\.\d+)?\s*(?:minutes?|min\b|seconds?|s a frame|s per frame|s/frame|frames/s|hours?)")


def _records(repo_root) -> dict:
    return json.loads((repo_root / RECORDS).read_text())["records"]


def _measured(rec: dict, quoted: str) -> float:
    """The record's figure in the unit of its quoted phrase."""
    if "frames/s" in quoted:
        return rec["frames_per_s"]
    return rec["seconds"] / 60.0 if "minute" in quoted else rec["seconds"]


def test_every_record_is_quoted_as_measured(repo_root):
    texts = [(repo_root / "README.md").read_text()] + [p.read_text() for p in sorted((repo_root / "docs").glob("*.md"))]
    for name, rec in _records(repo_root).items():
        if not rec["quoted"]:
            continue
        assert any(rec["quoted"] in t for t in texts), f"{name}: {rec['quoted']!r} is quoted nowhere"
        number = float(re.search(r"\d+(?:\.\d+)?", rec["quoted"]).group())
        assert round(_measured(rec, rec["quoted"])) == number, (name, rec)


def test_every_timing_the_readme_states_has_a_record(repo_root):
    text = (repo_root / "README.md").read_text()
    quoted = [r["quoted"] for r in _records(repo_root).values() if r["quoted"]]
    stray = [m.group() for m in TIMING.finditer(text) if not any(m.group() in q for q in quoted)]
    assert not stray, f"README speeds without a record in {RECORDS}: {stray}"
