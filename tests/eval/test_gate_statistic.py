"""One owner for the gate's statistic: every consumer converts through eval.gate_statistic, and a
spec in mse judges exactly as the same spec in rmse (thresholds squared)."""
from __future__ import annotations

import math
import re

import pytest

from dockfactory.eval.gate_statistic import STATISTICS, gate_statistic


def test_conversions_and_units():
    mse = gate_statistic("mse")
    assert mse.unit("mm") == "mm^2" and gate_statistic("rmse").unit("deg") == "deg"
    assert mse.to_rms(0.09) == pytest.approx(0.3) and mse.from_rms(0.3) == pytest.approx(0.09)
    assert gate_statistic("rmse").to_rms(0.3) == 0.3
    for s in STATISTICS.values():
        assert s.to_rms(s.from_rms(0.37)) == pytest.approx(0.37)
    with pytest.raises(ValueError, match="'p95' is not one of rmse, mse"):
        gate_statistic("p95")


def test_no_module_branches_on_the_statistic_s_name(repo_root):
    """The comparisons `statistic == "mse"` live in eval/gate_statistic.py only."""
    pattern = re.compile(r"""statistic["'\]]*\s*[!=]=\s*["']r?mse["']""")
    offenders = [str(p.relative_to(repo_root)) for folder in ("eval", "dockfactory", "core", "solver", "generator")
                 for p in (repo_root / folder).rglob("*.py") if pattern.search(p.read_text())]
    assert offenders == []


def test_no_module_lists_the_statistics_or_reads_their_powers(repo_root):
    """Outside eval/gate_statistic.py no module names the statistics as a set (a pair of names) or
    reads a statistic's power: they ask the owner."""
    pattern = re.compile(r"""["']r?mse["']\s*,\s*["']r?mse["']|(statistic|\))\.power\b|\]\.power\b""")
    offenders = [str(p.relative_to(repo_root)) for folder in ("eval", "dockfactory", "core", "solver", "generator")
                 for p in (repo_root / folder).rglob("*.py")
                 if p.name != "gate_statistic.py" and pattern.search(p.read_text())]
    assert offenders == []


def test_a_spec_in_mse_plans_and_judges_as_its_rmse_twin(tmp_path):
    from dockfactory.eval.acceptance import load_acceptance
    from dockfactory.eval.frame_planner import plan_frames
    text = ('decision_rule = "guarded"\nconfidence = 0.95\n[localization]\nstatistic = "{s}"\n'
            'x = {x}\ny = {y}\nalpha = {a}\n')
    (tmp_path / "r.toml").write_text(text.format(s="rmse", x=0.3, y=0.2, a=0.02))
    (tmp_path / "m.toml").write_text(text.format(s="mse", x=0.09, y=0.04, a=0.0004))
    expected = {"localization": {"x": 0.2, "y": 0.19, "alpha": 0.01}}
    rows_r = plan_frames(load_acceptance(tmp_path / "r.toml"), expected)
    rows_m = plan_frames(load_acceptance(tmp_path / "m.toml"), expected)
    assert [r["frames"] for r in rows_r] == [r["frames"] for r in rows_m]
    assert all(math.isclose(a["threshold"], b["threshold"]) for a, b in zip(rows_r, rows_m))
