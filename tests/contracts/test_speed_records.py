"""The speeds the README and docs quote come from timed runs (bench/results/speeds/speeds.json):
every quoted figure of a record appears in the README or docs/ and is its measurement rounded
(minutes, seconds a frame, frames/s), and every timing figure the README states (a number of
minutes, seconds, hours or frames/s) is one of the records' quoted phrases. Every timing figure
docs/*.md states is a record's quoted phrase, or sits in a passage that cites the measured
results it comes from, or is a target (test_every_timing_the_docs_state_is_recorded_cited_or_a_target
has the rule). A speed typed into the text without a record, or a record the text no longer says,
fails here."""
from __future__ import annotations

import json
import re
from pathlib import Path

RECORDS = "bench/results/speeds/speeds.json"
TIMING = re.compile(r"\b\d+(?:\.\d+)?\s*(?:minutes?|min\b|seconds?|s a frame|s per frame|s/frame|frames/s|hours?)")
# a path under bench/results/ or results/ (not a longer path that merely ends so)
CITATION = re.compile(r"(?<![\w/.-])(?:bench/)?results/[\w./-]*[\w/]")
# the word target(s) at most 25 characters from the figure, nothing between them ending the clause
TARGET_AFTER = re.compile(r"[^.,;:()]{0,25}?\btargets?\b", re.IGNORECASE)
TARGET_BEFORE = re.compile(r"\btargets?\b[^.,;:()]{0,25}$", re.IGNORECASE)
ITEM_START = re.compile(r"\s*(?:[-*+]|\d+\.)\s")


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


def passages(text: str) -> list[tuple[int, int]]:
    """(start, end) offsets of the text's passages: its blank-line separated blocks, each list item
    (from its marker line to the next marker line or the block's end) a passage of its own; a table
    or a code block without blank lines is one passage."""
    spans, start, pos = [], None, 0
    for line in text.splitlines(keepends=True):
        if not line.strip():
            if start is not None:
                spans.append((start, pos))
            start = None
        elif start is None:
            start = pos
        elif ITEM_START.match(line):
            spans.append((start, pos))
            start = pos
        pos += len(line)
    if start is not None:
        spans.append((start, pos))
    return spans


def _in_quoted_phrase(text: str, m: re.Match, quoted: list[str]) -> bool:
    """The figure lies inside an occurrence of a record's quoted phrase (line breaks allowed)."""
    for q in quoted:
        phrase = re.compile(r"\s+".join(re.escape(w) for w in q.split()))
        if any(p.start() <= m.start() and m.end() <= p.end() for p in phrase.finditer(text)):
            return True
    return False


def _is_target(text: str, m: re.Match) -> bool:
    return bool(TARGET_AFTER.match(text, m.end()) or TARGET_BEFORE.search(text[max(0, m.start() - 40):m.start()]))


def stray_timings(text: str, quoted: list[str], root: Path) -> list[str]:
    """The timing figures of ``text`` the docs rule (test_every_timing_the_docs_state_is_recorded_cited_or_a_target)
    does not allow, each with why."""
    stray = []
    for start, end in passages(text):
        cited = [c.group() for c in CITATION.finditer(text, start, end)]
        for m in TIMING.finditer(text, start, end):
            figure = " ".join(m.group().split())
            if _in_quoted_phrase(text, m, quoted) or _is_target(text, m):
                continue
            missing = [c for c in cited if not (root / c).exists()]
            if not cited or missing:
                why = f"cites {missing}, which do not exist" if missing else "cites no bench/results/ or results/ file"
                stray.append(f"{figure!r} (line {text.count(chr(10), 0, m.start()) + 1}: its passage {why})")
    return stray


def test_every_timing_the_docs_state_is_recorded_cited_or_a_target(repo_root):
    """Every match of TIMING in docs/*.md (a number of minutes, seconds, hours, seconds a frame or
    frames/s) is one of:
    (a) inside an occurrence of a record's quoted phrase (bench/results/speeds/speeds.json; line
        breaks within the phrase allowed);
    (b) in a passage that cites the measurement: a path under bench/results/ or results/ (e.g.
        `bench/results/stream_speed/README.md`, `bench/results/speeds`), and every such path the
        passage names exists in the repository. A passage is a blank-line separated block, except
        that each list item (a line starting with -, *, + or "N. ", to the next such line or the
        block's end) is a passage of its own; a table or a fenced block without blank lines is one;
    (c) a target, not a measurement: the word "target" or "targets" at most 25 characters after or
        before the figure with no . , ; : ( or ) between them ("the 15 frames/s target",
        "15 frames/s and 150 ms targets").
    Anything else is a speed without its record, and fails with its file, line and reason."""
    quoted = [r["quoted"] for r in _records(repo_root).values() if r["quoted"]]
    stray = {p.name: s for p in sorted((repo_root / "docs").glob("*.md"))
             if (s := stray_timings(p.read_text(), quoted, repo_root))}
    assert not stray, f"docs speeds with no record, no cited result and not a target: {stray}"


def test_the_docs_rule_tells_a_cited_figure_from_a_bare_one(tmp_path):
    (tmp_path / "bench/results/x").mkdir(parents=True)
    text = ("Renders take 4 s a frame (`bench/results/x`).\n\n"
            "- a bare 9 frames/s\n- 12 frames/s, cited: bench/results/x\n"
            "- 3 minutes in bench/results/gone.txt\n\n"
            "The 15 frames/s target is not met; 7 frames/s and 150 ms targets. About 5 s a frame.\n"
            "Met: 16.8\nframes/s, 2 s per frame.")
    stray = stray_timings(text, ["About 5 s a frame"], tmp_path)
    assert [s.split(" (")[0] for s in stray] == ["'9 frames/s'", "'3 minutes'", "'16.8 frames/s'", "'2 s per frame'"]
    assert "bench/results/gone.txt" in stray[1] and "line 3" in stray[0]
