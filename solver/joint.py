"""Joint estimator: both sections in one image, one shared focal length, on validated arrays.

Layer 3 of the solver, beside :mod:`solver.estimate` (which it uses for its fallback starts):
closed-form starts per section (:mod:`solver.upnp`) -> the joint Levenberg-Marquardt over 13
parameters (:func:`solver.refine.refine_joint`) -> covariance sigma^2 (J^T J)^-1 and
``d_from_b = inv(cam_from_a) @ cam_from_b`` with the covariance of (X, Y, Z, alpha, beta, gamma)
propagated to first order. Results travel as :class:`JointFit`; RANSAC, identification and the
docking pipeline (suspects, eccentricity) all fit through :class:`JointFitter`.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dockfactory.solver.errors import FocalNotObservable, NoValidCamera, SolverError
from dockfactory.solver.estimate import estimate_pnpf
from dockfactory.solver.options import RefineOptions
from dockfactory.solver.refine import (
    DEFAULT_REFINE,
    JointRefineResult,
    covariance_from_jacobian,
    d_from_b_jacobian,
    refine_joint,
    rel_focal_std,
    relative_pose,
)
from dockfactory.solver.upnp import upnp

__all__ = ["JointStart", "JointFit", "JointFitter", "SectionPoints", "fit_joint"]


@dataclass(frozen=True)
class JointStart:
    """Start of the joint LM: ``cam_from_a``, ``cam_from_b`` (4, 4), shared ``focal_px``."""

    cam_from_a: np.ndarray
    cam_from_b: np.ndarray
    focal_px: float

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
    reprojection RMS per section (px, per point); LM ``iterations``.
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

    @property
    def cams(self) -> dict:
        """{"A": cam_from_a, "B": cam_from_b}."""
        return {"A": self.cam_from_a, "B": self.cam_from_b}

    @property
    def start(self) -> JointStart:
        """This fit as the start of another joint LM."""
        return JointStart(self.cam_from_a, self.cam_from_b, self.focal_px)


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
    estimated from the residuals) and the refinement ``options``."""

    principal_point: np.ndarray
    sigma_px: float | None = None
    options: RefineOptions = DEFAULT_REFINE

    def fit(self, points_a, uv_a, points_b, uv_b, start: JointStart | None = None,
            accept_rmse: float | None = None) -> JointFit:
        return fit_joint(points_a, uv_a, points_b, uv_b, self.principal_point, self.sigma_px,
                         start, accept_rmse, self.options)

    def refit(self, fit: JointFit, points: SectionPoints, keep: dict,
              points_2d: dict | None = None) -> JointFit:
        """Fit on the points ``keep[s]`` ((n_s,) bool) of each section, started from ``fit``;
        ``points_2d`` replaces ``points.points_2d`` (e.g. corrected centres)."""
        p3, p2 = points.points_3d, points.points_2d if points_2d is None else points_2d
        return self.fit(p3["A"][keep["A"]], p2["A"][keep["A"]], p3["B"][keep["B"]],
                        p2["B"][keep["B"]], start=fit.start)


def fit_joint(points_a, uv_a, points_b, uv_b, pp, sigma_px=None, start=None, accept_rmse=None,
              options: RefineOptions = DEFAULT_REFINE) -> JointFit:
    """Joint solve on validated arrays: ``points_a`` (Na, 3) mm in A, ``uv_a`` (Na, 2) px, same
    for B; ``pp`` (2,) px.

    ``start`` (a :class:`JointStart`) replaces the closed-form start. If the joint LM does not
    converge, or ends with an RMS above ``accept_rmse`` px, each section is first solved on its
    own (:func:`solver.estimate.estimate_pnpf`) and the joint LM restarts from those; the lowest
    cost wins. Raises NoValidCamera when no start refines, FocalNotObservable when the shared
    focal ran off (``options.max_joint_focal_rel_std``).
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
    cov13, sigma = covariance_from_jacobian(jr.jacobian, res, sigma_px)
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
