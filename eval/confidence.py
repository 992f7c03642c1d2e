"""Confidence bounds of the gated statistics: how far the true RMSE (or pooled spread) can be
from the one measured on a few frames.

Two methods, one-sided at ``confidence``: chi-square under a Gaussian error model, and the bootstrap (studentized
for an RMSE, percentile for a pooled spread; not below ``MIN_BOOTSTRAP_N``); the more cautious bound decides
(``decide``). No scipy.

Why and how: docs/acceptance.md, "Confidence bounds".
"""
from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

MIN_BOOTSTRAP_N = 5
BOOTSTRAP_SAMPLES = 2000


def _gamma_p(a: float, x: float) -> float:
    """Regularized lower incomplete gamma P(a, x), by its series (x < a + 1) or continued
    fraction (Numerical Recipes 6.2), to about 1e-12."""
    if x <= 0:
        return 0.0
    log_front = a * math.log(x) - x - math.lgamma(a)
    if x < a + 1:
        term = total = 1.0 / a
        k = a
        while abs(term) > abs(total) * 1e-15:
            k += 1
            term *= x / k
            total += term
        return total * math.exp(log_front)
    b, c, d = x + 1 - a, 1e300, 1.0 / (x + 1 - a)
    h = d
    for i in range(1, 10_000):
        an = -i * (i - a)
        b += 2
        d = an * d + b
        d = 1e-300 if abs(d) < 1e-300 else d
        c = b + an / c
        c = 1e-300 if abs(c) < 1e-300 else c
        d = 1.0 / d
        h *= d * c
        if abs(d * c - 1) < 1e-15:
            break
    return 1.0 - math.exp(log_front) * h


def chi2_cdf(x: float, dof: float) -> float:
    return _gamma_p(dof / 2.0, x / 2.0)


@lru_cache(maxsize=4096)
def chi2_quantile(p: float, dof: float) -> float:
    """x with P(chi2(dof) <= x) = p, for 0 < p < 1 and dof > 0 (bisection to 1e-12 relative).
    Cached: a verdict, a frame plan or a design space asks the same few quantiles many times."""
    if not (0 < p < 1) or not dof > 0:
        raise ValueError(f"chi2_quantile: need 0 < p < 1 and dof > 0, got p={p}, dof={dof}")
    lo, hi = 0.0, max(1.0, dof)
    while chi2_cdf(hi, dof) < p:
        hi *= 2
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if chi2_cdf(mid, dof) < p:
            lo = mid
        else:
            hi = mid
        if hi - lo <= 1e-12 * hi:
            break
    return 0.5 * (lo + hi)


def chi2_bounds(sum_sq: float, dof: int, confidence: float) -> tuple[float, float] | None:
    """(lower, upper) one-sided bounds of sigma from a sum of squares over ``dof`` degrees of
    freedom; None without a degree of freedom."""
    if dof < 1:
        return None
    return (math.sqrt(sum_sq / chi2_quantile(confidence, dof)),
            math.sqrt(sum_sq / chi2_quantile(1 - confidence, dof)))


def bootstrap_bounds(resample, n: int, confidence: float, seed: int,
                     samples: int = BOOTSTRAP_SAMPLES) -> tuple[float, float] | None:
    """(lower, upper): the (1 - c) and c quantiles of ``resample(index array)`` over ``samples``
    resamples of range(n) with replacement, from default_rng(seed); None below MIN_BOOTSTRAP_N."""
    if n < MIN_BOOTSTRAP_N:
        return None
    rng = np.random.default_rng(seed)
    stats = np.array([resample(rng.integers(0, n, n)) for _ in range(samples)])
    return float(np.quantile(stats, 1 - confidence)), float(np.quantile(stats, confidence))


def studentized_rmse_bounds(errors, confidence: float, seed: int,
                            samples: int = BOOTSTRAP_SAMPLES) -> tuple[float, float] | None:
    """(lower, upper) of the RMSE of ``errors`` (n,) by the bootstrap-t of log(mean e^2) (module
    docstring), resamples from default_rng(seed); None below MIN_BOOTSTRAP_N errors or when the
    squared errors do not vary (no standard error to studentize by)."""
    sq = np.asarray(errors, dtype=float) ** 2
    n = sq.size
    if n < MIN_BOOTSTRAP_N or not sq.mean() > 0 or not sq.std() > 0:
        return None
    rng = np.random.default_rng(seed)
    boot = sq[rng.integers(0, n, (samples, n))]
    m = boot.mean(axis=1)
    se = boot.std(axis=1, ddof=1) / (math.sqrt(n) * np.maximum(m, 1e-300))
    keep = se > 0   # a resample of one repeated error has no spread: it says nothing of t
    t = (np.log(m[keep]) - math.log(sq.mean())) / se[keep]
    se0 = float(sq.std(ddof=1)) / (math.sqrt(n) * float(sq.mean()))
    log_m = math.log(float(sq.mean()))
    upper = log_m - float(np.quantile(t, 1 - confidence)) * se0
    lower = log_m - float(np.quantile(t, confidence)) * se0
    return math.exp(lower / 2), math.exp(upper / 2)


def tail_check(errors) -> dict:
    """{"kurtosis": n sum e^4 / (sum e^2)^2 (about zero; 3 for Gaussian errors, None under
    MIN_BOOTSTRAP_N errors or all zero), "heavy_tailed": kurtosis above 3 + 3 sqrt(24 / n), three
    standard errors of the Gaussian's}. Heavy tails are the case where every bound here covers
    less than it states; the flag's rates on Gaussian and heavy-tailed samples are in
    bench/results/confidence/README.md."""
    e = np.asarray(errors, dtype=float)
    ss = float(np.sum(e ** 2))
    if e.size < MIN_BOOTSTRAP_N or not ss > 0:
        return {"kurtosis": None, "heavy_tailed": False}
    k = e.size * float(np.sum(e ** 4)) / ss ** 2
    return {"kurtosis": k, "heavy_tailed": bool(k > 3 + 3 * math.sqrt(24 / e.size))}


def rmse_bounds(errors, confidence: float, seed: int) -> dict:
    """Bounds of the RMSE of ``errors`` (n,), about zero (module docstring), and the errors'
    :func:`tail_check`."""
    e = np.asarray(errors, dtype=float)
    chi2 = chi2_bounds(float(np.sum(e ** 2)), e.size, confidence)
    return {**decide(chi2, studentized_rmse_bounds(e, confidence, seed)), **tail_check(e)}


def pooled_spread_bounds(groups, confidence: float, seed: int) -> dict:
    """Bounds of the pooled spread of repeated estimates: ``groups`` a list of (n_i,) arrays of one
    component's estimates per static pose (poses with fewer than 2 left out); poses resampled."""
    groups = [np.asarray(g, dtype=float) for g in groups if len(g) >= 2]
    ss = np.array([float(((g - g.mean()) ** 2).sum()) for g in groups])
    dof = np.array([len(g) - 1 for g in groups])
    chi2 = chi2_bounds(float(ss.sum()), int(dof.sum()), confidence)

    def resample(idx):
        return math.sqrt(ss[idx].sum() / dof[idx].sum())
    boot = bootstrap_bounds(resample, len(groups), confidence, seed)
    return decide(chi2, boot)


def decide(chi2, boot) -> dict:
    """Both methods' bounds and the cautious pair that decides: the larger upper bound and the
    smaller lower bound, with the method each comes from."""
    out = {"chi2": None if chi2 is None else {"lower": chi2[0], "upper": chi2[1]},
           "bootstrap": None if boot is None else {"lower": boot[0], "upper": boot[1]}}
    pairs = [(name, b) for name, b in (("chi2", chi2), ("bootstrap", boot)) if b is not None]
    if not pairs:
        return {**out, "lower": None, "upper": None, "lower_by": None, "upper_by": None}
    low = min(pairs, key=lambda p: p[1][0])
    high = max(pairs, key=lambda p: p[1][1])
    return {**out, "lower": low[1][0], "upper": high[1][1], "lower_by": low[0], "upper_by": high[0]}


def chi2_pass_probability(rmse: float, threshold: float, dof: int, confidence: float) -> float:
    """P(the chi-square upper bound of an RMS measured over ``dof`` degrees of freedom is within
    ``threshold``) when the true RMS is ``rmse`` (Gaussian errors): the bound sqrt(S / chi2_{1-c}(dof))
    with S = rmse^2 chi2(dof); 1.0 for rmse 0."""
    if rmse <= 0:
        return 1.0
    return chi2_cdf(threshold ** 2 * chi2_quantile(1 - confidence, dof) / rmse ** 2, dof)


def chi2_reject_probability(rmse: float, threshold: float, dof: int, confidence: float) -> float:
    """P(the chi-square lower bound sqrt(S / chi2_c(dof)) is beyond ``threshold``) when the true RMS
    is ``rmse``, S = rmse^2 chi2(dof); 0.0 for rmse 0."""
    if rmse <= 0:
        return 0.0
    return 1.0 - chi2_cdf(threshold ** 2 * chi2_quantile(confidence, dof) / rmse ** 2, dof)


def frames_to_decide(rmse: float, threshold: float, dof: int, confidence: float, limit: int = 100_000) -> int | None:
    """Degrees of freedom (frames) at which the chi-square bound of a statistic measured at
    ``rmse`` would decide against ``threshold`` (upper bound within it when rmse < threshold,
    lower bound beyond it otherwise), assuming the measured value holds; None when no count up
    to ``limit`` does (rmse equal to the threshold). Found by doubling, then bisection."""
    if rmse is None or threshold is None or rmse == threshold or dof < 1:
        return None

    def decided(n: int) -> bool:
        lower, upper = chi2_bounds(rmse * rmse * n, n, confidence)
        return upper <= threshold if rmse < threshold else lower > threshold
    return first_decided(decided, dof, limit)


def first_decided(decided, start: int, limit: int) -> int | None:
    """The count n >= ``start`` where ``decided(n)`` first holds, by doubling then bisection (the
    smallest one when decided is monotone); None when none up to ``limit`` does."""
    hi = max(start, 1)
    while not decided(hi):
        hi *= 2
        if hi > limit:
            return None
    lo = max(1, hi // 2)
    while lo < hi:
        mid = (lo + hi) // 2
        if decided(mid):
            hi = mid
        else:
            lo = mid + 1
    return hi
