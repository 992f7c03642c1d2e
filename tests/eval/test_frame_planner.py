"""eval.frame_planner: the number of frames at which the guarded rule's chi-square bound decides,
on both sides of the threshold, for rmse and mse specs and both blocks."""
import pytest

from dockfactory.core.errors import DockfactoryError
from dockfactory.eval.acceptance import AcceptanceSpec, Gate
from dockfactory.eval.confidence import chi2_bounds
from dockfactory.eval.frame_planner import plan_frames, plan_lines

SPEC = AcceptanceSpec()   # localization x, y 5 mm, alpha 0.1 deg; estimation x, y 1 mm, alpha 0.05 deg


def _row(rows, block, c):
    return next(r for r in rows if r["block"] == block and r["component"] == c)


@pytest.mark.parametrize("rmse", [0.5, 2.0, 4.0, 4.9])
def test_the_count_is_the_first_at_which_the_upper_bound_is_within(rmse):
    rows = plan_frames(SPEC, {"localization": {"x": rmse, "y": 1.0, "alpha": 0.01}})
    n = _row(rows, "localization", "x")["frames"]
    assert _row(rows, "localization", "x")["proves"] == "conformance"
    assert chi2_bounds(rmse * rmse * n, n, 0.95)[1] <= 5.0
    if n > 1:
        assert chi2_bounds(rmse * rmse * (n - 1), n - 1, 0.95)[1] > 5.0


def test_both_sides_of_the_threshold():
    below = _row(plan_frames(SPEC, {"localization": {"x": 4.9, "y": 1, "alpha": 0.01}}), "localization", "x")
    above = _row(plan_frames(SPEC, {"localization": {"x": 5.1, "y": 1, "alpha": 0.01}}), "localization", "x")
    at = _row(plan_frames(SPEC, {"localization": {"x": 5.0, "y": 1, "alpha": 0.01}}), "localization", "x")
    assert below["proves"] == "conformance" and below["frames"] > 100          # a thin margin costs frames
    assert above["proves"] == "non-conformance" and above["frames"] > 100
    assert at["proves"] is None and at["frames"] is None
    lines = plan_lines(plan_frames(SPEC, {"localization": {"x": 5.0, "y": 1, "alpha": 0.01}}))
    assert any("no number of test frames decides it" in line for line in lines)
    assert lines[-1] == "localization: conformance cannot be proven at these figures"


def test_margin_drives_the_count_and_mse_thresholds_are_rooted():
    counts = [_row(plan_frames(SPEC, {"localization": {"x": m * 5.0, "y": 1, "alpha": 0.01}}), "localization",
                   "x")["frames"] for m in (0.5, 0.7, 0.8, 0.9)]
    assert counts == sorted(counts) and counts[0] < counts[-1]
    mse = AcceptanceSpec(localization=Gate(statistic="mse", x=25.0))
    rooted = _row(plan_frames(mse, {"localization": {"x": 4.0}}), "localization", "x")
    plain = _row(plan_frames(SPEC, {"localization": {"x": 4.0, "y": 1, "alpha": 0.01}}), "localization", "x")
    assert rooted["threshold"] == 5.0 and rooted["frames"] == plain["frames"]


def test_estimation_counts_degrees_of_freedom_and_a_missing_figure_is_refused():
    rows = plan_frames(SPEC, {"estimation": {"x": 0.5, "y": 0.5, "alpha": 0.02}})
    assert {r["block"] for r in rows} == {"estimation"}
    assert plan_lines(rows)[-1].startswith("estimation: ") and "degrees of freedom" in plan_lines(rows)[-1]
    with pytest.raises(DockfactoryError, match=r"\[localization\] gates alpha but no expected figure"):
        plan_frames(SPEC, {"localization": {"x": 0.5, "y": 0.5}})
