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
from dockfactory.solver.checks import _collinear_2d, _collinear_3d
from dockfactory.solver.errors import SolverError
from dockfactory.solver.pnpf import PnPfResult, make_result, refine_candidates
from dockfactory.solver.refine import covariance_from_jacobian, refine_pnpf
from dockfactory.solver.upnp import upnp

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
        if inl.sum() < 4:
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


def facing_init(a: complex, b: complex, pp, points_3d, distance_mm: float = 1500.0):
    """Camera (R, t, f) of a weak-perspective similarity ``z = a (X - iY) + b`` (px).

    The docking camera faces the markers along -Z of their frame, so the similarity's angle is
    the image roll and its modulus |a| = f / depth (px per mm). Depth is taken as
    ``distance_mm`` from the points' mean Z plane and f = |a| * depth; the focal/depth split
    is what refinement then settles.
    """
    from dockfactory.solver.lie import so3_exp
    theta = float(np.angle(a))
    k = float(abs(a))
    r = so3_exp([0.0, 0.0, theta]) @ np.diag([1.0, -1.0, -1.0])
    tw = (b - complex(pp[0], pp[1])) / a
    zbar = float(points_3d[:, 2].mean())
    t = so3_exp([0.0, 0.0, theta]) @ np.array([tw.real, tw.imag, 0.0])
    t[2] = distance_mm + zbar
    return r, t, k * distance_mm


def _similarity_model(w2, z2):
    """Complex similarity z = a w + b through two points; None if degenerate."""
    dw = w2[1] - w2[0]
    if abs(dw) == 0.0:
        return None
    a = (z2[1] - z2[0]) / dw
    return a, z2[0] - a * w2[0]


def _ransac_section(p3, p2, pp, rng, thr2, confidence, max_iterations, max_roll_rad,
                    scale_range, loose_frac):
    """One section's LO-RANSAC with 2-point weak-perspective hypotheses (see ransac_docking)."""
    n = p3.shape[0]
    w = p3[:, 0] - 1j * p3[:, 1]
    z = p2[:, 0] + 1j * p2[:, 1]
    d = np.abs(w[:, None] - w[None, :])
    d[np.eye(n, dtype=bool)] = np.inf
    spacing = float(d.min())
    best_score, best = np.inf, None
    needed, it = max_iterations, 0
    while it < min(needed, max_iterations):
        it += 1
        idx = rng.choice(n, size=2, replace=False)
        sim = _similarity_model(w[idx], z[idx])
        if sim is None:
            continue
        a, b = sim
        if not (scale_range[0] <= abs(a) <= scale_range[1]) or abs(np.angle(a)) > max_roll_rad:
            continue
        loose = np.abs(a * w + b - z) <= loose_frac * spacing * abs(a)
        if loose.sum() < 4:
            continue
        ref = None
        for _ in range(3):
            try:
                c = upnp(p3[loose], p2[loose], pp, checked=True, first_only=True) or \
                    upnp(p3[loose], p2[loose], pp, checked=True)
                ref = refine_pnpf(p3[loose], p2[loose], pp, c[0].rotation, c[0].translation,
                                  c[0].focal_px, max_iter=15)
            except (SolverError, np.linalg.LinAlgError):
                ref = None
                break
            e2 = _reproj_sq(p3, p2, pp, ref.rotation, ref.translation, ref.focal_px)
            if (e2 <= thr2).sum() >= 4 or loose.sum() <= 4:
                break
            # a wrong point inside the loose gate spoils the fit: drop the worst and refit
            worst = np.flatnonzero(loose)[np.argmax(e2[loose])]
            loose = loose.copy()
            loose[worst] = False
        if ref is None or (e2 <= thr2).sum() < 4:
            # closed form on few near-planar points can miss: start from the similarity
            try:
                ref = refine_pnpf(p3[loose], p2[loose], pp, *facing_init(a, b, pp, p3),
                                  max_iter=30)
            except SolverError:
                continue
            e2 = _reproj_sq(p3, p2, pp, ref.rotation, ref.translation, ref.focal_px)
        if float(np.minimum(e2, thr2).sum()) >= best_score:
            continue
        model, inl, score = _local_optimise(p3, p2, pp, (ref.rotation, ref.translation,
                                                         ref.focal_px), e2, thr2)
        if score < best_score:
            best_score, best = score, (model, inl)
            p_good = inl.mean() ** 2
            needed = _iterations_needed(p_good ** 0.5, 2, confidence)
    return best


def ransac_docking(p3a, p2a, p3b, p2b, pp, rng: np.random.Generator, *,
                   threshold_px: float = 4.0, confidence: float = 0.9999,
                   max_iterations: int = 300, max_roll_deg: float = 30.0,
                   scale_range=(0.05, 50.0), loose_frac: float = 0.4):
    """LO-RANSAC for a docking frame (two sections, shared focal length).

    Hypotheses come from 2-point samples per section: the camera faces the markers (the
    docking setup), so two correspondences fix a weak-perspective similarity of the markers'
    (X, -Y) coordinates (roll within ``max_roll_deg``, scale within ``scale_range`` px/mm);
    points it predicts within ``loose_frac`` of the marker spacing are fitted by UPnP + LM, and
    the model is scored by MSAC at ``threshold_px``. A two-point sample is clean far more
    often than a five-point one (a section may keep only 4 of its 7 markers), which is what
    makes 20 % outliers cheap. Every new best is locally optimised on its inliers; the number
    of samples adapts to the inlier ratio. Finally the two sections are refitted jointly
    (shared focal) and every point is re-classified against the joint model.

    ``p3a`` (Na, 3) mm in A's frame with pixels ``p2a`` (Na, 2); same for B; ``pp`` (2,) px.
    Returns (inliers_a (Na,) bool, inliers_b (Nb,) bool, (cam_from_a, cam_from_b, focal)).
    Raises SolverError when a section has no model with 4 or more inliers.
    """
    from dockfactory.solver.refine import refine_joint
    if not isinstance(rng, np.random.Generator):
        raise SolverError("ransac needs rng, a numpy.random.Generator (explicit seed)")
    if not (np.isfinite(threshold_px) and threshold_px > 0):
        raise SolverError(f"threshold_px must be positive and finite, got {threshold_px}")
    thr2 = float(threshold_px) ** 2
    res = {}
    for name, (p3, p2) in (("A", (p3a, p2a)), ("B", (p3b, p2b))):
        best = _ransac_section(p3, p2, pp, rng, thr2, confidence, max_iterations,
                               np.radians(max_roll_deg), scale_range, loose_frac)
        if best is None or best[1].sum() < 4:
            raise SolverError(f"section {name}: RANSAC found no model with 4 or more inliers "
                              f"within {threshold_px} px")
        res[name] = best
    (ma, ia), (mb, ib) = res["A"], res["B"]
    f0 = float(np.sqrt(ma[2] * mb[2]))
    model = (ma[0], ma[1] * (f0 / ma[2]), mb[0], mb[1] * (f0 / mb[2]), f0)
    for _ in range(3):
        try:
            jr = refine_joint(p3a[ia], p2a[ia], p3b[ib], p2b[ib], pp, *model, max_iter=30)
        except SolverError:
            break
        model = (jr.rotation_a, jr.translation_a, jr.rotation_b, jr.translation_b, jr.focal_px)
        ia_n = _reproj_sq(p3a, p2a, pp, model[0], model[1], model[4]) <= thr2
        ib_n = _reproj_sq(p3b, p2b, pp, model[2], model[3], model[4]) <= thr2
        if (np.array_equal(ia_n, ia) and np.array_equal(ib_n, ib)) or ia_n.sum() < 4 \
                or ib_n.sum() < 4:
            break
        ia, ib = ia_n, ib_n
    cam_a = np.eye(4)
    cam_a[:3, :3], cam_a[:3, 3] = model[0], model[1]
    cam_b = np.eye(4)
    cam_b[:3, :3], cam_b[:3, 3] = model[2], model[3]
    return ia, ib, (cam_a, cam_b, float(model[4]))
