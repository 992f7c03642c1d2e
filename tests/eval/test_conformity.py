"""eval.conformity: the ISO 14253-1 guarded decision of one measured value, on both sides of
each threshold, its exit statuses, and the tolerances an acceptance spec gives a single pose."""
import math

import pytest

from dockfactory.core.errors import DockfactoryError
from dockfactory.eval.acceptance import AcceptanceSpec, Gate, verdict_exit_status
from dockfactory.eval.conformity import (
    IN,
    OUT,
    UNDECIDED,
    conformity,
    coverage_k,
    exit_status,
    pose_conformity,
    pose_tolerances,
    worst,
)

EPS = 1e-9


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_in_out_undecided_on_both_sides_of_each_limit(sign):
    """T = 5, u = 0.5, U = 1: IN up to |y| = 4, OUT beyond |y| = 6, UNDECIDED between (the
    negative side of the zone alike)."""
    t, u = 5.0, 0.5
    assert conformity(sign * (4.0 - EPS), u, t) == IN
    assert conformity(sign * 4.0, u, t) == IN             # |y| + U = T: the interval touches the limit
    assert conformity(sign * (4.0 + 1e-6), u, t) == UNDECIDED
    assert conformity(sign * 5.0, u, t) == UNDECIDED
    assert conformity(sign * 6.0, u, t) == UNDECIDED      # |y| - U = T is not beyond it
    assert conformity(sign * (6.0 + 1e-6), u, t) == OUT
    assert conformity(0.0, u, t) == IN


def test_the_guard_band_scales_with_k_and_simple_has_none():
    assert conformity(4.5, 0.5, 5.0, k=1.0) == IN         # U = 0.5
    assert conformity(4.5, 0.5, 5.0, k=2.0) == UNDECIDED  # U = 1
    assert conformity(5.0, 0.5, 5.0, k=0.0) == IN         # simple rule: the value alone
    assert conformity(5.0 + 1e-9, 0.5, 5.0, k=0.0) == OUT
    assert coverage_k(AcceptanceSpec()) == 2.0
    assert coverage_k(AcceptanceSpec(decision_rule="simple")) == 0.0


@pytest.mark.parametrize("value,std", [(None, 0.1), (1.0, None), (math.nan, 0.1), (1.0, math.inf), (1.0, -0.1)])
def test_no_value_or_no_uncertainty_proves_nothing(value, std):
    assert conformity(value, std, 5.0) == UNDECIDED


@pytest.mark.parametrize("tol,k", [(0.0, 2.0), (-1.0, 2.0), (math.nan, 2.0), (math.inf, 2.0), (5.0, -1.0)])
def test_bad_tolerance_or_k_is_refused(tol, k):
    with pytest.raises(ValueError):
        conformity(1.0, 0.1, tol, k)


def test_worst_and_exit_status_follow_the_verdicts_convention():
    assert worst([IN, IN]) == IN and worst([]) == IN
    assert worst([IN, UNDECIDED]) == UNDECIDED
    assert worst([UNDECIDED, OUT, IN]) == OUT
    assert (exit_status(IN), exit_status(OUT), exit_status(UNDECIDED)) == (0, 1, 3)
    # the same numbers as evaluate's verdict
    assert exit_status(IN) == verdict_exit_status("ACCEPTED")
    assert exit_status(OUT) == verdict_exit_status("REJECTED")
    assert exit_status(UNDECIDED) == verdict_exit_status("NOT PROVEN")


def test_tolerances_come_from_the_localization_table():
    assert pose_tolerances(AcceptanceSpec()) == {"x_mm": 5.0, "y_mm": 5.0, "alpha_deg": 0.1}
    mse = AcceptanceSpec(localization=Gate(statistic="mse", x=4.0, gamma=0.01))
    assert pose_tolerances(mse) == pytest.approx({"x_mm": 2.0, "gamma_deg": 0.1})   # square roots
    with pytest.raises(DockfactoryError, match=r"spec.toml: \[localization\] gates no component"):
        pose_tolerances(AcceptanceSpec(localization=Gate(gated=False)), "spec.toml")


def test_pose_conformity_takes_the_worst_component():
    tol = {"x_mm": 5.0, "y_mm": 5.0, "alpha_deg": 0.1}
    pose = {"x_mm": 1.0, "y_mm": -4.7, "alpha_deg": 0.02, "z_mm": 300.0}
    std = {"x_mm": 0.2, "y_mm": 0.2, "alpha_deg": 0.01, "z_mm": 1.0}
    out = pose_conformity(pose, std, tol)
    assert {n: c["decision"] for n, c in out["components"].items()} == {"x_mm": IN, "y_mm": UNDECIDED,
                                                                        "alpha_deg": IN}
    assert out["decision"] == UNDECIDED and out["components"]["y_mm"]["U"] == pytest.approx(0.4)
    assert "z_mm" not in out["components"]                # not gated: not judged
    pose["alpha_deg"] = 0.2
    assert pose_conformity(pose, std, tol)["decision"] == OUT
