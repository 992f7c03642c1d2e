"""LO-RANSAC for one section: outlier-robust pose and focal length with an inlier mask.

Samples of ``sample_size`` correspondences (default 6: the smallest set for which the UPnP
null space is one-dimensional; 5 and 4 also work) give closed-form candidates; each is scored by
MSAC (truncated squared reprojection error) over all points. Every new best model is locally
optimised (Chum, Matas, Kittler 2003): Levenberg-Marquardt on its inliers, re-scored, repeated
while the inlier set grows. The number of iterations adapts to the inlier ratio for the
requested confidence. Randomness comes only from the ``rng`` passed in.
"""
from __future__ import annotations

import math

import numpy as np

from solver.checks import _collinear_2d, _collinear_3d
from solver.errors import SolverError
from solver.pnpf import PnPfResult, make_result, refine_candidates
from solver.refine import covariance_from_jacobian, refine_pnpf
from solver.upnp import upnp

__all__ = ["ransac_pnpf"]


def _reproj_sq(p3, p2, pp, rot, t, f):
    pc = p3 @ rot.T + t
    z = pc[:, 2]
    e = f * pc[:, :2] / np.where(z > 0, z, np.nan)[:, None] + pp - p2
    out = np.sum(e * e, axis=1)
    return np.where(np.isfinite(out), out, np.inf)


def ransac_pnpf(p3, p2, pp, rng: np.random.Generator, *, threshold_px: float = 4.0,
                confidence: float = 0.9999, max_iterations: int = 2000, sample_size: int = 6,
                sigma_px: float | None = None, refine: bool = True) -> PnPfResult:
    """Robust pose + focal from correspondences with outliers.

    ``p3`` (N, 3) mm, ``p2`` (N, 2) px, ``pp`` (2,) px (validated by the caller or by
    :func:`solver.solve_pnpf`); ``rng``: numpy Generator (the only source of randomness);
    ``threshold_px``: inlier threshold on the reprojection error (px). Returns a
    :class:`PnPfResult` whose ``inliers`` (N,) marks the points used; with ``refine=False``
    the pose is the LO estimate (inliers are still final). Raises SolverError if fewer than
    4 inliers support any model.
    """
    if not isinstance(rng, np.random.Generator):
        raise SolverError("ransac needs rng, a numpy.random.Generator (explicit seed)")
    if not (np.isfinite(threshold_px) and threshold_px > 0):
        raise SolverError(f"threshold_px must be positive and finite, got {threshold_px}")
    n = p3.shape[0]
    s = int(min(max(sample_size, 4), n))
    thr2 = float(threshold_px) ** 2
    best_score, best_model, best_inl = np.inf, None, None
    needed = max_iterations
    it = 0
    while it < min(needed, max_iterations):
        it += 1
        idx = rng.choice(n, size=s, replace=False)
        q3, q2 = p3[idx], p2[idx]
        if _collinear_3d(q3) or _collinear_2d(q2):
            continue
        try:
            cands = upnp(q3, q2, pp, checked=True)
        except (SolverError, np.linalg.LinAlgError):
            continue
        for c in cands:
            e2 = _reproj_sq(p3, p2, pp, c.rotation, c.translation, c.focal_px)
            score = float(np.minimum(e2, thr2).sum())
            if score >= best_score:
                continue
            model, inl, score = _local_optimise(p3, p2, pp, (c.rotation, c.translation,
                                                             c.focal_px), e2, thr2)
            if score < best_score:
                best_score, best_model, best_inl = score, model, inl
                w = inl.mean()
                needed = _iterations_needed(w, s, confidence)
    if best_model is None or best_inl.sum() < 4:
        raise SolverError(f"RANSAC found no model supported by 4 or more of the {n} points "
                          f"within {threshold_px} px")
    inl = best_inl
    if not refine:
        ref = refine_pnpf(p3[inl], p2[inl], pp, *best_model)
        cov, sigma = covariance_from_jacobian(ref.jacobian, ref.residuals, sigma_px)
        return make_result(ref, cov, sigma, (), inl)
    ref, cov, sigma = refine_candidates(p3[inl], p2[inl], pp, upnp(p3[inl], p2[inl], pp,
                                                                   checked=True), sigma_px)
    # keep the LO model if the fresh closed form went elsewhere
    lo = refine_pnpf(p3[inl], p2[inl], pp, *best_model)
    if float(lo.residuals @ lo.residuals) < float(ref.residuals @ ref.residuals):
        ref = lo
        cov, sigma = covariance_from_jacobian(ref.jacobian, ref.residuals, sigma_px)
    return make_result(ref, cov, sigma, (), inl)


def _local_optimise(p3, p2, pp, model, e2, thr2, rounds: int = 4):
    """Refine on the inliers, re-score, repeat while the inlier set changes."""
    inl = e2 <= thr2
    score = float(np.minimum(e2, thr2).sum())
    for _ in range(rounds):
        if inl.sum() < 5:
            break
        try:
            ref = refine_pnpf(p3[inl], p2[inl], pp, *model, max_iter=15)
        except SolverError:
            break
        cand = (ref.rotation, ref.translation, ref.focal_px)
        e2n = _reproj_sq(p3, p2, pp, *cand)
        score_n = float(np.minimum(e2n, thr2).sum())
        if score_n > score:
            break
        inl_n = e2n <= thr2
        model, score = cand, score_n
        if np.array_equal(inl_n, inl):
            break
        inl = inl_n
    return model, inl, score


def _iterations_needed(w: float, s: int, confidence: float) -> int:
    p_good = w ** s
    if p_good <= 0.0:
        return 10 ** 9
    if p_good >= 1.0:
        return 1
    return int(math.ceil(math.log(1.0 - confidence) / math.log(1.0 - p_good)))
