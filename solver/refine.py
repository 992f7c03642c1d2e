"""The one refinement: Levenberg-Marquardt of (R, t, f) on reprojection error, its Jacobian,
its covariance and the propagation to ``d_from_b``.

Layer 2 of the solver (closed form -> refinement -> estimators -> robust / identification ->
docking pipeline): imports only :mod:`solver.lie`, :mod:`solver.options`,
:mod:`solver.errors` and core. Every caller (single-section estimator, joint fit, RANSAC,
identification, Cramer-Rao bounds) uses the one Jacobian :func:`residuals_and_jacobian`, the one
LM loop (:func:`refine_pnpf`, :func:`refine_joint`) and the one covariance
:func:`covariance_from_jacobian`.

Why and how: docs/solver.md, "The refinement".
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dockfactory.core.geometry import euler_deg_from_rotation
from dockfactory.solver.camera_models import (
    PINHOLE,
    IntrinsicsModel,
    Intrinsics,
    intrinsics_jacobian,
)
from dockfactory.solver.errors import NoValidCamera
from dockfactory.solver.lie import so3_exp
from dockfactory.solver.options import RefineOptions

__all__ = ["residuals_and_jacobian", "joint_jacobian", "refine_pnpf", "refine_joint",
           "model_residuals_and_jacobian", "Block", "stack_blocks", "refine_blocks",
           "BlocksRefineResult",
           "covariance_from_jacobian", "scale_with_prior", "student_t_factor", "whitened", "inverse_spd",
           "d_from_b_jacobian", "relative_pose", "rel_focal_std", "RefineResult",
           "JointRefineResult", "DEFAULT_REFINE"]

DEFAULT_REFINE = RefineOptions()


def residuals_and_jacobian(points_3d: np.ndarray, points_2d: np.ndarray, pp: np.ndarray,
                           rotation: np.ndarray, translation: np.ndarray, focal: float,
                           want_jacobian: bool = True):
    """Residuals (2N,) = projected - observed (px), interleaved u, v, and J (2N, 7).

    ``points_3d`` (N, 3) mm, ``points_2d`` (N, 2) px, ``pp`` (2,) px, ``rotation`` (3, 3),
    ``translation`` (3,) mm, ``focal`` px. Returns (r, J, z) with z (N,) the depths; J is None
    when ``want_jacobian`` is False. ``rotation`` (N, 3, 3) and ``translation`` (N, 3) give
    every point its own pose (the columns are then each point's own pose parameters).
    """
    a = points_3d @ rotation.T if rotation.ndim == 2 else \
        np.einsum("nij,nj->ni", rotation, points_3d)
    pc = a + translation
    z = pc[:, 2]
    iz = 1.0 / z
    xy = pc[:, :2] * iz[:, None]                              # normalised (xn, yn)
    r = focal * xy + (pp - points_2d)
    if not want_jacobian:
        return r.reshape(-1), None, z
    return r.reshape(-1), _jacobian(a, xy, focal * iz), z


# the u and v rows of one point's Jacobian are the columns 0-6 and 7-13 of a (N, 14) array; a
# slice with a step picks one column of each row, so that every pair below is one numpy call
_PAIR = {k: slice(k, k + 8 + d, 7 + d) for k, d in ((0, 1), (1, -1), (2, 0), (3, 1), (4, -1),
                                                    (5, 0), (6, 0))}
_MINUS_PLUS = np.array([-1.0, 1.0])


def _jacobian(a, xy, fz):
    """J (N, 14) viewed as (2N, 7) of :func:`residuals_and_jacobian` from a = R X (N, 3), the
    normalised (xn, yn) (N, 2) and fz = f / z (N,). With du/dpc = fz (1, 0, -xn),
    dv/dpc = fz (0, 1, -yn) and du/dw = a x du/dpc (left perturbation):
    u row (-fz ay xn, fz (az + ax xn), -fz ay, fz, 0, -fz xn, xn),
    v row (-fz (ay yn + az), fz ax yn, fz ax, 0, fz, -fz yn, yn)."""
    n = a.shape[0]
    j = np.empty((n, 14))
    fzmp = fz[:, None] * _MINUS_PLUS                          # (-fz, fz)
    np.multiply(a[:, 1::-1], fzmp, out=j[:, _PAIR[2]])        # (-fz ay, fz ax)
    np.multiply(j[:, _PAIR[2]], xy, out=j[:, _PAIR[0]])      # (-fz ay xn, fz ax yn)
    s = a[:, :2] * xy
    s += a[:, 2:3]                                            # (az + ax xn, ay yn + az)
    cols = j[:, _PAIR[1]]                                     # (u: w_y, v: w_x)
    np.multiply(s, fzmp, out=cols)
    np.negative(cols, out=cols)
    j[:, _PAIR[3]] = fz[:, None]
    j[:, _PAIR[4]] = 0.0
    np.multiply(xy, fzmp[:, :1], out=j[:, _PAIR[5]])         # (-fz xn, -fz yn)
    j[:, _PAIR[6]] = xy
    return j.reshape(2 * n, 7)


def model_residuals_and_jacobian(points_3d: np.ndarray, points_2d: np.ndarray,
                                 intr: Intrinsics, model: IntrinsicsModel, rotation: np.ndarray,
                                 translation: np.ndarray, want_jacobian: bool = True):
    """Residuals (2N,) px and J (2N, 7 + e) over (w, t, f, *model.free) for a camera with
    intrinsics ``intr`` (:class:`solver.camera_models.Intrinsics`); other arguments as in
    :func:`residuals_and_jacobian`, which this is (same numbers) for the pinhole model without
    distortion. Returns (r, J or None, z (N,) depths)."""
    if model.n_extra == 0 and not intr.distorted:
        return residuals_and_jacobian(points_3d, points_2d, intr.principal_point, rotation,
                                      translation, intr.focal_px, want_jacobian)
    # the pinhole Jacobian at f = 1, pp = 0: normalised coordinates and d(xn, yn)/d(w, t)
    n = points_3d.shape[0]
    rn, jn, z = residuals_and_jacobian(points_3d, np.zeros((n, 2)), np.zeros(2), rotation,
                                       translation, 1.0, want_jacobian)
    xn = rn.reshape(n, 2)
    uv, j_xy, j_int = intrinsics_jacobian(xn, intr, model)
    r = (uv - points_2d).reshape(-1)
    if not want_jacobian:
        return r, None, z
    j_pose = np.einsum("nij,njk->nik", j_xy, jn.reshape(n, 2, 7)[:, :, :6])
    return r, np.concatenate([j_pose, j_int], axis=2).reshape(2 * n, 6 + j_int.shape[2]), z


def joint_jacobian(jac_a: np.ndarray, jac_b: np.ndarray) -> np.ndarray:
    """(2Na + 2Nb, 13) Jacobian over (w_A, t_A, w_B, t_B, f) from the two sections' (2N, 7)
    Jacobians over (w, t, f): the focal column is shared."""
    na = jac_a.shape[0]
    jac = np.zeros((na + jac_b.shape[0], 13))
    jac[:na, :6] = jac_a[:, :6]
    jac[:na, 12] = jac_a[:, 6]
    jac[na:, 6:12] = jac_b[:, :6]
    jac[na:, 12] = jac_b[:, 6]
    return jac


T_FACTOR_CAP = 3.0   # dof / (dof - 2) at dof = 3; below, a Student t's variance is infinite
NOISE_PRIOR_DOF = 2.0   # pseudo degrees of freedom of the known noise (:func:`scale_with_prior`)


def covariance_from_jacobian(jac: np.ndarray, residuals: np.ndarray, sigma_px: float | None,
                             floor_px: float | None = None, point_cov: np.ndarray | None = None,
                             prior_px: float | None = None):
    """(cov (p, p), sigma used): sigma^2 (J^T J)^-1 with ``sigma_px`` when given.

    Without it sigma is estimated from the residuals, s^2 = r.r / dof (dof = m - p), and the
    covariance is s^2 dof / (dof - 2) (J^T J)^-1 (at most ``T_FACTOR_CAP`` s^2): the error over
    a std from an estimated sigma is Student-t with dof degrees of freedom, whose variance is
    dof / (dof - 2), so this makes z = error / std have RMS 1 (a docking frame has dof 5-15: the
    std of X grows 1.08-1.29x). ``floor_px``: the centre noise measured on labelled data for
    this detector; the estimate is never below it (the residuals of a frame underrate noise that
    is correlated between markers, which moves the pose without showing in them).

    ``point_cov`` (N, 2, 2), rows of ``jac`` = 2N interleaved (u, v): the relative shape T_i of
    each point's noise covariance (e.g. :func:`solver.disc_noise.noise_shapes`; None: every
    T_i = I, the isotropic case above, same numbers). The noise of point i is then k^2 T_i and
    the covariance of the unweighted least-squares estimate is the sandwich
    k^2 (J^T J)^-1 J^T T J (J^T J)^-1. k^2 is estimated without bias as r.r / tr((I - P) T)
    (P = J (J^T J)^-1 J^T, so that tr((I - P) T) = m - p when T = I; Student-t factor as above
    with dof = m - p); ``sigma_px`` and ``floor_px`` are per-axis noise averaged over the points,
    k^2 mean(tr T_i) / 2, and the sigma returned is that average (px). ``prior_px`` (same units):
    the noise the camera is known to have, which an estimated scale is pulled up toward
    (:func:`scale_with_prior`)."""
    m, p = jac.shape
    inv = inverse_spd(jac.T @ jac)
    mean_var, dof_eff, meat = 1.0, float(m - p), None
    if point_cov is not None and np.all(np.isfinite(inv)):
        t = np.asarray(point_cov, dtype=np.float64)
        jr = jac.reshape(-1, 2, p)
        meat = np.einsum("nap,nab,nbq->pq", jr, t, jr)
        mean_var = float(np.trace(t, axis1=1, axis2=2).mean()) / 2.0
        dof_eff = 2.0 * t.shape[0] * mean_var - float(np.sum(inv * meat))    # tr((I - P) T)
    if sigma_px is not None:
        sigma2 = scale2 = float(sigma_px) ** 2 / mean_var
    else:
        dof = m - p
        sigma2 = float(residuals @ residuals) / dof_eff if dof > 0 else float("inf")
        sigma2, scale2 = scale_with_prior(sigma2, dof, None if prior_px is None else prior_px ** 2 / mean_var)
        if floor_px is not None:
            floor2 = floor_px ** 2 / mean_var
            sigma2, scale2 = max(sigma2, floor2), max(scale2, floor2)
    sigma_used = float(np.sqrt(sigma2 * mean_var))
    if meat is None:
        return scale2 * inv, sigma_used
    return scale2 * (inv @ meat @ inv), sigma_used


def scale_with_prior(scale2: float, dof: float, prior2: float | None) -> tuple[float, float]:
    """(noise variance, its covariance factor): ``scale2`` estimated from residuals with ``dof``
    degrees of freedom, pulled up toward the variance ``prior2`` the camera is known to have (its
    noise card's core, in the same units; None: none) as a conjugate prior of NOISE_PRIOR_DOF
    pseudo degrees of freedom: (dof s^2 + nu0 s0^2) / (dof + nu0) with the Student-t factor of dof
    + nu0, never below ``scale2`` with its own factor.

    Why: a fit left with few degrees of freedom (centres left out by the goodness-of-fit gate, a
    frame of few markers) can show residuals far below any camera's noise, and its covariance
    then claims a precision no camera has (measured: a Bayer + JPEG frame at 0.004 px against the
    class's 0.15 px, Z 26 of its std off). The prior is one-sided: residuals above it (gross
    errors, a worse camera) keep their own scale."""
    own = scale2 * student_t_factor(dof)
    if prior2 is None or not prior2 > 0 or not np.isfinite(scale2):
        return scale2, own
    post = (max(dof, 0.0) * scale2 + NOISE_PRIOR_DOF * prior2) / (max(dof, 0.0) + NOISE_PRIOR_DOF)
    if post <= scale2:
        return scale2, own
    return post, max(own, post * student_t_factor(max(dof, 0.0) + NOISE_PRIOR_DOF))


def student_t_factor(dof: float) -> float:
    """dof / (dof - 2), the variance of a Student t with ``dof`` degrees of freedom, capped at
    ``T_FACTOR_CAP`` (the factor an estimated sigma's covariance takes)."""
    return min(dof / (dof - 2.0), T_FACTOR_CAP) if dof > 2 else T_FACTOR_CAP


def inverse_spd(a: np.ndarray) -> np.ndarray:
    """Inverse of a symmetric positive (semi-)definite matrix (p, p) by eigendecomposition.

    The matrix is first scaled to unit diagonal; if that has an eigenvalue below 1e-15 x the
    largest, the parameters are not identifiable and every entry is infinite. (Used
    instead of ``np.linalg.inv``, whose multi-threaded BLAS path costs milliseconds on a
    loaded machine for a 7 x 7 matrix.)
    """
    d = a.diagonal()
    if not np.all(d > 0.0):
        return np.full(a.shape, np.inf)
    s = 1.0 / np.sqrt(d)                         # Jacobi scaling: units do not matter
    try:
        lam, vec = np.linalg.eigh(a * s[:, None] * s[None, :])
    except np.linalg.LinAlgError:
        return np.full(a.shape, np.inf)
    if not lam[0] > 1e-15 * lam[-1]:
        return np.full(a.shape, np.inf)
    return ((vec / lam) @ vec.T) * s[:, None] * s[None, :]


def rel_focal_std(cov: np.ndarray, focal: float, index: int = -1) -> float:
    """Standard deviation of the focal (parameter ``index`` of ``cov`` (p, p), by default the
    last) over ``focal``; inf when the variance is not finite and non-negative."""
    v = cov[index, index]
    return float(np.sqrt(v)) / focal if np.isfinite(v) and v >= 0 else np.inf


@dataclass(frozen=True)
class RefineResult:
    """One section: R (3, 3), t (3,) mm, f px, residuals (2N,) px, J (2N, 7), iterations."""
    rotation: np.ndarray
    translation: np.ndarray
    focal_px: float
    residuals: np.ndarray
    jacobian: np.ndarray
    iterations: int
    converged: bool

    @property
    def rmse_px(self) -> float:
        r = self.residuals
        return float(np.sqrt(2.0 * (r @ r) / r.size))


def _lm(evaluate, update, state, options: RefineOptions):
    """Generic Levenberg-Marquardt (Marquardt scaling) on a residual function.

    ``evaluate(state, want_jacobian) -> (res, jac or None, valid)``; ``update(state, step) ->
    state`` (None when the step leaves the valid region). Stopping rules: see
    :class:`RefineOptions`. Trial steps are judged on their residuals alone; the Jacobian is
    evaluated at the steps taken. Returns (state, res, jac, iterations, converged).
    """
    res, jac, valid = evaluate(state, True)
    if not valid:
        raise NoValidCamera("refinement started from an invalid camera (points behind it)")
    cost = float(np.dot(res, res))
    lam = options.initial_damping
    it = 0
    converged = False
    for it in range(1, options.max_iterations + 1):
        jtj = np.dot(jac.T, jac)
        g = np.dot(jac.T, res)
        d = jtj.diagonal().copy()
        d[d <= 0.0] = 1.0
        step, trial, lam = _damped_step(evaluate, update, state, jtj, g, d, cost, lam, options)
        if trial is None:
            converged = True   # no damped step decreases the cost: a minimum to precision
            break
        new_state, res_n, cost_n = trial
        tiny = float(np.max(np.abs(step) * np.sqrt(d))) < options.step_tol_px
        stagnant = cost - cost_n <= options.cost_rel_tol * cost
        state, res, cost = new_state, res_n, cost_n
        jac = evaluate(state, True)[1]
        lam = max(lam * 0.1, options.min_damping)
        if tiny or stagnant or cost < options.exact_cost_per_residual * res.size:
            converged = True
            break
    if not np.isfinite(cost):
        raise NoValidCamera("refinement diverged (non-finite cost)")
    return state, res, jac, it, converged


def _damped_step(evaluate, update, state, jtj, g, d, cost, lam, options: RefineOptions):
    """One LM iteration's search over the damping: (step, (state, res, cost) or None,
    damping). None when the model promises no decrease or no damped step decreases the cost."""
    for _ in range(options.damping_tries):
        a = jtj.copy()
        a.reshape(-1)[::a.shape[0] + 1] += lam * d
        try:
            step = np.linalg.solve(a, -g)
        except np.linalg.LinAlgError:
            lam *= 10.0
            continue
        predicted = -float(np.dot(g, step)) - 0.5 * float(np.dot(step, np.dot(jtj, step)))
        if predicted <= options.predicted_rel_tol * cost:
            break                 # the model promises nothing: at a minimum to precision
        new_state = update(state, step)
        if new_state is not None:
            res_n, _, valid_n = evaluate(new_state, False)
            cost_n = float(np.dot(res_n, res_n))
            if valid_n and cost_n <= cost:
                return step, (new_state, res_n, cost_n), lam
        lam *= 10.0
    return None, None, lam


def refine_pnpf(points_3d, points_2d, pp, rotation, translation, focal,
                options: RefineOptions = DEFAULT_REFINE, *, fix_focal: bool = False
                ) -> RefineResult:
    """Levenberg-Marquardt on reprojection error over (R, t, f) for one section.

    Inputs as in :func:`residuals_and_jacobian` (already validated); ``options`` the LM budget
    and stopping rules. ``fix_focal`` keeps f (calibrated refinement over (R, t); the returned
    Jacobian still has 7 columns). Raises NoValidCamera if the start is not a valid camera or
    the cost diverges.
    """
    def evaluate(st, want_jacobian):
        res, jac, z = residuals_and_jacobian(points_3d, points_2d, pp, st[0], st[1], st[2],
                                             want_jacobian)
        if fix_focal and jac is not None:
            jac = jac[:, :6]
        return res, jac, bool(z.min() > 0.0) and np.isfinite(res).all()

    def update(st, step):
        if fix_focal:
            return np.dot(so3_exp(step[:3]), st[0]), st[1] + step[3:6], st[2]
        f_new = st[2] + step[6]
        if not f_new > 0.0:
            return None
        return np.dot(so3_exp(step[:3]), st[0]), st[1] + step[3:6], f_new

    state = (np.array(rotation, dtype=np.float64), np.array(translation, dtype=np.float64),
             float(focal))
    state, res, jac, it, conv = _lm(evaluate, update, state, options)
    if fix_focal:
        jac = residuals_and_jacobian(points_3d, points_2d, pp, *state)[1]
    return RefineResult(state[0], state[1], float(state[2]), res, jac, it, conv)


@dataclass(frozen=True)
class JointRefineResult:
    """Two sections, shared focal: rotations/translations of cam_from_a and cam_from_b."""
    rotation_a: np.ndarray
    translation_a: np.ndarray
    rotation_b: np.ndarray
    translation_b: np.ndarray
    focal_px: float
    residuals_a: np.ndarray
    residuals_b: np.ndarray
    jacobian: np.ndarray          # (2Na + 2Nb, 13)
    iterations: int
    converged: bool


@dataclass(frozen=True)
class Block:
    """One residual block: ``points_3d`` (n, 3) mm in a section's frame, their pixels
    ``points_2d`` (n, 2), seen from pose number ``pose`` (camera from that section).
    ``sqrt_info`` (n, 2, 2) or None: each point's residual (and its Jacobian rows) is multiplied
    by its matrix (a weighted, whitened least squares: W_i^(1/2) for information W_i)."""

    points_3d: np.ndarray
    points_2d: np.ndarray
    pose: int
    sqrt_info: np.ndarray | None = None


def stack_blocks(blocks, poses, intr: Intrinsics, model: IntrinsicsModel,
                 want_jacobian: bool = True):
    """Residuals (M,) of every block in order and the Jacobian (M, 6 P + 1 + e) over
    (w_0, t_0, ..., f, *model.free), ``poses`` a sequence of P (R (3, 3), t (3,)) pairs.
    Returns (res, jac or None, valid): valid when every point is in front of its camera and
    every residual is finite. Runs (more than two blocks) and camera models beyond the pinhole
    are evaluated in one batch (:func:`_stack_batched`); the two-block pinhole case block by
    block."""
    if len(blocks) > 2 or model.n_extra or intr.distorted:
        return _stack_batched(blocks, poses, intr, model, want_jacobian)
    n_pose = 6 * len(poses)
    m = sum(2 * b.points_3d.shape[0] for b in blocks)
    jac = np.zeros((m, n_pose + model.n_intrinsics)) if want_jacobian else None
    parts, row, valid = [], 0, True
    pp, focal = intr.principal_point, intr.focal_px
    for b in blocks:
        rot, t = poses[b.pose]
        r, j, z = residuals_and_jacobian(b.points_3d, b.points_2d, pp, rot, t, focal,
                                         want_jacobian)
        if b.sqrt_info is not None:
            r, j = whitened(b.sqrt_info, r, j)
        parts.append(r)
        valid = valid and bool(z.min() > 0.0)
        if want_jacobian:
            jac[row:row + r.size, 6 * b.pose:6 * b.pose + 6] = j[:, :6]
            jac[row:row + r.size, n_pose:] = j[:, 6:]
        row += r.size
    res = np.concatenate(parts)
    return res, jac, valid and bool(np.isfinite(res).all())


def whitened(sqrt_info: np.ndarray, r: np.ndarray, j: np.ndarray | None):
    """(r, j) of n points (2n interleaved rows) with each point's rows multiplied by its
    ``sqrt_info`` (n, 2, 2)."""
    n = sqrt_info.shape[0]
    r = np.einsum("nab,nb->na", sqrt_info, r.reshape(n, 2)).reshape(-1)
    if j is not None:
        j = np.einsum("nab,nbk->nak", sqrt_info, j.reshape(n, 2, -1)).reshape(2 * n, -1)
    return r, j


def _stack_batched(blocks, poses, intr: Intrinsics, model: IntrinsicsModel, want_jacobian: bool):
    """:func:`stack_blocks` with every point's pose gathered first: one evaluation of the
    Jacobian for all blocks, its pose columns scattered to each point's pose."""
    pose_of = np.concatenate([np.full(b.points_3d.shape[0], b.pose) for b in blocks])
    rots = np.stack([np.asarray(rot) for rot, _ in poses])[pose_of]
    ts = np.stack([np.asarray(t) for _, t in poses])[pose_of]
    p3 = np.concatenate([b.points_3d for b in blocks])
    p2 = np.concatenate([b.points_2d for b in blocks])
    res, j, z = model_residuals_and_jacobian(p3, p2, intr, model, rots, ts, want_jacobian)
    if any(b.sqrt_info is not None for b in blocks):
        info = np.concatenate([np.broadcast_to(np.eye(2), (b.points_3d.shape[0], 2, 2))
                               if b.sqrt_info is None else b.sqrt_info for b in blocks])
        res, j = whitened(info, res, j)
    valid = bool(z.min() > 0.0) and bool(np.isfinite(res).all())
    if not want_jacobian:
        return res, None, valid
    n, n_pose = p3.shape[0], 6 * len(poses)
    jac = np.zeros((2 * n, n_pose + model.n_intrinsics))
    rows = np.arange(2 * n).reshape(n, 2, 1)
    cols = (6 * pose_of)[:, None, None] + np.arange(6)[None, None, :]
    jac[rows, cols] = j[:, :6].reshape(n, 2, 6)
    jac[:, n_pose:] = j[:, 6:]
    return res, jac, valid


@dataclass(frozen=True)
class BlocksRefineResult:
    """Refined ``poses`` (tuple of (R, t)), ``intrinsics``, ``model``, residuals (M,) px, J
    (M, 6 P + 1 + e), iterations, converged."""

    poses: tuple
    intrinsics: Intrinsics
    model: IntrinsicsModel
    residuals: np.ndarray
    jacobian: np.ndarray
    iterations: int
    converged: bool

    @property
    def cost(self) -> float:
        return float(self.residuals @ self.residuals)

    @property
    def focal_index(self) -> int:
        """Column of the focal length in the Jacobian and covariance."""
        return 6 * len(self.poses)


def refine_blocks(blocks, poses, intr: Intrinsics, model: IntrinsicsModel = PINHOLE,
                  options: RefineOptions = DEFAULT_REFINE) -> BlocksRefineResult:
    """LM over (w_0, t_0, ..., w_{P-1}, t_{P-1}, f, *model.free): P poses (left perturbations
    of their rotations), one camera shared by every block (:class:`Block`).

    ``poses``: the start, P pairs (R (3, 3), t (3,) mm); ``intr``: the start intrinsics (the
    model's fixed ones keep their values). Raises NoValidCamera as :func:`refine_pnpf`.
    """
    n_pose = 6 * len(poses)

    def evaluate(st, want_jacobian):
        return stack_blocks(blocks, st[0], st[1], model, want_jacobian)

    def update(st, step):
        intr_new = st[1].stepped(model, step[n_pose], step[n_pose + 1:])
        if intr_new is None:
            return None
        return tuple((np.dot(so3_exp(step[6 * k:6 * k + 3]), rot),
                      t + step[6 * k + 3:6 * k + 6])
                     for k, (rot, t) in enumerate(st[0])), intr_new

    state = (tuple((np.array(rot, dtype=np.float64), np.array(t, dtype=np.float64))
                   for rot, t in poses), intr)
    state, res, jac, it, conv = _lm(evaluate, update, state, options)
    return BlocksRefineResult(state[0], state[1], model, res, jac, it, conv)


def refine_joint(points_a, uv_a, points_b, uv_b, pp, rot_a, t_a, rot_b, t_b, focal,
                 options: RefineOptions = DEFAULT_REFINE) -> JointRefineResult:
    """LM over (w_A, t_A, w_B, t_B, f): both sections in one image, one shared focal length
    (the two-block pinhole case of :func:`refine_blocks`).

    ``points_a`` (Na, 3) mm in A's frame with pixels ``uv_a`` (Na, 2); same for B; the initial
    cam_from_a = (rot_a, t_a), cam_from_b = (rot_b, t_b), ``focal`` px.
    """
    na = 2 * points_a.shape[0]
    blocks = (Block(points_a, uv_a, 0), Block(points_b, uv_b, 1))
    br = refine_blocks(blocks, ((rot_a, t_a), (rot_b, t_b)),
                       Intrinsics.pinhole(float(focal), pp), PINHOLE, options)
    (ra, ta), (rb, tb) = br.poses
    res = br.residuals
    return JointRefineResult(ra, ta, rb, tb, float(br.intrinsics.focal_px), res[:na], res[na:],
                             br.jacobian, br.iterations, br.converged)


def relative_pose(rot_a, t_a, rot_b, t_b) -> np.ndarray:
    """``d_from_b`` (4, 4) = inv(cam_from_a) @ cam_from_b."""
    out = np.eye(4)
    out[:3, :3] = rot_a.T @ rot_b
    out[:3, 3] = rot_a.T @ (t_b - t_a)
    return out


def _inv3(m) -> np.ndarray:
    """Inverse of a 3 x 3 matrix by its adjugate (no BLAS call)."""
    (a, b, c), (d, e, f), (g, h, i) = np.asarray(m, dtype=np.float64).tolist()
    co = [[e * i - f * h, c * h - b * i, b * f - c * e],
          [f * g - d * i, a * i - c * g, c * d - a * f],
          [d * h - e * g, b * g - a * h, a * e - b * d]]
    det = a * co[0][0] + b * co[1][0] + c * co[2][0]
    return np.array(co) / det


def _skew(v):
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def d_from_b_jacobian(rot_a, t_a, rot_b, t_b) -> np.ndarray:
    """d(X, Y, Z [mm], alpha, beta, gamma [deg]) / d(w_A, t_A, w_B, t_B): (6, 12).

    With left perturbations R <- exp([w]x) R of both camera-frame rotations:
    T = R_A^T (t_B - t_A) gives dT/dw_A = R_A^T [t_B - t_A]x, dT/dt_A = -R_A^T, dT/dt_B = R_A^T;
    R_rel = R_A^T R_B moves by the left rotation vector R_A^T (w_B - w_A), and for
    R = Rz(a) Ry(b) Rx(g) that vector is E (da, db, dg) with E = [e_z, Rz(a) e_y, Rz(a) Ry(b) e_x].
    """
    ra_t = rot_a.T
    jac = np.zeros((6, 12))
    jac[:3, 0:3] = ra_t @ _skew(t_b - t_a)
    jac[:3, 3:6] = -ra_t
    jac[:3, 9:12] = ra_t
    alpha, beta, _ = np.radians(euler_deg_from_rotation(ra_t @ rot_b))
    ca, sa, cb, sb = np.cos(alpha), np.sin(alpha), np.cos(beta), np.sin(beta)
    e = np.array([[0.0, -sa, ca * cb], [0.0, ca, sa * cb], [1.0, 0.0, -sb]])
    de = np.degrees(_inv3(e) @ ra_t)               # d(angles)/d(w_B) ; d/d(w_A) = -that
    jac[3:, 6:9] = de
    jac[3:, 0:3] = -de
    return jac
