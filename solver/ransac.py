"""LO-RANSAC: outlier-robust pose and focal length with an inlier mask.

One section (:func:`ransac_pnpf`): samples of ``sample_size`` correspondences (default 6, the
smallest set for which the UPnP null space is one-dimensional) give a closed-form candidate that
is polished on the sample by a few Levenberg-Marquardt steps (near-planar markers make the
closed form alone too coarse to classify points at a few pixels); the model is scored by MSAC
(truncated squared reprojection error) over all points. Every new best model is locally
optimised (Chum, Matas, Kittler 2003): LM on its inliers, re-scored, repeated while the inlier
set changes. The number of iterations adapts to the inlier ratio for the requested confidence.

Why and how: docs/solver.md, "LO-RANSAC".
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from dockfactory.solver.checks import collinear_2d, collinear_3d
from dockfactory.solver.errors import InvalidSolverInput, NoConsensus, SolverError
from dockfactory.solver.estimate import PnPfResult, refine_best_candidate
from dockfactory.solver.joint import JointStart
from dockfactory.solver.lie import so3_exp
from dockfactory.solver.options import RansacOptions, RefineOptions
from dockfactory.solver.refine import DEFAULT_REFINE, refine_joint, refine_pnpf
from dockfactory.solver.upnp import upnp

__all__ = ["ransac_pnpf", "ransac_docking", "DockingConsensus", "facing_init",
           "DEFAULT_RANSAC"]

DEFAULT_RANSAC = RansacOptions()


@dataclass(frozen=True)
class DockingConsensus:
    """Result of :func:`ransac_docking`: ``inliers_a`` (Na,) and ``inliers_b`` (Nb,) bool, and
    the joint model as the ``start`` of the final fit."""

    inliers_a: np.ndarray
    inliers_b: np.ndarray
    start: JointStart


def _check_rng(rng) -> None:
    if not isinstance(rng, np.random.Generator):
        raise InvalidSolverInput("ransac needs rng, a numpy.random.Generator (explicit seed)")


def _reproj_sq(p3, p2, pp, rot, t, f):
    """(N,) squared reprojection errors (px^2); inf for points behind the camera."""
    pc = p3 @ rot.T + t
    z = pc[:, 2]
    e = f * pc[:, :2] / np.where(z > 0, z, np.nan)[:, None] + pp - p2
    out = np.sum(e * e, axis=1)
    return np.where(np.isfinite(out), out, np.inf)


def _closed_form_refined(q3, q2, pp, options: RefineOptions):
    """The cheapest closed-form candidate (every candidate if that fails), refined."""
    cands = upnp(q3, q2, pp, checked=True, first_only=True) or upnp(q3, q2, pp, checked=True)
    return refine_pnpf(q3, q2, pp, cands[0].rotation, cands[0].translation, cands[0].focal_px,
                       options)


def ransac_pnpf(p3, p2, pp, rng: np.random.Generator, options: RansacOptions = DEFAULT_RANSAC,
                refine_options: RefineOptions = DEFAULT_REFINE, *,
                sigma_px: float | None = None, refine: bool = True) -> PnPfResult:
    """Robust pose + focal from correspondences with outliers (LO-RANSAC).

    Parameters
    ----------
    p3, p2, pp : (N, 3) mm, (N, 2) px, (2,) px
        Validated by the caller or by :func:`solver.solve_pnpf`.
    rng : numpy.random.Generator
        The only source of randomness.
    options, refine_options : RansacOptions, RefineOptions
    sigma_px : float or None
        Pixel noise std for the covariance (None: from the residuals).
    refine : bool
        False: the pose is the LO estimate (inliers are still final).

    Returns
    -------
    PnPfResult
        Its ``inliers`` (N,) marks the points used.

    Raises
    ------
    NoConsensus
        If fewer than 4 inliers support any model.
    InvalidSolverInput
        If ``rng`` is not a numpy Generator.
    """
    _check_rng(rng)
    model, inl = _pnpf_consensus(p3, p2, pp, rng, options, refine_options)
    if model is None or inl.sum() < 4:
        raise NoConsensus(f"RANSAC found no model supported by 4 or more of the {p3.shape[0]} "
                          f"points within {options.threshold_px} px")
    q3, q2 = p3[inl], p2[inl]
    if not refine:
        lo = refine_pnpf(q3, q2, pp, *model, refine_options)
        return PnPfResult.from_refinement(lo, sigma_px, (), inl, refine_options)
    ref = refine_best_candidate(q3, q2, pp, upnp(q3, q2, pp, checked=True), refine_options,
                                max_tries=options.final_starts)
    # keep the LO model if the fresh closed form went elsewhere
    lo = refine_pnpf(q3, q2, pp, *model, refine_options)
    if float(lo.residuals @ lo.residuals) < float(ref.residuals @ ref.residuals):
        ref = lo
    return PnPfResult.from_refinement(ref, sigma_px, (), inl, refine_options)


def _pnpf_consensus(p3, p2, pp, rng, options: RansacOptions, refine_options: RefineOptions):
    """Sampling loop of :func:`ransac_pnpf`: (best model (R, t, f) or None, inliers (N,))."""
    n = p3.shape[0]
    s = int(min(max(options.sample_size, 4), n))
    thr2 = float(options.threshold_px) ** 2
    polish = replace(refine_options, max_iterations=options.sample_refine_iterations)
    lo_opts = replace(refine_options, max_iterations=options.lo_refine_iterations)
    best_score, best_model, best_inl = np.inf, None, None
    needed = options.max_iterations
    it = 0
    while it < min(needed, options.max_iterations):
        it += 1
        idx = rng.choice(n, size=s, replace=False)
        q3, q2 = p3[idx], p2[idx]
        if collinear_3d(q3) or collinear_2d(q2):
            continue
        try:
            c = _closed_form_refined(q3, q2, pp, polish)
        except (SolverError, np.linalg.LinAlgError):
            continue
        e2 = _reproj_sq(p3, p2, pp, c.rotation, c.translation, c.focal_px)
        score = float(np.minimum(e2, thr2).sum())
        if score >= best_score:
            continue
        model, inl, score = _local_optimise(p3, p2, pp, (c.rotation, c.translation,
                                                         c.focal_px), e2, thr2, lo_opts,
                                            options.lo_rounds)
        if score < best_score:
            best_score, best_model, best_inl = score, model, inl
            needed = _iterations_needed(inl.mean(), s, options.confidence)
    return best_model, best_inl


def _local_optimise(p3, p2, pp, model, e2, thr2, lo_opts: RefineOptions, rounds: int):
    """Refine on the inliers, re-score, repeat while the inlier set changes."""
    inl = e2 <= thr2
    score = float(np.minimum(e2, thr2).sum())
    for _ in range(rounds):
        if inl.sum() < 4:
            break
        try:
            ref = refine_pnpf(p3[inl], p2[inl], pp, *model, lo_opts)
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
    """Samples of size ``s`` needed to draw a clean one with ``confidence`` at inlier ratio w."""
    p_good = w ** s
    if p_good <= 0.0:
        return 10 ** 9
    if p_good >= 1.0:
        return 1
    return int(math.ceil(math.log(1.0 - confidence) / math.log(1.0 - p_good)))


def facing_init(a: complex, b: complex, pp, points_3d, distance_mm: float):
    """Camera (R, t, f) of a weak-perspective similarity ``z = a (X - iY) + b`` (px).

    The docking camera faces the markers along -Z of their frame, so the similarity's angle is
    the image roll and its modulus |a| = f / depth (px per mm). Depth is taken as
    ``distance_mm`` from the points' mean Z plane and f = |a| * depth; the focal/depth split
    is what refinement then settles. ``points_3d`` (N, 3) mm.
    """
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


def _ransac_section(p3, p2, pp, rng, options: RansacOptions, refine_options: RefineOptions):
    """One section's LO-RANSAC with 2-point weak-perspective hypotheses (see ransac_docking).
    Returns (model (R, t, f), inliers (N,) bool) or None."""
    prior = options.prior
    max_roll_rad = np.radians(prior.max_roll_deg)
    thr2 = float(options.threshold_px) ** 2
    lo_opts = replace(refine_options, max_iterations=options.lo_refine_iterations)
    n = p3.shape[0]
    w = p3[:, 0] - 1j * p3[:, 1]
    z = p2[:, 0] + 1j * p2[:, 1]
    d = np.abs(w[:, None] - w[None, :])
    d[np.eye(n, dtype=bool)] = np.inf
    spacing = float(d.min())
    best_score, best = np.inf, None
    needed, it = options.section_iterations, 0
    while it < min(needed, options.section_iterations):
        it += 1
        idx = rng.choice(n, size=2, replace=False)
        sim = _similarity_model(w[idx], z[idx])
        if sim is None:
            continue
        a, b = sim
        if not (prior.scale_range[0] <= abs(a) <= prior.scale_range[1]) \
                or abs(np.angle(a)) > max_roll_rad:
            continue
        loose = np.abs(a * w + b - z) <= prior.loose_gate * spacing * abs(a)
        if loose.sum() < 4:
            continue
        fitted = _fit_hypothesis(p3, p2, pp, sim, loose, thr2, options, refine_options)
        if fitted is None or float(np.minimum(fitted[1], thr2).sum()) >= best_score:
            continue
        ref, e2 = fitted
        model, inl, score = _local_optimise(p3, p2, pp, (ref.rotation, ref.translation,
                                                         ref.focal_px), e2, thr2, lo_opts,
                                            options.lo_rounds)
        if score < best_score:
            best_score, best = score, (model, inl)
            p_good = inl.mean() ** 2
            needed = _iterations_needed(p_good ** 0.5, 2, options.confidence)
    return best


def _fit_hypothesis(p3, p2, pp, sim, loose, thr2, options: RansacOptions,
                    refine_options: RefineOptions):
    """UPnP + LM on the points ``loose`` (N,) bool that the similarity ``sim`` = (a, b)
    predicts, dropping the worst while fewer than 4 points fit; from the facing camera when the
    closed form misses. (refinement, squared errors (N,)) or None."""
    ref = None
    fit_opts = replace(refine_options, max_iterations=options.loose_refine_iterations)
    for _ in range(options.loose_refits):
        try:
            ref = _closed_form_refined(p3[loose], p2[loose], pp, fit_opts)
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
        facing = replace(refine_options, max_iterations=options.facing_refine_iterations)
        try:
            ref = refine_pnpf(p3[loose], p2[loose], pp,
                              *facing_init(*sim, pp, p3, options.facing_distance_mm), facing)
        except SolverError:
            return None
        e2 = _reproj_sq(p3, p2, pp, ref.rotation, ref.translation, ref.focal_px)
    return ref, e2


def ransac_docking(p3a, p2a, p3b, p2b, pp, rng: np.random.Generator,
                   options: RansacOptions = DEFAULT_RANSAC,
                   refine_options: RefineOptions = DEFAULT_REFINE) -> DockingConsensus:
    """LO-RANSAC for a docking frame (two sections, shared focal length).

    Hypotheses come from 2-point samples per section: the camera faces the markers (the docking setup), so two
    correspondences fix a weak-perspective similarity of the markers' (X, -Y) coordinates (roll and scale within
    ``options.prior``); points it predicts within the prior's loose gate are fitted by UPnP + LM, and the model is
    scored by MSAC at ``options.threshold_px``. A two-point sample is clean far more often than a five-point one (a
    section may keep only 4 of its 7 markers), which is what makes 20 % outliers cheap. Every new best is locally
    optimised on its inliers; the number of samples adapts to the inlier ratio. Finally the two sections are refitted
    jointly (shared focal) and every point is re-classified against the joint model.

    Parameters
    ----------
    p3a, p2a, p3b, p2b, pp : (Na, 3) mm in A's frame, (Na, 2) px; the same for B; (2,) px
    rng : numpy.random.Generator
        The only source of randomness.
    options, refine_options : RansacOptions, RefineOptions

    Returns
    -------
    DockingConsensus

    Raises
    ------
    NoConsensus
        When a section has no model with 4 or more inliers.
    InvalidSolverInput
        If ``rng`` is not a numpy Generator.
    """
    _check_rng(rng)
    res = {}
    for name, (p3, p2) in (("A", (p3a, p2a)), ("B", (p3b, p2b))):
        best = _ransac_section(p3, p2, pp, rng, options, refine_options)
        if best is None or best[1].sum() < 4:
            raise NoConsensus(f"section {name}: RANSAC found no model with 4 or more inliers "
                              f"within {options.threshold_px} px")
        res[name] = best
    (ma, ia), (mb, ib) = res["A"], res["B"]
    f0 = float(np.sqrt(ma[2] * mb[2]))
    model = (ma[0], ma[1] * (f0 / ma[2]), mb[0], mb[1] * (f0 / mb[2]), f0)
    return _joint_reclassify((p3a, p2a, p3b, p2b, pp), model, ia, ib, options, refine_options)


def _joint_reclassify(data, model, ia, ib, options: RansacOptions,
                      refine_options: RefineOptions) -> DockingConsensus:
    """Refit both sections jointly on their inliers and re-classify every point against the
    joint model, while the inlier sets change (up to ``options.joint_rounds`` rounds)."""
    p3a, p2a, p3b, p2b, pp = data
    thr2 = float(options.threshold_px) ** 2
    joint_opts = replace(refine_options, max_iterations=options.joint_refine_iterations)
    for _ in range(options.joint_rounds):
        try:
            jr = refine_joint(p3a[ia], p2a[ia], p3b[ib], p2b[ib], pp, *model, joint_opts)
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
    return DockingConsensus(ia, ib, JointStart(cam_a, cam_b, float(model[4])))
