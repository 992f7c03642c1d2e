"""eval.confidence.studentized_rmse_bounds: the bootstrap-t bound of an RMSE (log mean square).
Its coverage is measured by bench/verdict/confidence_coverage.py (bench/results/confidence/); here its
contract: it brackets the measured RMSE, is equivariant to the unit, is reproducible from its
seed, widens with heavy tails, and is not computed where it cannot be."""
import math

import numpy as np
import pytest

from dockfactory.eval.confidence import MIN_BOOTSTRAP_N, rmse_bounds, studentized_rmse_bounds


def _rmse(e):
    return math.sqrt(float(np.mean(np.square(e))))


def test_brackets_the_rmse_is_unit_equivariant_and_seeded():
    e = np.random.default_rng(1).normal(0.0, 0.3, 30)
    lo, up = studentized_rmse_bounds(e, 0.95, seed=4)
    assert lo < _rmse(e) < up
    lo10, up10 = studentized_rmse_bounds(10 * e, 0.95, seed=4)
    assert (lo10, up10) == pytest.approx((10 * lo, 10 * up), rel=1e-9)
    assert studentized_rmse_bounds(e, 0.95, seed=4) == (lo, up)
    lo99, up99 = studentized_rmse_bounds(e, 0.99, seed=4)
    assert lo99 < lo and up99 > up


def test_an_outlier_widens_the_upper_bound_more_than_the_chi_square_one():
    """One gross error among 20: the studentized bound reaches further above the RMSE than the
    Gaussian chi-square bound, which sees only the sum of squares."""
    e = np.random.default_rng(2).normal(0.0, 1.0, 20)
    e[0] = 8.0
    b = rmse_bounds(e, 0.95, seed=0)
    assert b["bootstrap"]["upper"] > b["chi2"]["upper"] and b["upper_by"] == "bootstrap"
    assert b["upper"] == b["bootstrap"]["upper"]


@pytest.mark.parametrize("errors", [np.ones(MIN_BOOTSTRAP_N - 1), np.full(10, 0.5), np.zeros(10)])
def test_not_computed_with_too_few_or_constant_errors(errors):
    assert studentized_rmse_bounds(errors, 0.95, seed=0) is None
    b = rmse_bounds(errors, 0.95, seed=0)
    assert b["bootstrap"] is None and b["upper_by"] == "chi2"


def test_heavy_tails_are_flagged_and_named_in_the_criterion():
    """An error sample with a few gross errors is flagged (kurtosis beyond three Gaussian standard
    errors); a Gaussian one is not; the criterion's bounds_by says so."""
    from dockfactory.eval.acceptance import _bounds_of
    from dockfactory.eval.confidence import tail_check
    rng = np.random.default_rng(3)
    gauss = rng.normal(0.0, 1.0, 100)
    assert 2.0 < tail_check(gauss)["kurtosis"] < 4.0 and not tail_check(gauss)["heavy_tailed"]
    heavy = gauss.copy()
    heavy[:3] = 8.0
    assert tail_check(heavy)["heavy_tailed"] and tail_check(heavy)["kurtosis"] > 3 + 3 * math.sqrt(24 / 100)
    assert tail_check(np.ones(3)) == {"kurtosis": None, "heavy_tailed": False}
    metrics = {"bounds": {"localization": {"x": rmse_bounds(heavy, 0.95, seed=0)}}}
    row = _bounds_of(metrics, "localization", "x", "rmse", 1.0)
    assert "heavy tails (kurtosis" in row["bounds_by"] and "may undercover" in row["bounds_by"]
    metrics = {"bounds": {"localization": {"x": rmse_bounds(gauss, 0.95, seed=0)}}}
    assert "heavy" not in _bounds_of(metrics, "localization", "x", "rmse", 1.0)["bounds_by"]
