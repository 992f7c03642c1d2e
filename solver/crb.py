"""Cramer-Rao lower bounds under Gaussian pixel noise (std ``sigma_px`` per coordinate).

Parameters are ordered as in :mod:`solver.refine`:

- one section (7): ``(w, t, f)``, rotation vector w (rad, left perturbation in the camera
  frame), t (mm), f (px); ``focal_known=True`` drops f (6 parameters, calibrated camera);
- joint (13): ``(w_A, t_A, w_B, t_B, f)``, one focal length shared by both sections;
- joint with a camera model (:mod:`solver.camera_models`, ``camera_model`` and the true
  ``coeffs``): (13 + e) over ``(w_A, t_A, w_B, t_B, f, *model.free)``;
- a docking run (:func:`crb_sequence`): F frames, shared intrinsics, cam_from_a shared or one
  per frame, one cam_from_b per frame, as :func:`solver.solve_sequence` estimates them.

Why and how: docs/solver.md, "Cramer-Rao bounds".
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from dockfactory.core.distortion import coeffs_array
from dockfactory.core.names import POSE_NAMES
from dockfactory.solver.camera_models import (
    EXTRA_NAMES,
    MODELS,
    PINHOLE,
    Intrinsics,
    check_model_name,
)
from dockfactory.solver.checks import as_point_covariances, as_points, as_principal_point
from dockfactory.solver.errors import DegenerateGeometry, InvalidSolverInput
from dockfactory.solver.refine import (
    Block,
    d_from_b_jacobian,
    inverse_spd,
    joint_jacobian,
    residuals_and_jacobian,
    stack_blocks,
)

__all__ = ["crb_pnpf", "crb_joint", "crb_d_from_b", "crb_d_from_b_structured", "crb_sequence",
           "DockingBound", "SequenceBound", "POSE_NAMES"]


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


def _inverse_information(jac, sigma_px, noise_shapes=None, normalise: bool = True):
    """sigma^2 (J^T J)^-1, or with ``noise_shapes`` (N, 2, 2) (rows of ``jac``: 2N interleaved
    u, v) the inverse of sum_i J_i^T C_i^-1 J_i (module docstring; ``normalise`` False: the
    shapes are already normalised, over a larger set of points, and C_i = sigma^2 T_i)."""
    if not (np.isfinite(sigma_px) and sigma_px >= 0):
        raise InvalidSolverInput(f"sigma_px must be finite and >= 0, got {sigma_px}")
    if noise_shapes is None:
        info, scale2 = jac.T @ jac, sigma_px ** 2
    else:
        t = as_point_covariances("noise_shapes", noise_shapes, jac.shape[0] // 2)
        jr = jac.reshape(-1, 2, jac.shape[1])
        info = np.einsum("nap,nab,nbq->pq", jr, np.linalg.inv(t), jr)
        scale2 = sigma_px ** 2 / (_mean_axis_variance(t) if normalise else 1.0)
    inv = inverse_spd(info)
    if not np.all(np.isfinite(inv)):
        raise DegenerateGeometry("Fisher information is singular: the parameters are not "
                                 "observable from these points (degenerate configuration)")
    return scale2 * inv


def _mean_axis_variance(shapes: np.ndarray) -> float:
    """mean_i tr(T_i) / 2 of (N, 2, 2) shapes."""
    return float(np.trace(shapes, axis1=1, axis2=2).mean()) / 2.0


def _pair(noise_shapes, n_a: int, n_b: int):
    """(shapes_a (n_a, 2, 2), shapes_b (n_b, 2, 2)) checked and concatenated (None stays
    None)."""
    if noise_shapes is None:
        return None
    try:
        shapes_a, shapes_b = noise_shapes
    except (TypeError, ValueError):
        raise InvalidSolverInput("noise_shapes: expected a pair (shapes_a (Na, 2, 2), "
                                 "shapes_b (Nb, 2, 2))") from None
    return np.concatenate([as_point_covariances("noise_shapes[0]", shapes_a, n_a),
                           as_point_covariances("noise_shapes[1]", shapes_b, n_b)])


def crb_pnpf(points_3d, cam_from_world, focal_px: float, principal_point, sigma_px: float,
             focal_known: bool = False, noise_shapes=None) -> np.ndarray:
    """Cramer-Rao bound on the covariance of (w, t, f) for one section.

    Parameters
    ----------
    points_3d : (N, 3) float64, mm, world frame
    cam_from_world : (4, 4) true pose
    focal_px, principal_point, sigma_px : float px, (2,) px, float px
        The true focal, the principal point and the pixel noise std.
    focal_known : bool
        The focal is known: the bound over (w, t) only.
    noise_shapes : (N, 2, 2) or None
        None (isotropic) or the relative noise shapes (docs/solver.md, "Cramer-Rao bounds").

    Returns
    -------
    numpy.ndarray
        (7, 7) ((6, 6) if ``focal_known``).

    Raises
    ------
    InvalidSolverInput
        Non-positive focal, negative or non-finite sigma, malformed noise shapes.
    DegenerateGeometry
        Points behind the camera, or a singular Fisher information.
    """
    jac = _jac(points_3d, cam_from_world, focal_px, principal_point)
    if focal_known:
        jac = jac[:, :6]
    return _inverse_information(jac, sigma_px, noise_shapes)


def _joint_jac(points_a, cam_from_a, points_b, cam_from_b, focal_px, principal_point):
    ja = _jac(points_a, cam_from_a, focal_px, principal_point)
    jb = _jac(points_b, cam_from_b, focal_px, principal_point)
    return joint_jacobian(ja, jb)


def _camera(camera_model, focal_px, principal_point, coeffs):
    """(IntrinsicsModel, true Intrinsics) from the public arguments (checked)."""
    model = MODELS[check_model_name(camera_model, allow_auto=False)]
    if not (np.isfinite(focal_px) and focal_px > 0):
        raise InvalidSolverInput(f"focal_px must be positive and finite, got {focal_px}")
    try:
        co = coeffs_array(coeffs)
    except ValueError as exc:
        raise InvalidSolverInput(f"coeffs: {exc}") from None
    return model, Intrinsics(float(focal_px), as_principal_point(principal_point), co)


def _blocks_jac(blocks, poses, intr, model):
    """Jacobian of the stacked blocks at the true parameters (DegenerateGeometry when a point
    is behind its camera)."""
    _, jac, valid = stack_blocks(blocks, poses, intr, model)
    if not valid:
        raise DegenerateGeometry("points behind the camera: the bound is undefined")
    return jac


def crb_joint(points_a, cam_from_a, points_b, cam_from_b, focal_px: float, principal_point,
              sigma_px: float, camera_model: str = "pinhole", coeffs=None,
              noise_shapes=None) -> np.ndarray:
    """Cramer-Rao bound on the covariance of (w_A, t_A, w_B, t_B, f[, *model.free]): (13 + e, 13 + e).

    Parameters
    ----------
    points_a, cam_from_a, points_b, cam_from_b : (Na, 3) mm in A's frame, (4, 4), (Nb, 3) mm in B's frame, (4, 4)
        The points and the true poses.
    focal_px, principal_point, sigma_px : float px, (2,) px, float px
        The shared true focal, the principal point, the pixel noise std.
    camera_model, coeffs : str, sequence or None
        The estimated model (:data:`solver.camera_models.MODELS`) and the true lens distortion (k1, k2, p1, p2, k3;
        None: none) at ``principal_point``.
    noise_shapes : (shapes_a (Na, 2, 2), shapes_b (Nb, 2, 2)) or None
        None: isotropic (docs/solver.md, "Cramer-Rao bounds").

    Returns
    -------
    numpy.ndarray
        (13 + e, 13 + e), e the number of the model's free intrinsics besides f.

    Raises
    ------
    InvalidSolverInput
        Bad transforms, points, focal, sigma, model name, coefficients or noise shapes.
    DegenerateGeometry
        Points behind a camera, or a singular Fisher information.
    """
    shapes = _pair(noise_shapes, len(points_a), len(points_b))
    if camera_model == PINHOLE.name and coeffs is None:
        jac = _joint_jac(points_a, cam_from_a, points_b, cam_from_b, focal_px, principal_point)
        return _inverse_information(jac, sigma_px, shapes)
    model, intr = _camera(camera_model, focal_px, principal_point, coeffs)
    ca = _check_transform("cam_from_a", cam_from_a)
    cb = _check_transform("cam_from_b", cam_from_b)
    blocks = (Block(as_points("points_a", points_a, 3), np.zeros((len(points_a), 2)), 0),
              Block(as_points("points_b", points_b, 3), np.zeros((len(points_b), 2)), 1))
    jac = _blocks_jac(blocks, ((ca[:3, :3], ca[:3, 3]), (cb[:3, :3], cb[:3, 3])), intr, model)
    return _inverse_information(jac, sigma_px, shapes)


@dataclass(frozen=True)
class DockingBound:
    """Bound on d_from_b: ``covariance`` (6, 6) over POSE_NAMES, ``std`` dict name -> std;
    ``intrinsics_std``: {"focal_px", "cx", ..., "p2"} bounds on the estimated intrinsics
    (0.0 for the ones the model fixes; empty for the "independent" and "calibrated"
    problems)."""
    covariance: np.ndarray
    std: dict
    problem: str
    intrinsics_std: dict = field(default_factory=dict)


def _intrinsics_std(cov_intr: np.ndarray, model) -> dict:
    """{"focal_px", *EXTRA_NAMES}: std from the (1 + e, 1 + e) intrinsics block."""
    sd = np.sqrt(np.diag(cov_intr))
    out = {"focal_px": float(sd[0])}
    out.update({n: 0.0 for n in EXTRA_NAMES})
    out.update({n: float(v) for n, v in zip(model.free, sd[1:])})
    return out


def crb_d_from_b(points_a, cam_from_a, points_b, cam_from_b, focal_px: float, principal_point,
                 sigma_px: float, problem: str = "joint", camera_model: str = "pinhole",
                 coeffs=None, noise_shapes=None) -> DockingBound:
    """Cramer-Rao bound on (X, Y, Z mm, alpha, beta, gamma deg) of ``d_from_b`` (docs/solver.md, "Cramer-Rao bounds").

    Parameters
    ----------
    points_a, cam_from_a, points_b, cam_from_b : (Na, 3) mm in A's frame, (4, 4), (Nb, 3) mm in B's frame, (4, 4)
    focal_px, principal_point, sigma_px : float px, (2,) px, float px
    problem : {"joint", "independent", "calibrated"}
        "joint": 13 parameters, shared focal (with ``camera_model`` and the true ``coeffs``: 13 + e); "independent":
        7 + 7, a focal per section; "calibrated": 6 + 6, focal known. The last two for the pinhole only.
    camera_model, coeffs : str, sequence or None
        As :func:`crb_joint`.
    noise_shapes : (shapes_a (Na, 2, 2), shapes_b (Nb, 2, 2)) or None
        None: isotropic noise of std ``sigma_px``; else per-point noise shapes, ``sigma_px`` then the per-axis noise
        averaged over all the points ("independent" and "calibrated" average over each section's points).

    Returns
    -------
    DockingBound
        X, Y, alpha are ``std["x_mm"]``, ``std["y_mm"]``, ``std["alpha_deg"]``.

    Raises
    ------
    InvalidSolverInput
        An unknown ``problem``, a non-pinhole model with "independent" / "calibrated", or bad input.
    DegenerateGeometry
        Points behind a camera, or a singular Fisher information.
    """
    ca = _check_transform("cam_from_a", cam_from_a)
    cb = _check_transform("cam_from_b", cam_from_b)
    prop = d_from_b_jacobian(ca[:3, :3], ca[:3, 3], cb[:3, :3], cb[:3, 3])
    intr_std = {}
    if problem == "joint":
        cov13 = crb_joint(points_a, ca, points_b, cb, focal_px, principal_point, sigma_px,
                          camera_model, coeffs, noise_shapes)
        cov12 = cov13[:12, :12]
        intr_std = _intrinsics_std(cov13[12:, 12:], MODELS[camera_model])
    elif camera_model != PINHOLE.name or coeffs is not None:
        raise InvalidSolverInput(f"problem {problem!r} is for the pinhole camera only")
    elif problem in ("independent", "calibrated"):
        cov12 = _independent(points_a, ca, points_b, cb, focal_px, principal_point, sigma_px,
                             problem == "calibrated", noise_shapes)
    else:
        raise InvalidSolverInput(f"problem must be 'joint', 'independent' or 'calibrated', "
                                 f"got {problem!r}")
    cov6 = prop @ cov12 @ prop.T
    std = dict(zip(POSE_NAMES, np.sqrt(np.diag(cov6)).tolist()))
    return DockingBound(cov6, std, problem, intr_std)


def _whitener(covariance, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(Sigma, L^-1), L the Cholesky factor of a checked (n, n) covariance (InvalidSolverInput else)."""
    sigma = np.asarray(covariance, dtype=np.float64)
    if sigma.shape != (n, n) or not np.all(np.isfinite(sigma)) or not np.allclose(sigma, sigma.T):
        raise InvalidSolverInput(f"covariance: expected a finite symmetric ({n}, {n}) matrix, got shape {sigma.shape}")
    try:
        return sigma, np.linalg.inv(np.linalg.cholesky(sigma))
    except np.linalg.LinAlgError:
        raise InvalidSolverInput("covariance: not positive definite") from None


def crb_d_from_b_structured(points_a, cam_from_a, points_b, cam_from_b, focal_px: float, principal_point,
                            covariance, weight_shapes) -> tuple[DockingBound, DockingBound]:
    """The joint pinhole problem's bound on ``d_from_b`` when the centres' errors are correlated,
    and what a fit weighted as if they were not achieves under them.

    Parameters
    ----------
    points_a, cam_from_a, points_b, cam_from_b, focal_px, principal_point
        As :func:`crb_d_from_b` (mm, (4, 4), px).
    covariance : (2N, 2N) px^2, N = Na + Nb
        The centres' joint error covariance, rows interleaved (u, v) per point, A's points first.
    weight_shapes : (N, 2, 2)
        The per-point covariances the fit weights by (C_i^-1; any common scale).

    Returns
    -------
    (DockingBound, DockingBound)
        The Cramer-Rao bound under ``covariance`` ((J^T Sigma^-1 J)^-1), and the weighted fit's
        covariance under it (the sandwich A^-1 J^T W Sigma W J A^-1, A = J^T W J): at least the
        bound, equal to it when ``covariance`` is block-diagonal and proportional to the weights.

    Raises
    ------
    InvalidSolverInput
        A covariance not (2N, 2N), not symmetric positive definite, or bad points or poses.
    DegenerateGeometry
        Points behind a camera, or a singular information.
    """
    ca, cb = _check_transform("cam_from_a", cam_from_a), _check_transform("cam_from_b", cam_from_b)
    jac = _joint_jac(points_a, ca, points_b, cb, focal_px, principal_point)
    n = jac.shape[0]
    sigma, sigma_inv = _whitener(covariance, n)
    whitened = sigma_inv @ jac
    bound = inverse_spd(whitened.T @ whitened)
    weights = np.linalg.inv(as_point_covariances("weight_shapes", weight_shapes, n // 2))
    wj = np.einsum("nab,nbp->nap", weights, jac.reshape(-1, 2, jac.shape[1])).reshape(n, -1)
    a_inv = inverse_spd(jac.T @ wj)
    fit = a_inv @ wj.T @ sigma @ wj @ a_inv
    if not (np.all(np.isfinite(bound)) and np.all(np.isfinite(a_inv))):
        raise DegenerateGeometry("Fisher information is singular: the parameters are not observable from these points")
    prop = d_from_b_jacobian(ca[:3, :3], ca[:3, 3], cb[:3, :3], cb[:3, 3])
    out = []
    for cov in (bound, fit):
        cov6 = prop @ cov[:12, :12] @ prop.T
        out.append(DockingBound(cov6, dict(zip(POSE_NAMES, np.sqrt(np.diag(cov6)).tolist())), "joint"))
    return out[0], out[1]


def _independent(points_a, ca, points_b, cb, focal_px, principal_point, sigma_px, known,
                 noise_shapes) -> np.ndarray:
    """(12, 12) bound over (w_A, t_A, w_B, t_B): each section solved on its own (own focal, or
    ``known``); noise shapes normalised over both sections' points, as in the joint problem."""
    shapes = _pair(noise_shapes, len(points_a), len(points_b))
    if shapes is not None:
        shapes = shapes / _mean_axis_variance(shapes)
    cov12 = np.zeros((12, 12))
    rows = {0: slice(0, len(points_a)), 1: slice(len(points_a), None)}
    for k, (pts, cam) in enumerate(((points_a, ca), (points_b, cb))):
        jac = _jac(pts, cam, focal_px, principal_point)
        cov = _inverse_information(jac[:, :6] if known else jac, sigma_px,
                                   None if shapes is None else shapes[rows[k]], normalise=False)
        cov12[6 * k:6 * k + 6, 6 * k:6 * k + 6] = cov[:6, :6]
    return cov12


@dataclass(frozen=True)
class SequenceBound:
    """Bound for a docking run: ``frames`` (one :class:`DockingBound` per frame),
    ``intrinsics_std`` (as in DockingBound) and ``covariance`` the full bound over
    (poses..., f, *model.free)."""
    frames: tuple
    intrinsics_std: dict
    covariance: np.ndarray


def crb_sequence(points_a, cam_from_a, points_b, cams_from_b, focal_px: float,
                 principal_point, sigma_px: float, camera_model: str = "pinhole", coeffs=None,
                 share_cam_from_a: bool = True) -> SequenceBound:
    """Cramer-Rao bound for a docking run solved as :func:`solver.solve_sequence` does.

    Parameters
    ----------
    points_a, cam_from_a, points_b, cams_from_b : (Na, 3) mm, (4, 4), (Nb, 3) mm, (F, 4, 4)
        Every frame sees all of ``points_a`` and ``points_b``; ``cams_from_b`` the true camera-from-B poses.
    focal_px, principal_point, sigma_px : float px, (2,) px, float px
    camera_model, coeffs : str, sequence or None
        The shared intrinsics' model and the true ``coeffs``.
    share_cam_from_a : bool
        One fixed ``cam_from_a`` estimated once, or once per frame.

    Returns
    -------
    SequenceBound

    Raises
    ------
    InvalidSolverInput
        Bad transforms, points, focal, sigma, model name or coefficients.
    DegenerateGeometry
        Points behind a camera, or a singular Fisher information.
    """
    model, intr = _camera(camera_model, focal_px, principal_point, coeffs)
    ca = _check_transform("cam_from_a", cam_from_a)
    cbs = [_check_transform(f"cams_from_b[{k}]", c) for k, c in enumerate(cams_from_b)]
    pa, pb = as_points("points_a", points_a, 3), as_points("points_b", points_b, 3)
    za, zb = np.zeros((len(pa), 2)), np.zeros((len(pb), 2))
    pose_a = (ca[:3, :3], ca[:3, 3])
    poses, blocks, pairs = [pose_a] if share_cam_from_a else [], [], []
    for cb in cbs:
        if not share_cam_from_a:
            poses.append(pose_a)
        ia = 0 if share_cam_from_a else len(poses) - 1
        poses.append((cb[:3, :3], cb[:3, 3]))
        blocks += [Block(pa, za, ia), Block(pb, zb, len(poses) - 1)]
        pairs.append((ia, len(poses) - 1))
    cov = _inverse_information(_blocks_jac(blocks, poses, intr, model), sigma_px)
    frames = []
    for (ia, ib), cb in zip(pairs, cbs):
        prop = d_from_b_jacobian(ca[:3, :3], ca[:3, 3], cb[:3, :3], cb[:3, 3])
        idx = np.r_[6 * ia:6 * ia + 6, 6 * ib:6 * ib + 6]
        cov6 = prop @ cov[np.ix_(idx, idx)] @ prop.T
        frames.append(DockingBound(cov6, dict(zip(POSE_NAMES, np.sqrt(np.diag(cov6)).tolist())),
                                   "sequence"))
    i0 = 6 * len(poses)
    return SequenceBound(tuple(frames), _intrinsics_std(cov[i0:, i0:], model), cov)
