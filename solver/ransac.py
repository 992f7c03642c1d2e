"""LO-RANSAC: outlier-robust pose and focal length with an inlier mask.

One section (:func:`ransac_pnpf`): samples of ``sample_size`` correspondences (default 6, the
smallest set for which the UPnP null space is one-dimensional) give a closed-form candidate that
is polished on the sample by a few Levenberg-Marquardt steps (near-planar markers make the
closed form alone too coarse to classify points at a few pixels); the model is scored by MSAC
(truncated squared reprojection error) over all points. Every new best model is locally
optimised (Chum, Matas, Kittler 2003): LM on its inliers, re-scored, repeated while the inlier
set changes. The number of iterations adapts to the inlier ratio for the requested confidence.

Two sections (:func:`ransac_docking`): the same with samples drawn from both sections and the
joint model (one shared focal length), which is far better conditioned than either section.
Randomness comes only from the ``rng`` passed in.
"""
from __future__ import annotations

import math

import numpy as np

from solver.checks import _collinear_2d, _collinear_3d
from solver.errors import SolverError
from solver.pnpf import PnPfResult, make_result, refine_candidates
from solver.refine import covariance_from_jacobian, refine_pnpf
from solver.upnp import upnp

__all__ = ["ransac_pnpf", "ransac_docking"]


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
            cands = upnp(q3, q2, pp, checked=True, first_only=True) or \
                upnp(q3, q2, pp, checked=True)
            ref = refine_pnpf(q3, q2, pp, cands[0].rotation, cands[0].translation,
                              cands[0].focal_px, max_iter=10)
        except (SolverError, np.linalg.LinAlgError):
            continue
        for c in (ref,):
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


def ransac_docking(p3a, p2a, p3b, p2b, pp, rng: np.random.Generator, *,
                   threshold_px: float = 4.0, confidence: float = 0.9999,
                   max_iterations: int = 2000, sample_sizes=(5, 5)):
    """Joint LO-RANSAC over both sections (shared focal length).

    ``p3a`` (Na, 3) mm in A's frame with pixels ``p2a`` (Na, 2); same for B; ``pp`` (2,) px.
    Returns (inliers_a (Na,) bool, inliers_b (Nb,) bool, (cam_from_a, cam_from_b, focal)).
    Raises SolverError when no model has 4 or more inliers in each section.
    """
    from solver.docking import _closed_form_starts
    from solver.refine import refine_joint
    if not isinstance(rng, np.random.Generator):
        raise SolverError("ransac needs rng, a numpy.random.Generator (explicit seed)")
    if not (np.isfinite(threshold_px) and threshold_px > 0):
        raise SolverError(f"threshold_px must be positive and finite, got {threshold_px}")
    na, nb = p3a.shape[0], p3b.shape[0]
    sa, sb = min(max(sample_sizes[0], 4), na), min(max(sample_sizes[1], 4), nb)
    thr2 = float(threshold_px) ** 2
    best_score, best = np.inf, None
    needed = max_iterations
    it = 0

    def score_of(model):
        ra, ta, rb, tb, f = model
        ea = _reproj_sq(p3a, p2a, pp, ra, ta, f)
        eb = _reproj_sq(p3b, p2b, pp, rb, tb, f)
        return ea, eb, float(np.minimum(ea, thr2).sum() + np.minimum(eb, thr2).sum())

    while it < min(needed, max_iterations):
        it += 1
        ia = rng.choice(na, size=sa, replace=False)
        ib = rng.choice(nb, size=sb, replace=False)
        qa3, qa2, qb3, qb2 = p3a[ia], p2a[ia], p3b[ib], p2b[ib]
        if _collinear_3d(qa3) or _collinear_2d(qa2) or _collinear_3d(qb3) or _collinear_2d(qb2):
            continue
        try:
            start = _closed_form_starts(qa3, qa2, qb3, qb2, pp)[0]
            jr = refine_joint(qa3, qa2, qb3, qb2, pp, *start, max_iter=10)
        except (SolverError, np.linalg.LinAlgError, IndexError):
            continue
        model = (jr.rotation_a, jr.translation_a, jr.rotation_b, jr.translation_b, jr.focal_px)
        ea, eb, score = score_of(model)
        if score >= best_score:
            continue
        # local optimisation on the inliers
        for _ in range(4):
            ia_in, ib_in = ea <= thr2, eb <= thr2
            if ia_in.sum() < 4 or ib_in.sum() < 4:
                break
            try:
                jr = refine_joint(p3a[ia_in], p2a[ia_in], p3b[ib_in], p2b[ib_in], pp, *model,
                                  max_iter=15)
            except SolverError:
                break
            cand = (jr.rotation_a, jr.translation_a, jr.rotation_b, jr.translation_b,
                    jr.focal_px)
            ea_n, eb_n, score_n = score_of(cand)
            if score_n > score:
                break
            changed = not (np.array_equal(ea_n <= thr2, ia_in)
                           and np.array_equal(eb_n <= thr2, ib_in))
            model, ea, eb, score = cand, ea_n, eb_n, score_n
            if not changed:
                break
        if score < best_score:
            best_score, best = score, (model, ea <= thr2, eb <= thr2)
            wa, wb = best[1].mean(), best[2].mean()
            p_good = (wa ** sa) * (wb ** sb)
            needed = _iterations_needed(p_good ** (1.0 / (sa + sb)), sa + sb, confidence)
    if best is None or best[1].sum() < 4 or best[2].sum() < 4:
        raise SolverError(f"RANSAC found no joint model with 4 or more inliers per section "
                          f"within {threshold_px} px")
    model, inl_a, inl_b = best
    cam_a = np.eye(4)
    cam_a[:3, :3], cam_a[:3, 3] = model[0], model[1]
    cam_b = np.eye(4)
    cam_b[:3, :3], cam_b[:3, 3] = model[2], model[3]
    return inl_a, inl_b, (cam_a, cam_b, float(model[4]))
