"""Centre noise of a marker's image: the shape of its 2 x 2 covariance, from the disc's ellipse.

Why and how: docs/solver.md, "Disc noise".
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from dockfactory.core.names import SECTIONS
from dockfactory.solver.camera_models import Intrinsics, camera_model
from dockfactory.solver.errors import SolverError
from dockfactory.solver.joint import JointFit, JointFitter, SectionPoints, with_added_covariance, with_model_check
from dockfactory.solver.model_error import model_check
from dockfactory.solver.options import GATE_NOISE_FACTOR
from dockfactory.solver.refine import (
    Block,
    covariance_from_jacobian,
    d_from_b_jacobian,
    inverse_spd,
    refine_blocks,
    relative_pose,
    scale_with_prior,
    stack_blocks,
    whitened,
)
from dockfactory.solver.section_shift import section_shift_covariance

__all__ = ["MINOR_EXPONENT", "NOISE_FLOOR", "REFERENCE_RADIUS_PX", "disc_ellipses", "noise_shapes",
           "section_noise_shapes", "with_disc_noise", "robust_refit", "t_weights", "with_model_error",
           "ROBUST_NU", "ROBUST_ITERATIONS"]

REFERENCE_RADIUS_PX = 10.0   # minor semi-axis (px) of the disc whose noise shape is I
MINOR_EXPONENT = 2.5         # the variance grows as (REFERENCE_RADIUS_PX / b)^MINOR_EXPONENT ...
NOISE_FLOOR = 0.5            # ... over a floor, in the same units (:func:`noise_shapes`)
ROBUST_NU = 4.0          # Student-t degrees of freedom of the robust refit's weights
ROBUST_ITERATIONS = 4    # reweighting rounds of the robust refit
MEDIAN_CHI2_2 = 2.0 * np.log(2.0)   # median of a chi-square with 2 degrees of freedom


def disc_ellipses(centres_cam, normals_cam, diameters_mm, focal_px: float) -> np.ndarray:
    """(N, 2, 2) px^2: S = A A^T of each disc's image {c + A (cos t, sin t)}, whose eigenvalues
    are the squared semi-axes (first order at the disc's centre, pinhole ``focal_px``).

    ``centres_cam`` (N, 3) mm and ``normals_cam`` (N, 3) in the camera frame (OpenCV: z
    forward, every z > 0), ``diameters_mm`` (N,)."""
    c = np.asarray(centres_cam, dtype=np.float64).reshape(-1, 3)
    n = np.asarray(normals_cam, dtype=np.float64).reshape(-1, 3)
    n = n / np.linalg.norm(n, axis=1, keepdims=True)
    ref = np.where(np.abs(n[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    e1 = np.cross(ref, n)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = np.cross(n, e1)
    iz = 1.0 / c[:, 2]
    zero = np.zeros_like(iz)
    jp = focal_px * iz[:, None, None] * np.stack(
        [np.stack([1.0 + zero, zero, -c[:, 0] * iz], 1),
         np.stack([zero, 1.0 + zero, -c[:, 1] * iz], 1)], 1)          # d(u, v) / d(x, y, z)
    a = np.einsum("nij,njk->nik", jp, np.stack([e1, e2], 2))
    a *= 0.5 * np.asarray(diameters_mm, dtype=np.float64).reshape(-1, 1, 1)
    return a @ np.transpose(a, (0, 2, 1))


def noise_shapes(ellipses) -> np.ndarray:
    """(N, 2, 2): the relative centre covariance T = v(b) I of each disc image ``ellipses`` (N, 2,
    2) px^2 (:func:`disc_ellipses`), b its minor semi-axis (px):

        v(b) = ((REFERENCE_RADIUS_PX / b)^MINOR_EXPONENT + NOISE_FLOOR) / (1 + NOISE_FLOOR),

    so T = I for a disc whose minor semi-axis is REFERENCE_RADIUS_PX. The scale (px) is measured,
    never assumed here. Why isotropic and in b alone: the refined centres of converged renders err
    as much along a disc's major axis as across it, and both grow steeply as the disc thins
    (slant or distance), whatever its major axis; the law and its check on three scenes of
    different geometry and seven cameras: docs/solver.md, "Disc noise"."""
    lam = np.linalg.eigvalsh(np.asarray(ellipses, dtype=np.float64).reshape(-1, 2, 2))
    minor = np.sqrt(np.maximum(lam[:, 0], 1e-12))
    v = ((REFERENCE_RADIUS_PX / minor) ** MINOR_EXPONENT + NOISE_FLOOR) / (1.0 + NOISE_FLOOR)
    return v[:, None, None] * np.eye(2)


def section_noise_shapes(markers, cam_from_s, focal_px: float) -> np.ndarray:
    """(m, 2, 2): :func:`noise_shapes` of ``markers`` (core.layout.Marker, all of one section)
    seen by ``cam_from_s`` (4, 4), the camera from their section's frame."""
    if len(markers) == 0:
        return np.zeros((0, 2, 2))
    cam = np.asarray(cam_from_s, dtype=np.float64)
    centres = np.array([m.center_mm for m in markers]) @ cam[:3, :3].T + cam[:3, 3]
    normals = np.array([m.normal for m in markers]) @ cam[:3, :3].T
    return noise_shapes(disc_ellipses(centres, normals, [m.diameter_mm for m in markers], focal_px))


def with_disc_noise(fit: JointFit, points: SectionPoints, fitter: JointFitter, keep: dict,
                    points_2d: dict | None = None, extra_px2: dict | None = None) -> JointFit:
    """``fit`` with the covariance of the disc noise model (:func:`solver.refine.
    covariance_from_jacobian` with ``point_cov``: the sandwich of the unweighted fit, the scale
    estimated from the residuals as the fitter's options say): pose and intrinsics unchanged.

    ``points`` and ``keep`` ({section: (n_s,) bool}) are the points the fit used, ``points_2d``
    their pixels if not ``points.points_2d`` (e.g. eccentricity-corrected), ``extra_px2`` the
    occlusion variances of every point (:func:`solver.suspects.occlusion_variances`, or None),
    added to the disc noise (:func:`_with_occlusion`). The fit is returned as it is when a point
    falls behind the camera.

    The detector's noise floor (``RefineOptions.sigma_floor_px``, the noise card) is not applied
    here: it is an RMS over every centre, gross errors included, while the scale of this model
    is the core of the errors. Measured RMS of z = error / std of X, Y, alpha with and without it
    (configs/detector.toml test split, 61 frames, and configs/centre_scene_b.toml, 60 frames):
    with the floor 0.97 / 0.75 / 1.01 and 1.02 / 0.87 / 0.99, without 1.11 / 0.87 / 1.13 and
    1.15 / 0.99 / 1.09 (target 0.85-1.2: Y's std was 1.3x too cautious with it)."""
    blocks, poses, intr, model, shapes = _stacked(fit, points, fitter, keep, points_2d)
    shapes = _with_occlusion(shapes, extra_px2, keep, blocks, poses, intr, model)
    res, jac, valid = stack_blocks(blocks, poses, intr, model)
    if not valid:
        return fit
    cov, sigma = covariance_from_jacobian(jac, res, fitter.sigma_px, None, shapes, fitter.options.noise_prior_px)
    prop = d_from_b_jacobian(*poses[0], *poses[1])
    out = replace(fit, covariance=prop @ cov[:12, :12] @ prop.T, covariance_params=cov, sigma_px=sigma)
    k2 = sigma ** 2 / (np.trace(shapes, axis1=1, axis2=2).mean() / 2.0)
    return _checked(out, blocks, poses, intr, model, np.linalg.inv(np.linalg.cholesky(shapes)), k2, fitter)


def _checked(fit: JointFit, blocks, poses, intr, model, sqrt_w, k2: float, fitter: JointFitter) -> JointFit:
    """``fit`` with the model error of its camera model (:func:`solver.model_error.model_check`
    with the fitter's lens prior; ``sqrt_w`` (n, 2, 2) or None the estimator's whitening of the
    points, ``k2`` the noise scale of the whitened residuals, ``fit.sigma_px`` the per-axis px
    noise it stands for). The check is also made against the known noise
    (:func:`_known_noise_px` times ``GATE_NOISE_FACTOR``), when there is one."""
    known = _known_noise_px(fitter)
    known_k2 = None if known is None or not fit.sigma_px > 0 else k2 * (GATE_NOISE_FACTOR * known / fit.sigma_px) ** 2
    check = model_check(blocks, poses, intr, model, fit.covariance_params.shape[0], sqrt_w, k2,
                        fitter.lens, fitter.principal_point, fitter.sigma_px is not None, known_k2)
    return _with_shift(with_model_check(fit, check), blocks, poses, intr, model, sqrt_w, fitter.section_shift_px)


def _known_noise_px(fitter: JointFitter) -> float | None:
    """The centre noise (px per axis) the fitter's caller knows: the detector's noise floor
    (``RefineOptions.sigma_floor_px``, the noise card) when set, else the given ``sigma_px``;
    None when neither is (the goodness-of-fit gate's noise, eval.fit_gate, before its factor)."""
    floor = fitter.options.sigma_floor_px
    return float(floor) if floor is not None else fitter.sigma_px


def _with_shift(fit: JointFit, blocks, poses, intr, model, sqrt_w, shift_px) -> JointFit:
    """``fit`` with the covariance of a common shift of each section's centres (std ``shift_px``
    per axis; :func:`solver.section_shift.section_shift_covariance`), weighted as the estimator
    (``sqrt_w`` or None); ``fit`` unchanged without a shift or when a point is behind the camera."""
    if shift_px is None or not any(v > 0 for v in shift_px):
        return fit
    _, jac, valid = stack_blocks(blocks, poses, intr, model)
    if not valid:
        return fit
    groups = np.concatenate([np.full(b.points_3d.shape[0], k) for k, b in enumerate(blocks)])
    return with_added_covariance(fit, section_shift_covariance(jac, groups, shift_px, sqrt_w))


def with_model_error(fit: JointFit, points_3d: dict, points_2d: dict, fitter: JointFitter) -> JointFit:
    """``fit`` (an unweighted fit with isotropic noise ``fit.sigma_px`` of ``points_3d`` and
    ``points_2d``, {section: (n_s, 3) mm / (n_s, 2) px}) with the model error of its camera
    model (:mod:`solver.model_error`)."""
    blocks = tuple(Block(points_3d[s], points_2d[s], k) for k, s in enumerate(SECTIONS))
    poses = tuple((c[:3, :3], c[:3, 3]) for c in (fit.cam_from_a, fit.cam_from_b))
    intr = fit.intrinsics or Intrinsics.pinhole(fit.focal_px, fitter.principal_point)
    return _checked(fit, blocks, poses, intr, camera_model(fit.model), None, fit.sigma_px ** 2, fitter)


def _stacked(fit: JointFit, points: SectionPoints, fitter: JointFitter, keep: dict, points_2d):
    """(blocks, poses, intrinsics, model, noise shapes (n, 2, 2)) of the points ``keep`` at
    ``fit``."""
    p2 = points.points_2d if points_2d is None else points_2d
    blocks, shapes = [], []
    for k, s in enumerate(SECTIONS):
        rows = [r for r, ok in zip(points.rows[s], keep[s]) if ok]
        blocks.append(Block(points.points_3d[s][keep[s]], p2[s][keep[s]], k))
        shapes.append(section_noise_shapes([points.markers[r] for r in rows], fit.cams[s], fit.focal_px))
    intr = fit.intrinsics or Intrinsics.pinhole(fit.focal_px, fitter.principal_point)
    poses = tuple((c[:3, :3], c[:3, 3]) for c in (fit.cam_from_a, fit.cam_from_b))
    return tuple(blocks), poses, intr, camera_model(fit.model), np.concatenate(shapes)


def _loo_q(rho: np.ndarray, jw: np.ndarray) -> np.ndarray:
    """(n,) leave-one-out residuals rho_i^T (I - H_ii)^-1 rho_i of a whitened fit (see
    :func:`t_weights`)."""
    h = np.eye(2) - np.einsum("nap,pq,nbq->nab", jw, inverse_spd(np.einsum("nap,naq->pq", jw, jw)), jw)
    return np.einsum("na,nab,nb->n", rho, np.linalg.inv(h), rho)


def _with_occlusion(shapes: np.ndarray, extra_px2: dict | None, keep: dict, blocks, poses, intr,
                    model) -> np.ndarray:
    """``shapes`` (n, 2, 2) plus the extra variance ``extra_px2`` ({section: (n_s, 2, 2)} px^2
    of every point, :func:`solver.suspects.occlusion_variances`; None: none) of the points
    ``keep``, in the shapes' units: px^2 over the frame's noise scale k^2, the robust (median
    leave-one-out) scale of the first round of :func:`t_weights` on the fit as it is."""
    if extra_px2 is None:
        return shapes
    extra = np.concatenate([extra_px2[s][keep[s]] for s in SECTIONS])
    if not np.any(extra):
        return shapes
    rho, jw, valid = _whitened_residuals(blocks, poses, intr, model,
                                         np.linalg.inv(np.linalg.cholesky(shapes)))
    if not valid:
        return shapes
    k2 = float(np.median(_loo_q(rho, jw))) / MEDIAN_CHI2_2
    if not (np.isfinite(k2) and k2 > 0):
        return shapes
    return shapes + extra / k2


def t_weights(rho: np.ndarray, jw: np.ndarray, previous: np.ndarray | None = None,
              nu: float = ROBUST_NU) -> np.ndarray:
    """(n,) Student-t weights (nu + 2) / (nu + q_i / s^2) of n points from their residuals
    ``rho`` (n, 2) and Jacobian rows ``jw`` (n, 2, p), both whitened by each point's noise shape.

    First round (``previous`` None): q_i is point i's leave-one-out residual, rho_i^T (I -
    H_ii)^-1 rho_i (H the hat matrix of the whitened fit), and s^2 their median over that of a
    chi-square 2: a gross centre that the unweighted fit has absorbed (a point of high
    leverage) still stands out, and so does not mask itself. Later rounds: q_i the whitened
    residual, s^2 = sum w_i q_i / (2n - p) with the previous weights (the scale step of the t
    likelihood's EM)."""
    n, p = jw.shape[0], jw.shape[2]
    if previous is None:
        q = _loo_q(rho, jw)
        s2 = float(np.median(q)) / MEDIAN_CHI2_2
    else:
        q = np.sum(rho * rho, axis=1)
        s2 = float(previous @ q) / max(2 * n - p, 1)
    return (nu + 2.0) / (nu + q / max(s2, 1e-300))


def _whitened_residuals(blocks, poses, intr, model, winv: np.ndarray):
    """(rho (n, 2), jw (n, 2, p), valid) of the unweighted blocks at (poses, intr), whitened by
    ``winv`` (n, 2, 2): each point's inverse Cholesky factor of its noise shape."""
    res, jac, valid = stack_blocks(blocks, poses, intr, model)
    r, j = whitened(winv, res, jac)
    return r.reshape(-1, 2), j.reshape(winv.shape[0], 2, -1), valid


def robust_refit(fit: JointFit, points: SectionPoints, fitter: JointFitter, keep: dict,
                 points_2d: dict | None = None, extra_px2: dict | None = None) -> JointFit:
    """``fit`` refitted by iteratively reweighted least squares under the disc noise model with
    Student-t tails (:func:`t_weights`, ``ROBUST_ITERATIONS`` rounds): a centre far off what its
    disc's noise explains (a partly hidden or glared disc) loses its pull without a yes/no
    decision about which one. ``extra_px2``: as in :func:`with_disc_noise`; with it the fit
    weighted by that noise comes first, so that the first round's leave-one-out residuals are
    those of the fit their hat matrix describes. Its covariance: :func:`_robust_result`. ``fit`` comes back with
    the disc noise covariance of the unweighted fit (:func:`with_disc_noise`) if a refit fails.

    A median-based scale (collapsing onto the good points of a dozen) and raw first-round
    residuals (a high-leverage gross centre masks itself) did worse on the synthetic test
    (tests/solver/test_disc_noise.py); what the reweighting buys on two scenes:
    results/README.md."""
    blocks, poses, intr, model, base = _stacked(fit, points, fitter, keep, points_2d)
    shapes = _with_occlusion(base, extra_px2, keep, blocks, poses, intr, model)
    winv = np.linalg.inv(np.linalg.cholesky(shapes))
    sizes = np.cumsum([0] + [b.points_3d.shape[0] for b in blocks])
    w = None
    try:
        if shapes is not base:
            # the residuals the first round's leave-one-out test reads must be those of the fit
            # its hat matrix describes (the one weighted by the inflated noise): a partly hidden
            # centre that the unweighted fit absorbed would otherwise show as large residuals of
            # its section's good points, which the inflation has just given leverage near 1
            whitened_blocks = tuple(replace(b, sqrt_info=winv[sizes[k]:sizes[k + 1]]) for k, b in enumerate(blocks))
            ref = refine_blocks(whitened_blocks, poses, intr, model, fitter.options)
            poses, intr = ref.poses, ref.intrinsics
        for _ in range(ROBUST_ITERATIONS):
            rho, jw, valid = _whitened_residuals(blocks, poses, intr, model, winv)
            if not valid:
                return with_disc_noise(fit, points, fitter, keep, points_2d, extra_px2)
            w = t_weights(rho, jw, w)
            info = np.sqrt(w)[:, None, None] * winv
            weighted = tuple(replace(b, sqrt_info=info[sizes[k]:sizes[k + 1]]) for k, b in enumerate(blocks))
            ref = refine_blocks(weighted, poses, intr, model, fitter.options)
            poses, intr = ref.poses, ref.intrinsics
    except SolverError:
        return with_disc_noise(fit, points, fitter, keep, points_2d, extra_px2)
    return _robust_result(fit, ref, blocks, shapes, winv, w, base, fitter)


def _robust_result(fit: JointFit, ref, blocks, shapes, winv, previous: np.ndarray,
                   base: np.ndarray | None = None, fitter: JointFitter | None = None) -> JointFit:
    """The JointFit of the robust refinement ``ref``. Its covariance is the sandwich of the
    weighted estimate under the disc noise model, k^2 A^-1 B A^-1 with A = sum w_i J_i^T T_i^-1
    J_i and B = sum w_i^2 J_i^T T_i^-1 J_i (the final weights), the scale k^2 = sum w_i q_i /
    (2n - p) (the t likelihood's) with the Student-t factor of
    :func:`solver.refine.covariance_from_jacobian` (its calibration: results/README.md), plus the
    model error of its camera model under ``fitter``'s lens prior (:func:`_checked`; no
    ``fitter``: none)."""
    (ra, ta), (rb, tb) = ref.poses
    rw, jw, _ = _whitened_residuals(blocks, ref.poses, ref.intrinsics, ref.model, winv)
    w = t_weights(rw, jw, previous)
    a_inv = inverse_spd(np.einsum("n,nap,naq->pq", w, jw, jw))
    b = np.einsum("n,nap,naq->pq", w * w, jw, jw)
    dof = 2 * shapes.shape[0] - jw.shape[2]
    base = shapes if base is None else base      # sigma: the disc noise, without occlusion
    mean_var = float(np.trace(base, axis1=1, axis2=2).mean()) / 2.0
    prior = None if fitter is None else fitter.options.noise_prior_px
    _, k2 = scale_with_prior(float(w @ np.sum(rw * rw, axis=1)) / max(dof, 1), dof,
                             None if prior is None else prior ** 2 / mean_var)
    cov = k2 * (a_inv @ b @ a_inv)
    sigma = float(np.sqrt(k2 * mean_var))   # px, per axis
    res, _, _ = stack_blocks(blocks, ref.poses, ref.intrinsics, ref.model, want_jacobian=False)
    na = 2 * blocks[0].points_3d.shape[0]
    rmse = [float(np.sqrt(2.0 * (r @ r) / max(r.size, 1))) for r in (res[:na], res[na:])]
    cam_a, cam_b = np.eye(4), np.eye(4)
    cam_a[:3, :3], cam_a[:3, 3], cam_b[:3, :3], cam_b[:3, 3] = ra, ta, rb, tb
    prop = d_from_b_jacobian(ra, ta, rb, tb)
    out = replace(fit, cam_from_a=cam_a, cam_from_b=cam_b, focal_px=float(ref.intrinsics.focal_px),
                  d_from_b=relative_pose(ra, ta, rb, tb), covariance=prop @ cov[:12, :12] @ prop.T,
                  covariance_params=cov, sigma_px=sigma, rmse_a=rmse[0], rmse_b=rmse[1],
                  iterations=fit.iterations + ref.iterations,
                  intrinsics=ref.intrinsics if fit.intrinsics is not None else None)
    if fitter is None:
        return out
    return _checked(out, blocks, ref.poses, ref.intrinsics, ref.model, np.sqrt(w)[:, None, None] * winv, k2, fitter)
