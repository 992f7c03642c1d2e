"""Tail probabilities of the chi-square and F distributions, in log space (numpy-free math).

Bottom layer of the solver (no project imports). Used by the automatic camera-model choice
(:mod:`solver.model_choice`): the likelihood-ratio statistic of nested least-squares models is
chi-square with the number of added parameters as degrees of freedom when the pixel noise is
known, and F-distributed when it is estimated from the residuals. Log space, because a strongly
distorted lens gives p-values far below the smallest double and candidates are ranked by them.

Regularised incomplete gamma and beta functions by series and Lentz continued fractions
(Numerical Recipes, 3rd ed., 6.2 and 6.4); relative accuracy about 1e-12. Their inverses by
bisection, and the noncentral tails (Poisson mixtures of the central ones): a test's power, which
the goodness-of-fit gate can ask of the camera-model check (eval.fit_gate).
"""
from __future__ import annotations

import math

__all__ = ["chi2_logsf", "chi2_isf", "f_isf", "f_logsf", "ncx2_sf", "ncf_sf", "ncp_for_power"]

_EPS = 1e-15
_TINY = 1e-300
_MAX_TERMS = 500


def _lentz(term):
    """Modified Lentz evaluation of b0 + a1 / (b1 + a2 / (b2 + ...)) given ``term(i) -> (a_i,
    b_i)`` for i >= 1 and b0 = term(0)[1]; returns its log."""
    f = term(0)[1] or _TINY
    c, d, log_f = f, 0.0, math.log(abs(f))
    for i in range(1, _MAX_TERMS):
        a, b = term(i)
        d = b + a * d
        d = 1.0 / (d if abs(d) > _TINY else _TINY)
        c = b + a / c
        c = c if abs(c) > _TINY else _TINY
        delta = c * d
        log_f += math.log(abs(delta))
        if abs(delta - 1.0) < _EPS:
            break
    return log_f


def _log_gamma_q(a: float, x: float) -> float:
    """log of the regularised upper incomplete gamma Q(a, x)."""
    if x <= 0.0:
        return 0.0
    log_pre = a * math.log(x) - x - math.lgamma(a)
    if x < a + 1.0:                  # series for P, Q = 1 - P
        term, total, n = 1.0 / a, 1.0 / a, a
        for _ in range(_MAX_TERMS):
            n += 1.0
            term *= x / n
            total += term
            if term < total * _EPS:
                break
        p = math.exp(log_pre) * total
        return math.log1p(-p) if p < 1.0 else -math.inf
    # continued fraction for Q: 1 / (x + 1 - a - 1 (1 - a) / (x + 3 - a - ...))
    log_cf = _lentz(lambda i: (1.0, x + 1.0 - a) if i == 0 else
                    (-i * (i - a), x + 2.0 * i + 1.0 - a))
    return log_pre - log_cf


def _log_beta_cf(a: float, b: float, x: float) -> float:
    """log of the continued fraction of the incomplete beta function (NR betacf)."""
    def term(i):
        if i == 0:
            return 0.0, 1.0
        m, odd = divmod(i, 2)
        if odd:
            return -(a + m) * (a + b + m) * x / ((a + 2 * m) * (a + 2 * m + 1)), 1.0
        return m * (b - m) * x / ((a + 2 * m - 1) * (a + 2 * m)), 1.0
    return _lentz(term)


def _log_beta_inc(a: float, b: float, x: float) -> float:
    """log of the regularised incomplete beta I_x(a, b) for 0 < x < 1."""
    log_front = (math.lgamma(a + b) - math.lgamma(a) - math.lgamma(b) + a * math.log(x)
                 + b * math.log1p(-x))
    if x < (a + 1.0) / (a + b + 2.0):
        return log_front - _log_beta_cf(a, b, x) - math.log(a)
    other = math.exp(log_front - _log_beta_cf(b, a, 1.0 - x) - math.log(b))
    return math.log1p(-other) if other < 1.0 else -math.inf


def chi2_logsf(x: float, dof: int) -> float:
    """log P(chi2_dof > x): log of the chi-square survival function (``dof`` >= 1)."""
    if dof < 1:
        raise ValueError(f"dof must be >= 1, got {dof}")
    return _log_gamma_q(0.5 * dof, 0.5 * max(float(x), 0.0))


def chi2_isf(p: float, dof: int) -> float:
    """x with P(chi2_dof > x) = ``p`` (0 < p < 1), to about 1e-10 relative."""
    if not 0.0 < p < 1.0:
        raise ValueError(f"p must be in (0, 1), got {p}")
    return _bisect_up(lambda x: -chi2_logsf(x, dof), -math.log(p))


def _poisson_mixture(ncp: float, term) -> float:
    """sum_j Poisson(j; ncp / 2) term(j), summed until the weights left are below 1e-14: a
    noncentral chi-square's (or F's) tail from the central ones of dof + 2 j."""
    half = 0.5 * float(ncp)
    if half == 0.0:
        return term(0)
    total, left = 0.0, 1.0
    for j in range(int(half + 40.0 * math.sqrt(half) + 60)):
        w = math.exp(-half + j * math.log(half) - math.lgamma(j + 1.0))
        total += w * term(j)
        left -= w
        if left < 1e-14 and j > half:
            break
    return min(total, 1.0)


def ncx2_sf(x: float, dof: int, ncp: float) -> float:
    """P(X > x) of the noncentral chi-square with ``dof`` degrees of freedom and noncentrality
    ``ncp`` >= 0 (the power of a chi-square test against a departure whose expected statistic is
    dof + ncp)."""
    if ncp < 0:
        raise ValueError(f"ncp must be >= 0, got {ncp}")
    return _poisson_mixture(ncp, lambda j: math.exp(chi2_logsf(x, dof + 2 * j)))


def ncf_sf(x: float, d1: int, d2: int, ncp: float) -> float:
    """P(F' > x) of the noncentral F, (chi2_d1(ncp) / d1) / (chi2_d2 / d2): the power of an F test
    whose noise is estimated from d2 residual degrees of freedom."""
    if ncp < 0:
        raise ValueError(f"ncp must be >= 0, got {ncp}")
    return _poisson_mixture(ncp, lambda j: math.exp(f_logsf(x * d1 / (d1 + 2 * j), d1 + 2 * j, d2)))


def _bisect_up(f, target: float, lo: float = 0.0, hi: float = 1.0, rel: float = 1e-10) -> float:
    """The x where the increasing ``f`` reaches ``target``, by bisection after doubling ``hi``."""
    while f(hi) < target:
        lo, hi = hi, 2.0 * hi + 1.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if f(mid) < target else (lo, mid)
        if hi - lo <= rel * hi:
            break
    return 0.5 * (lo + hi)


def f_isf(p: float, d1: int, d2: int) -> float:
    """x with P(F_{d1, d2} > x) = ``p`` (0 < p < 1)."""
    if not 0.0 < p < 1.0:
        raise ValueError(f"p must be in (0, 1), got {p}")
    return _bisect_up(lambda x: -f_logsf(x, d1, d2), -math.log(p))


def ncp_for_power(dof: int, level: float, power: float, dof_res: int | None = None) -> float:
    """The noncentrality at which a chi-square test of ``dof`` degrees of freedom at ``level``
    (reject when its p-value is below ``level``) rejects with probability ``power``; with
    ``dof_res``, the F test of T / dof against (dof, dof_res) (the noise estimated from the
    residuals), which needs more."""
    if not 0.0 < power < 1.0:
        raise ValueError(f"power must be in (0, 1), got {power}")
    if dof_res is None:
        crit = chi2_isf(level, dof)
        return _bisect_up(lambda ncp: ncx2_sf(crit, dof, ncp), power, rel=1e-9)
    crit = f_isf(level, dof, dof_res)
    return _bisect_up(lambda ncp: ncf_sf(crit, dof, dof_res, ncp), power, rel=1e-9)


def f_logsf(x: float, d1: int, d2: int) -> float:
    """log P(F_{d1, d2} > x): log of the F distribution's survival function (d1, d2 >= 1)."""
    if d1 < 1 or d2 < 1:
        raise ValueError(f"degrees of freedom must be >= 1, got ({d1}, {d2})")
    x = float(x)
    if x <= 0.0:
        return 0.0
    # P(F > x) = I_{d2 / (d2 + d1 x)}(d2 / 2, d1 / 2)
    return _log_beta_inc(0.5 * d2, 0.5 * d1, d2 / (d2 + d1 * x))
