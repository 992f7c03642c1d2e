"""Cramer-Rao lower bounds under isotropic Gaussian pixel noise (std ``sigma_px`` per coordinate).

For a model u = pi(theta) with i.i.d. N(0, sigma^2) noise on every pixel coordinate the Fisher
information is J^T J / sigma^2 (J = d pi / d theta at the true theta), so every unbiased estimator
has covariance >= sigma^2 (J^T J)^-1. Parameters are ordered as in :mod:`solver.refine`:

- one section (7): ``(w, t, f)``, rotation vector w (rad, left perturbation in the camera
  frame), t (mm), f (px); ``focal_known=True`` drops f (6 parameters, calibrated camera);
- joint (13): ``(w_A, t_A, w_B, t_B, f)``, one focal length shared by both sections.

The bound on ``d_from_b``'s (X, Y, Z, alpha, beta, gamma) follows by first-order propagation
(exact for the bound of a smooth function of the parameters) through
:func:`solver.refine.d_from_b_jacobian`. Two problems are offered for it:
``"joint"`` (both sections in one estimation, shared focal: what :func:`solver.solve_docking`
solves) and ``"independent"`` (each section solved on its own with its own focal: the bound for
any single-section solver applied twice).

A side branch of the solver: uses only the Jacobian and the covariance inverse of
:mod:`solver.refine` (the same ones the estimators use) and the input checks.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dockfactory.core.names import POSE_NAMES
from dockfactory.solver.checks import as_points, as_principal_point
from dockfactory.solver.errors import DegenerateGeometry, InvalidSolverInput
from dockfactory.solver.refine import (
    d_from_b_jacobian,
    inverse_spd,
    joint_jacobian,
    residuals_and_jacobian,
)

__all__ = ["crb_pnpf", "crb_joint", "crb_d_from_b", "DockingBound", "POSE_NAMES"]


def _check_transform(name, value):
    arr = np.asarray(value, dtype=np.float64)
    if arr.shape != (4, 4) or not np.all(np.isfinite(arr)):
        raise InvalidSolverInput(f"{name}: expected a finite (4, 4) transform, got shape "
                                 f"{arr.shape}")
    return arr


def _jac(points_3d, cam_from_world, focal_px, principal_point):
    p3 = as_points("points_3d", points_3d, 3)
    cam = _check_transform("cam_from_world", cam_from_world)
    pp = as_principal_point(principal_point)
    if not (np.isfinite(focal_px) and focal_px > 0):
        raise InvalidSolverInput(f"focal_px must be positive and finite, got {focal_px}")
    uv = np.zeros((p3.shape[0], 2))
    _, jac, z = residuals_and_jacobian(p3, uv, pp, cam[:3, :3], cam[:3, 3], float(focal_px))
    if np.any(z <= 0):
        raise DegenerateGeometry("points behind the camera: the bound is undefined")
    return jac


def _inverse_information(jac, sigma_px):
    if not (np.isfinite(sigma_px) and sigma_px >= 0):
        raise InvalidSolverInput(f"sigma_px must be finite and >= 0, got {sigma_px}")
    inv = inverse_spd(jac.T @ jac)
    if not np.all(np.isfinite(inv)):
        raise DegenerateGeometry("Fisher information is singular: the parameters are not "
                                 "observable from these points (degenerate configuration)")
    return sigma_px ** 2 * inv


def crb_pnpf(points_3d, cam_from_world, focal_px: float, principal_point, sigma_px: float,
             focal_known: bool = False) -> np.ndarray:
    """Bound on the covariance of (w, t, f) for one section: (7, 7) ((6, 6) if focal_known).

    ``points_3d``: (N, 3) float64, mm, world frame; ``cam_from_world``: (4, 4) true pose;
    ``focal_px``: true focal (px); ``principal_point``: (2,) px; ``sigma_px``: noise std (px).
    """
    jac = _jac(points_3d, cam_from_world, focal_px, principal_point)
    if focal_known:
        jac = jac[:, :6]
    return _inverse_information(jac, sigma_px)


def _joint_jac(points_a, cam_from_a, points_b, cam_from_b, focal_px, principal_point):
    ja = _jac(points_a, cam_from_a, focal_px, principal_point)
    jb = _jac(points_b, cam_from_b, focal_px, principal_point)
    return joint_jacobian(ja, jb)


def crb_joint(points_a, cam_from_a, points_b, cam_from_b, focal_px: float, principal_point,
              sigma_px: float) -> np.ndarray:
    """Bound on the covariance of (w_A, t_A, w_B, t_B, f): (13, 13).

    ``points_a`` (Na, 3) mm in A's frame, ``points_b`` (Nb, 3) mm in B's frame,
    ``cam_from_a``/``cam_from_b`` (4, 4) true poses, shared ``focal_px``.
    """
    jac = _joint_jac(points_a, cam_from_a, points_b, cam_from_b, focal_px, principal_point)
    return _inverse_information(jac, sigma_px)


@dataclass(frozen=True)
class DockingBound:
    """Bound on d_from_b: ``covariance`` (6, 6) over POSE_NAMES, ``std`` dict name -> std."""
    covariance: np.ndarray
    std: dict
    problem: str


def crb_d_from_b(points_a, cam_from_a, points_b, cam_from_b, focal_px: float, principal_point,
                 sigma_px: float, problem: str = "joint") -> DockingBound:
    """Bound on (X, Y, Z mm, alpha, beta, gamma deg) of ``d_from_b`` (see module docstring).

    ``problem``: "joint" (13 parameters, shared focal), "independent" (7 + 7, a focal per
    section) or "calibrated" (6 + 6, focal known). Returns a :class:`DockingBound`; X, Y, alpha
    are ``std["x_mm"]``, ``std["y_mm"]``, ``std["alpha_deg"]``.
    """
    ca = _check_transform("cam_from_a", cam_from_a)
    cb = _check_transform("cam_from_b", cam_from_b)
    prop = d_from_b_jacobian(ca[:3, :3], ca[:3, 3], cb[:3, :3], cb[:3, 3])
    if problem == "joint":
        cov13 = crb_joint(points_a, ca, points_b, cb, focal_px, principal_point, sigma_px)
        cov12 = cov13[:12, :12]
    elif problem in ("independent", "calibrated"):
        known = problem == "calibrated"
        cov_a = crb_pnpf(points_a, ca, focal_px, principal_point, sigma_px, focal_known=known)
        cov_b = crb_pnpf(points_b, cb, focal_px, principal_point, sigma_px, focal_known=known)
        cov12 = np.zeros((12, 12))
        cov12[:6, :6] = cov_a[:6, :6]
        cov12[6:, 6:] = cov_b[:6, :6]
    else:
        raise InvalidSolverInput(f"problem must be 'joint', 'independent' or 'calibrated', "
                                 f"got {problem!r}")
    cov6 = prop @ cov12 @ prop.T
    std = dict(zip(POSE_NAMES, np.sqrt(np.diag(cov6)).tolist()))
    return DockingBound(cov6, std, problem)
