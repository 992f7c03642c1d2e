"""``solve_sequence``: a docking run of one camera unit solved at once (self-calibration).

A docking run is filmed by one camera whose pose and zoom stay fixed while B approaches A, and A
is fixed in the world: every frame shares the camera's intrinsics (f, principal point,
distortion) and, physically, the camera's pose relative to A. The run is solved as one
least-squares problem (top layer of the solver, beside :mod:`solver.docking`):

Why and how: docs/solver.md, "Docking runs (self-calibration)".
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from dockfactory.core.names import SECTIONS
from dockfactory.solver.camera_models import PINHOLE, Intrinsics, check_model_name
from dockfactory.solver.checks import as_principal_point, check_sigma
from dockfactory.solver.disc_noise import section_noise_shapes
from dockfactory.solver.docking import DockingResult
from dockfactory.solver.errors import InvalidSolverInput, NoValidCamera, SolverError
from dockfactory.solver.joint import fit_joint, joint_fit_from_model
from dockfactory.solver.layout_points import (
    LayoutArrays,
    checked_correspondences,
    section_arrays,
)
from dockfactory.solver.lie import project_to_so3
from dockfactory.solver.model_choice import ModelChoice
from dockfactory.solver.model_error import (
    BIAS_LENGTH,
    ModelCheck,
    model_check,
    persistent_bias_covariance,
    spatial_bias_factor,
)
from dockfactory.solver.model_fit import (
    ModelFit,
    check_model_focal,
    fit_camera_model,
    refine_model,
)
from dockfactory.solver.options import DEFAULT_DOCKING, DockingOptions
from dockfactory.solver.refine import Block
from dockfactory.solver.section_shift import section_shift_covariance

__all__ = ["SequenceResult", "solve_sequence"]


@dataclass(frozen=True)
class SequenceResult:
    """Result of :func:`solve_sequence`.

    - ``frames``: one :class:`solver.DockingResult` per input frame (pose of B in A, its
      covariance (6, 6), the frame's ``covariance_params`` block over (w_A, t_A, w_B, t_B, f,
      *free), reprojection RMS per section, and the run's shared intrinsics);
    - ``camera_model`` (chosen for "auto"), ``focal_px``, ``intrinsics`` {"cx", "cy", "k1",
      "k2", "p1", "p2"}, ``intrinsics_std`` {"focal_px", "cx", ...} (0.0 for fixed ones),
      ``intrinsics_covariance`` (1 + e, 1 + e) over (f, *free);
    - ``cam_from_a`` (4, 4): the shared camera pose (the first frame's when not shared);
      ``share_cam_from_a``; ``sigma_px`` the noise std used; ``rmse_px`` the run's
      reprojection RMS (px, per point); LM ``iterations``; ``model_choice`` (for "auto");
    - ``model_check``: the model error of the run's camera model (:mod:`solver.model_error`,
      the intrinsics the run does not estimate, shared by its frames): whether the model
      explains the run's residuals and, with ``options.lens.marginalise``, their pose error in
      every frame's covariance (each frame's ``model_check`` is this one);
    - ``bias_px``: the std per axis (px) of the bias field that persists over the run, as its
      residuals show it (0.0: none counted, or ``options.run_marker_bias`` off): a pattern of
      centre errors the camera repeats in every frame (lighting, blur, colour), in the covariance.
    """

    frames: tuple
    camera_model: str
    focal_px: float
    intrinsics: dict
    intrinsics_std: dict
    intrinsics_covariance: np.ndarray
    cam_from_a: np.ndarray
    share_cam_from_a: bool
    sigma_px: float
    rmse_px: float
    iterations: int
    model_choice: ModelChoice | None = None
    model_check: ModelCheck | None = None
    bias_px: float = 0.0


@dataclass(frozen=True)
class _Frame:
    """One frame's validated points: ``rows`` / ``p3`` / ``p2`` per section (as
    :func:`solver.layout_points.section_arrays`) and its marker ``ids`` (N,)."""

    ids: tuple
    rows: dict
    p3: dict
    p2: dict


def solve_sequence(markers, principal_point, frames, *, camera_model: str = PINHOLE.name,
                   sigma_px: float | None = None, share_cam_from_a: bool = True,
                   options: DockingOptions = DEFAULT_DOCKING) -> SequenceResult:
    """Poses of B in A for every frame of one docking run, the camera's intrinsics estimated once for the run.

    Parameters
    ----------
    markers, principal_point : layout (as :func:`solver.solve_docking`), (2,) px
        The assumed principal point (the image centre), the start of an estimated one.
    frames : sequence of F >= 1 correspondences
        Each a dict marker id -> (u, v) px or a pair (marker_ids (N,), points_2d (N, 2)), every section with at least
        4 points per frame.
    camera_model : str
        A name of :data:`solver.camera_models.MODELS` or "auto".
    sigma_px : float or None
        The pixel noise std, or None (estimated from the residuals).
    share_cam_from_a : bool
        One camera pose relative to A for the whole run (the camera and A are fixed) or one per frame.
    options : DockingOptions

    Returns
    -------
    SequenceResult

    Raises
    ------
    SolverError : bad input (InvalidSolverInput), too few points (TooFewPoints), no valid camera (NoValidCamera), an
        unobservable focal (FocalNotObservable).
    """
    layout = LayoutArrays.of(markers)
    pp = as_principal_point(principal_point)
    sigma = check_sigma(sigma_px)
    model_name = check_model_name(camera_model)
    parsed = _parse_frames(layout, frames)
    pin = _pinhole_run(parsed, pp, sigma, bool(share_cam_from_a), options)
    blocks = _blocks(parsed, bool(share_cam_from_a))
    mf = fit_camera_model(blocks, pin, model_name, sigma, options.refine, options.model_choice)
    check_model_focal(mf, options.refine)
    noise2, bias = mf.sigma_px ** 2, 0.0   # the residuals' whole scale: what the misfit test weighs them by
    if options.run_marker_bias:
        mf, bias = _with_run_bias(mf, parsed, sigma, layout, bool(share_cam_from_a), pp,
                                  options.refine.sigma_floor_px)
    check = model_check(blocks, mf.poses, mf.intrinsics, mf.model, mf.covariance.shape[0], None,
                        noise2, options.lens, pp, sigma is not None)
    shift = _run_shift_covariance(mf, parsed, options.section_shift_px)
    return replace(_result(replace(mf, covariance=mf.covariance + check.added + shift), parsed,
                           bool(share_cam_from_a), check, shift), bias_px=bias)


def _run_shift_covariance(mf: ModelFit, parsed, shift_px) -> np.ndarray:
    """What one common shift of each section's centres over the whole run (std ``shift_px`` per
    axis, :func:`solver.section_shift.section_shift_covariance`) adds to the run's parameter
    covariance; zeros without a shift."""
    jac = mf.refinement.jacobian
    if shift_px is None:
        return np.zeros((jac.shape[1],) * 2)
    groups = np.concatenate([np.full(len(fr.rows[s]), k) for fr in parsed for k, s in enumerate(SECTIONS)])
    return section_shift_covariance(jac, groups, shift_px)


def _with_run_bias(mf: ModelFit, parsed, sigma, layout: LayoutArrays, share: bool, pp,
                   floor_px=None) -> tuple[ModelFit, float]:
    """(``mf`` with the covariance of noise plus a bias field that persists across the run's
    frames, correlated between nearby centres of a section (:func:`solver.model_error.
    spatial_bias_factor` over the image, correlation length BIAS_LENGTH image diagonals, the
    diagonal taken from the assumed principal point ``pp``; :func:`solver.model_error.
    persistent_bias_covariance`); with the noise estimated, each centre's noise shaped by its
    disc's image (:func:`solver.disc_noise.section_noise_shapes`),
    never below ``floor_px``; ``sigma_px`` its noise part, the field's std px per axis). ``mf``
    unchanged (and 0.0) when that covariance is not finite."""
    points, groups, shapes = [], [], []
    for k, fr in enumerate(parsed):
        for s, pose in zip(SECTIONS, _pose_indices(k, share)):
            rot, t = mf.poses[pose]
            cam = np.eye(4)
            cam[:3, :3], cam[:3, 3] = rot, t
            points.append(fr.p2[s])
            groups += [s] * len(fr.rows[s])
            shapes.append(section_noise_shapes([layout.by_id[fr.ids[r]] for r in fr.rows[s]], cam,
                                               mf.intrinsics.focal_px))
    extent = (2.0 * float(pp[0]) + 1.0, 2.0 * float(pp[1]) + 1.0)       # the image, from its centre
    factor = spatial_bias_factor(np.concatenate(points), np.array(groups), BIAS_LENGTH * float(np.hypot(*extent)),
                                 extent)
    ref = mf.refinement
    cov, sigma2, tau2 = persistent_bias_covariance(ref.jacobian, ref.residuals, factor, sigma,
                                                   None if sigma is not None else np.concatenate(shapes), floor_px)
    if not np.all(np.isfinite(cov)):
        return mf, 0.0
    return replace(mf, covariance=cov, sigma_px=float(np.sqrt(sigma2))), float(np.sqrt(tau2))


def _parse_frames(layout: LayoutArrays, frames) -> list:
    """Validated :class:`_Frame` per input frame (InvalidSolverInput for an empty run; a
    frame's own error prefixed with its index)."""
    try:
        frames = list(frames)
    except TypeError:
        raise InvalidSolverInput("frames: expected a sequence of correspondences") from None
    if not frames:
        raise InvalidSolverInput("frames: a docking run needs at least one frame")
    out = []
    for k, corr in enumerate(frames):
        try:
            ids, uv = checked_correspondences(layout, corr)
            rows, p3, p2 = section_arrays(layout, ids, np.ones(len(ids), dtype=bool), uv)
        except SolverError as exc:
            raise type(exc)(f"frame {k}: {exc}") from None
        out.append(_Frame(tuple(ids), rows, p3, p2))
    return out


def _blocks(parsed, share: bool) -> tuple:
    """Residual blocks A, B of every frame; poses: [A, B_0, B_1, ...] when shared, else
    [A_0, B_0, A_1, B_1, ...]."""
    out = []
    for k, fr in enumerate(parsed):
        ia, ib = _pose_indices(k, share)
        out += [Block(fr.p3["A"], fr.p2["A"], ia), Block(fr.p3["B"], fr.p2["B"], ib)]
    return tuple(out)


def _pose_indices(k: int, share: bool) -> tuple:
    return (0, k + 1) if share else (2 * k, 2 * k + 1)


def _pinhole_run(parsed, pp, sigma, share: bool, options: DockingOptions) -> ModelFit:
    """Per-frame pinhole fits merged into one start, refined as one pinhole run."""
    fits = []
    for fr in parsed:
        try:
            fits.append(fit_joint(fr.p3["A"], fr.p2["A"], fr.p3["B"], fr.p2["B"], pp, None,
                                  options=options.refine))
        except SolverError:
            fits.append(None)
    good = [k for k, f in enumerate(fits) if f is not None]
    if not good:
        raise NoValidCamera("no frame of the run has a valid pinhole start")
    f0 = float(np.median([fits[k].focal_px for k in good]))
    scale = {k: f0 / fits[k].focal_px for k in good}
    rot_a = project_to_so3(sum(fits[k].cam_from_a[:3, :3] for k in good))
    t_a = np.mean([fits[k].cam_from_a[:3, 3] * scale[k] for k in good], axis=0)
    poses = [] if not share else [(rot_a, t_a)]
    for k in range(len(parsed)):
        src = min(good, key=lambda j: abs(j - k))       # nearest frame with a start
        cb = fits[src].cam_from_b
        if not share:
            poses.append((rot_a, t_a))
        poses.append((cb[:3, :3], cb[:3, 3] * scale[src]))
    return refine_model(_blocks(parsed, share), poses, Intrinsics.pinhole(f0, pp), PINHOLE,
                        sigma, options.refine)


def _result(mf: ModelFit, parsed, share: bool, check: ModelCheck, shift: np.ndarray) -> SequenceResult:
    """Per-frame DockingResults and the run's intrinsics from the run's model fit (its
    covariance with the model error ``check`` and the section shift's ``shift`` already added)."""
    out, row = [], 0
    for k, fr in enumerate(parsed):
        na, nb = 2 * len(fr.rows["A"]), 2 * len(fr.rows["B"])
        ia, ib = _pose_indices(k, share)
        rows = (slice(row, row + na), slice(row + na, row + na + nb), ia, ib)
        fit = replace(joint_fit_from_model(mf, *rows), model_check=check,
                      shift_covariance=joint_fit_from_model(replace(mf, covariance=shift), *rows).covariance
                      if np.any(shift) else None)
        row += na + nb
        n = len(fr.ids)
        out.append(DockingResult.from_fit(fit, fr.ids, np.ones(n, dtype=bool),
                                          np.zeros(n, dtype=bool)))
    i0 = mf.focal_index
    res = mf.refinement.residuals
    rot, t = mf.poses[0]
    cam_a = np.eye(4)
    cam_a[:3, :3], cam_a[:3, 3] = rot, t
    return SequenceResult(tuple(out), mf.model.name, float(mf.intrinsics.focal_px),
                          mf.intrinsics.values(), mf.intrinsics_std(),
                          mf.covariance[i0:, i0:].copy(), cam_a, share, mf.sigma_px,
                          float(np.sqrt(2.0 * (res @ res) / res.size)),
                          mf.refinement.iterations, mf.choice, check)
