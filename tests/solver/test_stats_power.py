"""The chi-square's inverse and the noncentral chi-square's tail (solver.stats): the power of the
camera-model check against a shifted principal point, which the goodness-of-fit gate reads."""
from __future__ import annotations

import math

import numpy as np
import pytest

from dockfactory.solver.stats import chi2_isf, chi2_logsf, f_isf, f_logsf, ncf_sf, ncp_for_power, ncx2_sf


@pytest.mark.parametrize("dof", [1, 2, 3, 7, 40])
@pytest.mark.parametrize("p", [0.5, 0.1, 1e-3, 1e-6])
def test_chi2_isf_inverts_the_survival_function(dof, p):
    assert math.exp(chi2_logsf(chi2_isf(p, dof), dof)) == pytest.approx(p, rel=1e-8)


def test_known_critical_values():
    assert chi2_isf(0.05, 1) == pytest.approx(3.841459, abs=1e-5)     # 1.96^2
    assert chi2_isf(0.1, 2) == pytest.approx(-2.0 * math.log(0.1), abs=1e-9)   # exponential for 2 dof


@pytest.mark.parametrize("dof, ncp", [(1, 3.0), (2, 10.46), (3, 0.5), (5, 30.0)])
def test_noncentral_tail_matches_sampling(dof, ncp):
    """Within 4 binomial standard errors of 200,000 seeded draws, at the 10 % critical value."""
    crit = chi2_isf(0.1, dof)
    draws = np.random.default_rng(7).noncentral_chisquare(dof, ncp, 200_000)
    share = float(np.mean(draws > crit))
    assert abs(ncx2_sf(crit, dof, ncp) - share) < 4.0 * math.sqrt(share * (1.0 - share) / draws.size) + 1e-4


def test_noncentral_tail_without_departure_is_the_central_one():
    assert ncx2_sf(4.0, 3, 0.0) == pytest.approx(math.exp(chi2_logsf(4.0, 3)), rel=1e-12)


def test_ncp_for_power_reaches_the_power_and_grows_with_dof():
    needed = [ncp_for_power(q, 0.1, 0.9) for q in (1, 2, 3, 4)]
    for q, ncp in zip((1, 2, 3, 4), needed):
        assert ncx2_sf(chi2_isf(0.1, q), q, ncp) == pytest.approx(0.9, abs=1e-6)
    assert needed == sorted(needed) and needed[0] == pytest.approx(8.56, abs=0.01)


@pytest.mark.parametrize("bad", [0.0, 1.0, -0.5])
def test_bad_probabilities_are_refused(bad):
    with pytest.raises(ValueError):
        ncp_for_power(2, 0.1, bad)
    with pytest.raises(ValueError):
        chi2_isf(bad, 2)


@pytest.mark.parametrize("d1, d2, ncp", [(1, 10, 9.0), (2, 19, 11.8), (3, 40, 4.0)])
def test_noncentral_f_tail_matches_sampling(d1, d2, ncp):
    """Within 4 binomial standard errors of 200,000 seeded draws, at the F's 10 % critical value."""
    crit = f_isf(0.1, d1, d2)
    rng = np.random.default_rng(11)
    draws = (rng.noncentral_chisquare(d1, ncp, 200_000) / d1) / (rng.chisquare(d2, 200_000) / d2)
    share = float(np.mean(draws > crit))
    assert abs(ncf_sf(crit, d1, d2, ncp) - share) < 4.0 * math.sqrt(share * (1.0 - share) / draws.size) + 1e-4


def test_an_estimated_noise_needs_more_departure_for_the_same_power():
    """The F test (noise from the residuals) needs a larger noncentrality than the chi-square, and
    approaches it as the residual degrees of freedom grow."""
    chi = ncp_for_power(2, 0.1, 0.9)
    f = [ncp_for_power(2, 0.1, 0.9, d) for d in (10, 19, 200)]
    assert f[0] > f[1] > f[2] > chi and f[2] == pytest.approx(chi, rel=0.02)
    assert math.exp(f_logsf(f_isf(0.1, 2, 19), 2, 19)) == pytest.approx(0.1, rel=1e-8)
