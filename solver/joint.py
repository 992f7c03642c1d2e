"""Joint estimator: both sections in one image, one shared focal length, on validated arrays.

Layer 3 of the solver, beside :mod:`solver.estimate` (which it uses for its fallback starts):
closed-form starts per section (:mod:`solver.upnp`) -> the joint Levenberg-Marquardt over 13
parameters (:func:`solver.refine.refine_joint`) -> covariance sigma^2 (J^T J)^-1 and
``d_from_b = inv(cam_from_a) @ cam_from_b`` with the covariance of (X, Y, Z, alpha, beta, gamma)
propagated to first order. Results travel as :class:`JointFit`; RANSAC, identification and the
docking pipeline (suspects, eccentricity) all fit through :class:`JointFitter`.

Camera models beyond the pinhole (:mod:`solver.camera_models`): :class:`JointFitter` with
``camera_model`` other than "pinhole" fits the pinhole first (as above), then refines the
model's extra intrinsics from it (:mod:`solver.model_fit`; "auto" chooses the model); a refit
started from such a fit (``fit.start``) keeps its model and intrinsics.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from dockfactory.solver.camera_models import PINHOLE, Intrinsics, camera_model
from dockfactory.solver.errors import FocalNotObservable, NoValidCamera, SolverError
from dockfactory.solver.estimate import estimate_pnpf
from dockfactory.solver.model_choice import ModelChoice
from dockfactory.solver.model_error import ModelCheck
from dockfactory.solver.model_fit import (
    ModelFit,
    check_model_focal,
    fit_camera_model,
    refine_model,
)
from dockfactory.solver.options import (
    DEFAULT_LENS_PRIOR,
    DEFAULT_MODEL_CHOICE,
    LensPrior,
    ModelChoiceOptions,
    RefineOptions,
)
from dockfactory.solver.refine import (
    DEFAULT_REFINE,
    Block,
    JointRefineResult,
    covariance_from_jacobian,
    d_from_b_jacobian,
    refine_joint,
    rel_focal_std,
    relative_pose,
)
from dockfactory.solver.upnp import upnp

__all__ = ["JointStart", "JointFit", "JointFitter", "SectionPoints", "fit_joint",
           "joint_fit_from_model", "with_model_check", "with_added_covariance"]


@dataclass(frozen=True)
class JointStart:
    """Start of the joint LM: ``cam_from_a``, ``cam_from_b`` (4, 4), shared ``focal_px``;
    optionally the camera ``model`` (a name) and its ``intrinsics`` of a previous fit (a refit
    keeps them), and the automatic ``choice`` that selected that model."""

    cam_from_a: np.ndarray
    cam_from_b: np.ndarray
    focal_px: float
    intrinsics: Intrinsics | None = None
    model: str | None = None
    choice: ModelChoice | None = None

    def params(self) -> tuple:
        """(R_A (3, 3), t_A (3,), R_B, t_B, f) as :func:`solver.refine.refine_joint` takes."""
        ca, cb = self.cam_from_a, self.cam_from_b
        return ca[:3, :3], ca[:3, 3], cb[:3, :3], cb[:3, 3], self.focal_px


@dataclass(frozen=True)
class JointFit:
    """Result of :func:`fit_joint`.

    ``cam_from_a``, ``cam_from_b``, ``d_from_b`` (4, 4); ``focal_px``; ``covariance`` (6, 6)
    over ``POSE_NAMES`` (X, Y, Z mm, alpha, beta, gamma deg); ``covariance_params`` (13, 13)
    over (w_A, t_A, w_B, t_B, f); ``sigma_px`` the noise std used; ``rmse_a``, ``rmse_b``
    reprojection RMS per section (px, per point); LM ``iterations``; ``model`` the camera
    model's name, ``intrinsics`` (:class:`solver.camera_models.Intrinsics`; None only for a
    bare :func:`fit_joint`: pinhole at the caller's principal point) and ``choice`` (the
    automatic model choice, if any). With a model beyond the pinhole ``covariance_params`` is
    (13 + e, 13 + e) over (w_A, t_A, w_B, t_B, f, *model.free). ``model_check``: the model
    error of the final fit (:mod:`solver.model_error`; None before it is checked);
    ``shift_covariance`` (6, 6) over POSE_NAMES: what a common shift of each section's centres
    added to ``covariance`` (:mod:`solver.section_shift`; None: nothing added).
    """

    cam_from_a: np.ndarray
    cam_from_b: np.ndarray
    focal_px: float
    d_from_b: np.ndarray
    covariance: np.ndarray
    covariance_params: np.ndarray
    sigma_px: float
    rmse_a: float
    rmse_b: float
    iterations: int
    model: str = PINHOLE.name
    intrinsics: Intrinsics | None = None
    choice: ModelChoice | None = None
    model_check: ModelCheck | None = None
    shift_covariance: np.ndarray | None = None

    @property
    def cams(self) -> dict:
        """{"A": cam_from_a, "B": cam_from_b}."""
        return {"A": self.cam_from_a, "B": self.cam_from_b}

    @property
    def start(self) -> JointStart:
        """This fit as the start of another joint LM (same camera model and intrinsics)."""
        return JointStart(self.cam_from_a, self.cam_from_b, self.focal_px, self.intrinsics,
                          self.model, self.choice)


@dataclass(frozen=True)
class SectionPoints:
    """The points a docking fit uses, per section s in ("A", "B"): ``rows[s]`` the input rows
    (list of n_s ints), ``points_3d[s]`` (n_s, 3) mm in the section's frame, ``points_2d[s]``
    (n_s, 2) px; ``markers`` (N,): the layout marker of every input row (None if not
    identified)."""

    rows: dict
    points_3d: dict
    points_2d: dict
    markers: tuple


@dataclass(frozen=True)
class JointFitter:
    """:func:`fit_joint` bound to one image: ``principal_point`` (2,) px, ``sigma_px`` (None:
    estimated from the residuals), the refinement ``options``, the ``camera_model`` (a name of
    :data:`solver.camera_models.MODELS` or "auto"), the automatic choice's
    ``choice_options``, the ``lens`` prior of the final fit's model error
    (:mod:`solver.model_error`) and the ``section_shift_px`` (x, y) std of a common offset of
    each section's centres (:mod:`solver.section_shift`; None: none)."""

    principal_point: np.ndarray
    sigma_px: float | None = None
    options: RefineOptions = DEFAULT_REFINE
    camera_model: str = PINHOLE.name
    choice_options: ModelChoiceOptions = DEFAULT_MODEL_CHOICE
    lens: LensPrior = DEFAULT_LENS_PRIOR
    section_shift_px: tuple | None = None

    def fit(self, points_a, uv_a, points_b, uv_b, start: JointStart | None = None,
            accept_rmse: float | None = None) -> JointFit:
        """Fit with the fitter's camera model, or with ``start``'s model when it has one."""
        model = start.model if start is not None and start.model is not None else \
            self.camera_model
        if model == PINHOLE.name:
            fit = fit_joint(points_a, uv_a, points_b, uv_b, self.principal_point, self.sigma_px,
                            start, accept_rmse, self.options)
            return replace(fit, intrinsics=Intrinsics.pinhole(fit.focal_px,
                                                              self.principal_point),
                           choice=None if start is None else start.choice)
        blocks = (Block(points_a, uv_a, 0), Block(points_b, uv_b, 1))
        if start is not None and start.intrinsics is not None:
            mf = refine_model(blocks, _poses(start.cam_from_a, start.cam_from_b),
                              start.intrinsics, camera_model(model), self.sigma_px, self.options)
            mf = replace(mf, choice=start.choice)
        else:
            pin = fit_joint(points_a, uv_a, points_b, uv_b, self.principal_point,
                            self.sigma_px, start, accept_rmse, self.options)
            pin_mf = refine_model(blocks, _poses(pin.cam_from_a, pin.cam_from_b),
                                  Intrinsics.pinhole(pin.focal_px, self.principal_point),
                                  PINHOLE, self.sigma_px, self.options)
            mf = fit_camera_model(blocks, pin_mf, model, self.sigma_px, self.options,
                                  self.choice_options)
        check_model_focal(mf, self.options)
        na = 2 * points_a.shape[0]
        return joint_fit_from_model(mf, slice(0, na), slice(na, None))

    def refit(self, fit: JointFit, points: SectionPoints, keep: dict,
              points_2d: dict | None = None) -> JointFit:
        """Fit on the points ``keep[s]`` ((n_s,) bool) of each section, started from ``fit``;
        ``points_2d`` replaces ``points.points_2d`` (e.g. corrected centres)."""
        p3, p2 = points.points_3d, points.points_2d if points_2d is None else points_2d
        return self.fit(p3["A"][keep["A"]], p2["A"][keep["A"]], p3["B"][keep["B"]],
                        p2["B"][keep["B"]], start=fit.start)


def _poses(cam_from_a, cam_from_b) -> tuple:
    return ((cam_from_a[:3, :3], cam_from_a[:3, 3]), (cam_from_b[:3, :3], cam_from_b[:3, 3]))


def _transform(rot, t) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3], out[:3, 3] = rot, t
    return out


def joint_fit_from_model(mf: ModelFit, rows_a: slice, rows_b: slice, pose_a: int = 0,
                         pose_b: int = 1) -> JointFit:
    """The :class:`JointFit` of one frame of a model fit: poses ``pose_a`` (camera from A) and
    ``pose_b`` (camera from B), residual rows ``rows_a`` and ``rows_b`` of the fit's residual
    vector. ``covariance_params`` is the frame's block (w_A, t_A, w_B, t_B, f, *free) of the
    model fit's covariance."""
    (ra, ta), (rb, tb) = mf.poses[pose_a], mf.poses[pose_b]
    i0 = mf.focal_index
    idx = np.r_[6 * pose_a:6 * pose_a + 6, 6 * pose_b:6 * pose_b + 6,
                i0:mf.covariance.shape[0]]
    cov = mf.covariance[np.ix_(idx, idx)]
    prop = d_from_b_jacobian(ra, ta, rb, tb)
    res = mf.refinement.residuals
    res_a, res_b = res[rows_a], res[rows_b]
    rmse_a, rmse_b = (float(np.sqrt(2.0 * (r @ r) / r.size)) for r in (res_a, res_b))
    return JointFit(_transform(ra, ta), _transform(rb, tb), float(mf.intrinsics.focal_px),
                    relative_pose(ra, ta, rb, tb), prop @ cov[:12, :12] @ prop.T, cov,
                    mf.sigma_px, rmse_a, rmse_b, mf.refinement.iterations, mf.model.name,
                    mf.intrinsics, mf.choice)


def with_model_check(fit: JointFit, check: ModelCheck) -> JointFit:
    """``fit`` carrying ``check``, its covariances grown by ``check.added`` (over the fit's
    (13 + e) parameters, the order of ``covariance_params``)."""
    return replace(_grown(fit, check.added)[0], model_check=check)


def with_added_covariance(fit: JointFit, added: np.ndarray) -> JointFit:
    """``fit`` with ``added`` (over its (13 + e) parameters) in its covariances and, as a pose
    covariance, in ``shift_covariance`` (what :mod:`solver.section_shift` adds)."""
    grown, prop = _grown(fit, added)
    return replace(grown, shift_covariance=prop @ added[:12, :12] @ prop.T)


def _grown(fit: JointFit, added: np.ndarray) -> tuple[JointFit, np.ndarray]:
    """(``fit`` with ``added`` in ``covariance_params`` and its pose ``covariance`` propagated
    again, the d_from_b propagation (6, 12) of the fit's poses)."""
    prop = d_from_b_jacobian(fit.cam_from_a[:3, :3], fit.cam_from_a[:3, 3], fit.cam_from_b[:3, :3],
                             fit.cam_from_b[:3, 3])
    params = fit.covariance_params + added
    return replace(fit, covariance_params=params, covariance=prop @ params[:12, :12] @ prop.T), prop


def fit_joint(points_a, uv_a, points_b, uv_b, pp, sigma_px=None, start=None, accept_rmse=None,
              options: RefineOptions = DEFAULT_REFINE) -> JointFit:
    """Joint solve (two sections, one shared focal) on validated arrays.

    Parameters
    ----------
    points_a, uv_a, points_b, uv_b, pp : (Na, 3) mm in A, (Na, 2) px, (Nb, 3) mm in B, (Nb, 2) px, (2,) px
    sigma_px : float or None
        Pixel noise std for the covariance (None: from the residuals).
    start : JointStart or None
        Replaces the closed-form start.
    accept_rmse : float or None
        If the joint LM does not converge, or ends with an RMS above ``accept_rmse`` px, each section is first solved
        on its own (:func:`solver.estimate.estimate_pnpf`) and the joint LM restarts from those; the lowest cost wins.
    options : RefineOptions

    Returns
    -------
    JointFit

    Raises
    ------
    NoValidCamera
        When no start refines.
    FocalNotObservable
        When the shared focal ran off (``options.max_joint_focal_rel_std``).
    """
    data = (points_a, uv_a, points_b, uv_b, pp)
    starts = [start.params()] if start is not None else _closed_form_starts(*data)
    errors: list = []
    best = _refine_from_starts(data, starts, None, errors, options, stop_when_converged=True)
    n_res = 2 * (points_a.shape[0] + points_b.shape[0])
    good = best is not None and best[1].converged and (
        accept_rmse is None or np.sqrt(2.0 * best[0] / n_res) <= accept_rmse)
    if not good:
        # fall back: solve each section on its own first, then join
        try:
            sol_a = estimate_pnpf(points_a, uv_a, pp, check_focal=False,
                                  accept_rmse=accept_rmse, options=options)
            sol_b = estimate_pnpf(points_b, uv_b, pp, check_focal=False,
                                  accept_rmse=accept_rmse, options=options)
        except SolverError as exc:
            errors.append(str(exc))
        else:
            best = _refine_from_starts(data, _joint_starts(sol_a, sol_b), best, errors, options,
                                       stop_when_converged=False)
    if best is None:
        raise NoValidCamera("joint refinement failed: " + "; ".join(errors))
    return _joint_fit_result(best[1], sigma_px, options)


def _refine_from_starts(data, starts, best, errors, options, stop_when_converged):
    """Joint LM from each start; returns the lowest-cost (cost, JointRefineResult) so far
    (``best``, may be None). Failures append their message to ``errors``."""
    for st in starts:
        try:
            jr = refine_joint(*data, *st, options)
        except SolverError as exc:
            errors.append(str(exc))
            continue
        cost = float(jr.residuals_a @ jr.residuals_a + jr.residuals_b @ jr.residuals_b)
        if best is None or cost < best[0]:
            best = (cost, jr)
        if jr.converged and stop_when_converged:
            break
    return best


def _joint_fit_result(jr: JointRefineResult, sigma_px, options: RefineOptions) -> JointFit:
    """Covariances, observability check and ``d_from_b`` of a joint refinement."""
    res = np.concatenate([jr.residuals_a, jr.residuals_b])
    cov13, sigma = covariance_from_jacobian(jr.jacobian, res, sigma_px, options.sigma_floor_px)
    rel = rel_focal_std(cov13, jr.focal_px)
    if not rel <= options.max_joint_focal_rel_std:
        raise FocalNotObservable(f"focal length is not observable from these points (relative "
                                 f"std {rel:.3g}); the pose cannot be trusted")
    prop = d_from_b_jacobian(jr.rotation_a, jr.translation_a, jr.rotation_b, jr.translation_b)
    cov6 = prop @ cov13[:12, :12] @ prop.T
    cam_a = np.eye(4)
    cam_a[:3, :3], cam_a[:3, 3] = jr.rotation_a, jr.translation_a
    cam_b = np.eye(4)
    cam_b[:3, :3], cam_b[:3, 3] = jr.rotation_b, jr.translation_b
    rmse = {s: float(np.sqrt(2.0 * (r @ r) / r.size))
            for s, r in (("A", jr.residuals_a), ("B", jr.residuals_b))}
    d_from_b = relative_pose(jr.rotation_a, jr.translation_a, jr.rotation_b, jr.translation_b)
    return JointFit(cam_a, cam_b, float(jr.focal_px), d_from_b, cov6, cov13, sigma, rmse["A"],
                    rmse["B"], jr.iterations)


def _closed_form_starts(points_a, uv_a, points_b, uv_b, pp):
    """Joint LM start from the per-section closed forms (cheap path first)."""
    cands = []
    for p3, p2 in ((points_a, uv_a), (points_b, uv_b)):
        c = upnp(p3, p2, pp, checked=True, first_only=True)
        if not c:
            c = upnp(p3, p2, pp, checked=True, sweep_above_px=None)
        cands.append(c[0])
    ca, cb = cands
    f0 = float(np.sqrt(ca.focal_px * cb.focal_px))
    return [(ca.rotation, ca.translation * (f0 / ca.focal_px),
             cb.rotation, cb.translation * (f0 / cb.focal_px), f0)]


def _joint_starts(sol_a, sol_b):
    """Initial (R_A, t_A, R_B, t_B, f) for the joint LM from two section estimates
    (:class:`solver.estimate.PnPfEstimate`), most plausible first.

    Focal candidates: the better-determined section's own focal (smaller relative std), the
    geometric mean, the other section's focal. Translations are rescaled with the focal
    (f / depth is what the image fixes).
    """
    ref_a, ref_b = sol_a.refinement, sol_b.refinement
    rel_a = rel_focal_std(sol_a.covariance, ref_a.focal_px)
    rel_b = rel_focal_std(sol_b.covariance, ref_b.focal_px)
    first, other = (ref_a.focal_px, ref_b.focal_px) if rel_a <= rel_b else \
        (ref_b.focal_px, ref_a.focal_px)
    out = []
    for f0 in (first, np.sqrt(first * other), other):
        out.append((ref_a.rotation, ref_a.translation * (f0 / ref_a.focal_px),
                    ref_b.rotation, ref_b.translation * (f0 / ref_b.focal_px), f0))
    return out
