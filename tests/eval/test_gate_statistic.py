"""One owner for the gate's statistic: every consumer converts through eval.gate_statistic; a spec
in mse judges exactly as the same spec in rmse (thresholds squared), and one in p95 (the 95th
percentile of |e|, distribution-free order-statistic bounds) as its rmse twin at 1.96 x the
threshold on Gaussian errors with enough frames."""
from __future__ import annotations

import math
import re

import numpy as np
import pytest

from dockfactory.eval.gate_statistic import STATISTICS, gate_statistic


def test_conversions_and_units():
    mse = gate_statistic("mse")
    assert mse.unit("mm") == "mm^2" and gate_statistic("rmse").unit("deg") == "deg"
    assert mse.to_rms(0.09) == pytest.approx(0.3) and mse.from_rms(0.3) == pytest.approx(0.09)
    assert gate_statistic("rmse").to_rms(0.3) == 0.3
    for s in STATISTICS.values():
        assert s.to_rms(s.from_rms(0.37)) == pytest.approx(0.37)
    with pytest.raises(ValueError, match="'p99' is not one of rmse, mse, p95"):
        gate_statistic("p99")


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


# ----------------------------------------------------------------------------- p95 of |e|

P95_TRUE = {"gauss": 1.959963984540054, "laplace": math.log(20.0), "t3": 3.182446305284263}   # of |e|, unit scale


def _draws(kind: str, rng, shape):
    return {"gauss": rng.normal, "laplace": rng.laplace, "t3": lambda size: rng.standard_t(3, size)}[kind](size=shape)


def _spec(tmp_path, name: str, statistic: str, thresholds: dict, rule: str = "guarded", confidence: float = 0.95):
    from dockfactory.eval.acceptance import load_acceptance
    gates = "\n".join(f"{c} = {v!r}" for c, v in thresholds.items())
    (tmp_path / name).write_text(f'decision_rule = "{rule}"\nconfidence = {confidence}\n[estimation]\ngated = false\n'
                                 f'[localization]\nstatistic = "{statistic}"\n{gates}\n[failures]\nmax_rate = 1.0\n')
    return load_acceptance(tmp_path / name)


def _verdict_of(errors: dict, spec) -> dict:
    """The verdict of test rows with these errors per component (no repeatability captures)."""
    from dockfactory.eval.acceptance import COMPONENTS, verdict
    from dockfactory.eval.evaluate import statistic_bounds
    from dockfactory.eval.pose_metrics import error_stats, repeatability
    n = len(next(iter(errors.values())))
    rows = [{"ok": True, **{f"err_{c}": float(errors.get(c, np.zeros(n))[i]) for c in COMPONENTS}} for i in range(n)]
    loc = {"n_frames": n, "n_solved": n, "overall": {c: error_stats([r[f"err_{c}"] for r in rows]) for c in COMPONENTS}}
    metrics = {"localization": loc, "estimation": {**repeatability({}), "n_frames": 0, "n_solved": 0},
               "bounds": statistic_bounds(rows, [], spec), "failures_test": {}}
    return verdict(metrics, spec)


def test_p95_units_value_and_gaussian_conversion():
    p95 = gate_statistic("p95")
    assert p95.unit("mm") == "mm" and p95.header() == "p95 |e|"
    assert p95.from_rms(1.0) == pytest.approx(1.95996, abs=1e-5) and p95.to_rms(1.95996) == pytest.approx(1.0, abs=1e-5)
    e = np.random.default_rng(1).normal(0.0, 0.3, 57)
    from dockfactory.eval.pose_metrics import error_stats
    assert p95.value(e) == float(np.percentile(np.abs(e), 95)) == error_stats(e)["p95"]
    assert p95.value([]) is None


def test_a_spec_in_p95_judges_as_its_rmse_twin_on_gaussian_errors(tmp_path):
    """Enough frames of Gaussian errors: a p95 threshold of 1.96 x an RMS threshold gives the
    verdict the RMS spec gives, criterion by criterion, under both rules."""
    rng = np.random.default_rng(7)
    sigma = {"x": 0.4, "y": 0.25, "alpha": 0.02, "beta": 0.05}
    errors = {c: rng.normal(0.0, s, 3000) for c, s in sigma.items()}
    rms_thr = {"x": 0.4 * 0.9, "y": 0.25 * 1.1, "alpha": 0.02 * 1.15, "beta": 0.05 * 0.85}
    p95_thr = {c: 1.959964 * t for c, t in rms_thr.items()}
    for rule in ("guarded", "simple"):
        by_rms = _verdict_of(errors, _spec(tmp_path, f"r_{rule}.toml", "rmse", rms_thr, rule))
        by_p95 = _verdict_of(errors, _spec(tmp_path, f"p_{rule}.toml", "p95", p95_thr, rule))
        decisions = [[(c["name"], c["decision"]) for c in v["criteria"] if c["block"] == "localization"]
                     for v in (by_rms, by_p95)]
        assert decisions[0] == decisions[1]
        assert [d for _, d in decisions[1]] == ["fail", "pass", "pass", "fail"]
        assert by_rms["verdict"] == by_p95["verdict"] == "REJECTED"
    row = next(c for c in by_p95["criteria"] if c["component"] == "y")
    assert row["unit"] == "mm" and row["lower"] < row["value"] < row["upper"] and "binomial" in row["bounds_by"]


@pytest.mark.parametrize("n, confidence", [(40, 0.8), (100, 0.95)])
@pytest.mark.parametrize("kind", ["gauss", "laplace", "t3"])
def test_the_order_statistic_bounds_cover_the_true_p95(n, confidence, kind):
    """2000 seeded samples: each one-sided bound misses the true p95 of |e| in at most
    (1 - confidence) of them (plus three binomial standard errors of the 2000), whatever the
    distribution's tails; and not in almost none (a bound that always covered would be too wide)."""
    p95 = gate_statistic("p95")
    rng = np.random.default_rng(2024)
    samples = _draws(kind, rng, (2000, n))
    b = [p95.bounds(e, confidence, seed=0) for e in samples]
    slack = 3 * math.sqrt(confidence * (1 - confidence) / 2000)
    for missed in (np.mean([r["upper"] < P95_TRUE[kind] for r in b]), np.mean([r["lower"] > P95_TRUE[kind] for r in b])):
        assert 0.3 * (1 - confidence) < missed <= 1 - confidence + slack


def test_too_few_frames_give_no_upper_bound_and_the_guarded_rule_does_not_pass(tmp_path):
    from dockfactory.eval.gate_statistic import order_ranks
    assert order_ranks(58, 0.95, 0.95)[1] is None and order_ranks(59, 0.95, 0.95)[1] == 59
    errors = {"x": np.random.default_rng(3).normal(0.0, 0.01, 45)[:40]}    # far within the threshold
    guarded = _verdict_of(errors, _spec(tmp_path, "g.toml", "p95", {"x": 1.0}))
    row = guarded["criteria"][0]
    assert row["upper"] is None and row["decision"] == "fail" and not row["pass"]
    assert "from 40 values" in row["note"] and "from 59" in row["note"]
    assert _verdict_of(errors, _spec(tmp_path, "s.toml", "p95", {"x": 1.0}, "simple"))["criteria"][0]["pass"]
    assert _verdict_of({"x": np.random.default_rng(3).normal(0.0, 0.01, 45)}, _spec(tmp_path, "g90.toml", "p95", {"x": 1.0}, confidence=0.9)
                       )["criteria"][0]["decision"] == "pass"   # 45 frames suffice at 90 %


@pytest.mark.parametrize("rms", [0.9, 1.12])
def test_p95_pass_and_reject_probabilities_are_the_guarded_rule_s_frequencies(rms):
    p95 = gate_statistic("p95")
    rng = np.random.default_rng(11)
    bounds = [p95.bounds(e, 0.95, seed=0) for e in rng.normal(0.0, rms, (2000, 120))]
    thr = p95.from_rms(1.0)
    assert abs(np.mean([b["upper"] <= thr for b in bounds]) - p95.pass_probability(rms, 1.0, 120, 0.95)) < 0.03
    assert abs(np.mean([b["lower"] > thr for b in bounds]) - p95.reject_probability(rms, 1.0, 120, 0.95)) < 0.03
    assert p95.pass_probability(rms, 1.0, 50, 0.95) == 0.0   # no upper bound from 50 frames


def test_p95_plans_frames_conformity_and_design_through_the_gaussian_model(tmp_path):
    from dockfactory.eval.conformity import pose_tolerances
    from dockfactory.eval.design_rank import pass_probability
    from dockfactory.eval.frame_planner import plan_frames
    p95 = gate_statistic("p95")
    assert p95.frames_to_decide(0.0, 1.0, 1, 0.95) == 59 and p95.frames_to_decide(1.0, 1.0, 1, 0.95) is None
    spec_r = _spec(tmp_path, "r.toml", "rmse", {"x": 0.3, "alpha": 0.02})
    spec_p = _spec(tmp_path, "p.toml", "p95", {"x": 0.3 * 1.959964, "alpha": 0.02 * 1.959964})
    expected = {"localization": {"x": 0.25, "alpha": 0.023}}
    rows_r, rows_p = plan_frames(spec_r, expected), plan_frames(spec_p, expected)
    assert [r["threshold"] for r in rows_p] == pytest.approx([r["threshold"] for r in rows_r], rel=1e-6)
    assert [r["proves"] for r in rows_p] == [r["proves"] for r in rows_r] == ["conformance", "non-conformance"]
    assert all(p["frames"] > r["frames"] for p, r in zip(rows_p, rows_r))   # distribution-free costs frames
    n = rows_p[0]["frames"]
    assert 0.3 < pass_probability(0.25, 0.3, n, 0.95, "p95") < 0.8   # the count puts the bound at its median
    assert pose_tolerances(spec_p) == pytest.approx(pose_tolerances(spec_r), rel=1e-6)


def test_an_undecided_p95_criterion_says_how_many_frames_would_decide_it(tmp_path):
    e = np.random.default_rng(5).normal(0.0, 1.0, 200)
    p95 = gate_statistic("p95")
    between = (p95.value(e) + p95.bounds(e, 0.95, seed=0)["upper"]) / 2   # within the value's bounds
    row = _verdict_of({"x": e}, _spec(tmp_path, "u.toml", "p95", {"x": between}))["criteria"][0]
    assert row["decision"] == "undecided" and "more test frames would decide it" in row["note"]


@pytest.mark.parametrize("text, words", [
    ('[estimation]\nstatistic = "p95"\nx = 1.0\n', "[estimation] statistic: 'p95': a percentile of |e| gates "
                                                  "localization only"),
    ('[localization]\nstatistic = "p99"\nx = 1.0\n', "[localization] statistic: 'p99' is not one of rmse, mse, p95"),
])
def test_a_statistic_the_spec_cannot_gate_is_one_line_naming_file_table_key_value(tmp_path, text, words):
    from dockfactory.core.config import ConfigError
    from dockfactory.eval.acceptance import load_acceptance
    (tmp_path / "s.toml").write_text(text)
    with pytest.raises(ConfigError) as exc:
        load_acceptance(tmp_path / "s.toml")
    msg = str(exc.value)
    assert msg.startswith(str(tmp_path / "s.toml")) and words in msg and "\n" not in msg
