"""Model error: what the intrinsics a camera model does not estimate do to its pose, and whether
the residuals show them.

Why and how: docs/solver.md, "Model error".
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dockfactory.solver.camera_models import EXTRA_NAMES, IntrinsicsModel, Intrinsics
from dockfactory.solver.options import LensPrior
from dockfactory.solver.refine import inverse_spd, stack_blocks, whitened
from dockfactory.solver.stats import chi2_logsf, f_logsf

__all__ = ["ModelCheck", "model_check", "marker_bias_covariance", "persistent_bias_covariance",
           "spatial_bias_factor", "ALL_EXTRAS"]

ALL_EXTRAS = IntrinsicsModel("all", EXTRA_NAMES)
BIAS_ALPHA = 0.05   # a run's persistent bias is counted only when the residuals show it at this level
BIAS_LENGTH = 0.19   # correlation length of a run's persistent centre errors, in image diagonals
GRID_STEP = 0.25     # spacing of the bias field's inducing points, in correlation lengths


@dataclass(frozen=True)
class ModelCheck:
    """The model error of one solve: ``tested`` the unestimated intrinsics the misfit test
    covers (those the data determine), ``statistic`` (chi-square or F), ``dof``, ``log_p``
    (natural log of its p-value; 0.0 when nothing was testable), ``explains`` (False: the
    assumed model does not explain the residuals at the prior's ``misfit_alpha``), ``added``
    (p, p) the covariance added to the estimator's parameters (zeros unless marginalised),
    ``theta`` {name: posterior mean} of the unestimated intrinsics' departure, ``known_log_p``
    the log p-value of the same score test with the noise a caller knows (chi-square; None when
    no known noise was given: :func:`model_check`'s ``known_k2``); ``pp_offset_ncp`` the test's
    power against a principal point off by the prior's half-range (:func:`pp_offset_ncp`; None when
    the model estimates the principal point or the prior gives it no range)."""

    model: str
    tested: tuple
    statistic: float
    dof: int
    log_p: float
    explains: bool
    added: np.ndarray
    theta: dict
    known_log_p: float | None = None
    pp_offset_ncp: float | None = None

    @property
    def p_value(self) -> float:
        return math.exp(self.log_p)

    def warning(self) -> str:
        """One sentence for a user when the model does not explain the data, else ""."""
        if self.explains:
            return ""
        return (f"camera model {self.model} does not explain the residuals: the unestimated "
                f"{', '.join(self.tested)} would (score test p {self.p_value:.2g})")


def _split_columns(n_params: int, model: IntrinsicsModel):
    """(estimated columns, unestimated columns, unestimated names) of the ALL_EXTRAS Jacobian
    over (poses, f, *EXTRA_NAMES) for a fit with ``n_params`` = 6 P + 1 + e parameters."""
    n_pose_f = n_params - model.n_extra
    est = list(range(n_pose_f)) + [n_pose_f + EXTRA_NAMES.index(n) for n in model.free]
    names = tuple(n for n in EXTRA_NAMES if n not in model.free)
    return est, [n_pose_f + EXTRA_NAMES.index(n) for n in names], names


def _score_test(f_info, score, half, sigma_known: bool, dof_res: int, within_prior: bool = False):
    """(statistic, dof, log_p, tested mask) of the score test over the directions of the
    prior-scaled information ``f_info`` with eigenvalue above 1 (see the module docstring);
    ``within_prior``: the null is a departure drawn from the prior, not none (the score's
    covariance F + F P F: eigenvalues lam (1 + lam) of the prior-scaled one)."""
    d = half / math.sqrt(3.0)
    lam, vec = np.linalg.eigh(f_info * d[:, None] * d[None, :])
    keep = lam > 1.0
    q = int(keep.sum())
    if q == 0:
        return 0.0, 0, 0.0, np.zeros(len(half), dtype=bool)
    proj = vec[:, keep].T @ (d * score)
    t = float(np.sum(proj ** 2 / (lam[keep] * (1.0 + lam[keep]) if within_prior else lam[keep])))
    tested = np.sum(vec[:, keep] ** 2 * lam[keep], axis=1) > 1.0 / len(half)
    if sigma_known or dof_res <= 0:
        return t, q, chi2_logsf(t, q), tested
    return t / q, q, f_logsf(t / q, q, dof_res), tested


def pp_offset_ncp(f_info, half, names) -> float | None:
    """The smallest noncentrality, over directions in the image plane, of the score test of
    :func:`_score_test` against a principal point off by the prior's half-range ``half`` of cx and
    cy: theta~^T (V L V^T) theta~ over the tested directions (prior-scaled eigenvalues L above 1,
    eigenvectors V), theta~ = sqrt(3) u the offset in prior-scaled units. Why: the number of
    tested directions says how many combinations of the unestimated intrinsics the data
    determine, not whether a shifted principal point (a cropped image) would show in them; this
    does. None when cx or cy is estimated or has no range; 0 when nothing is tested."""
    if "cx" not in names or "cy" not in names:
        return None
    idx = [names.index("cx"), names.index("cy")]
    if not np.all(half[idx] > 0):
        return None
    d = half / math.sqrt(3.0)
    lam, vec = np.linalg.eigh(f_info * d[:, None] * d[None, :])
    keep = lam > 1.0
    if not np.any(keep):
        return 0.0
    tested = (vec[:, keep] * lam[keep]) @ vec[:, keep].T
    return float(3.0 * np.linalg.eigvalsh(tested[np.ix_(idx, idx)])[0])


def _posterior(f_info, score, half, g, marginalise: bool):
    """(mu, added): the unestimated intrinsics' posterior mean departure under the lens prior
    (uniform over +-``half``, as a Gaussian of its variance) and the covariance that departure adds
    to the estimated parameters through ``g`` (d estimate / d theta); zeros unless ``marginalise``."""
    var = half ** 2 / 3.0
    on = var > 0
    post = np.zeros((len(half), len(half)))
    if np.any(on):
        post[np.ix_(on, on)] = inverse_spd(np.diag(1.0 / var[on]) + f_info[np.ix_(on, on)])
    mu = -post @ score
    added = g @ (post + np.outer(mu, mu)) @ g.T if marginalise else np.zeros((g.shape[0],) * 2)
    return mu, added


def model_check(blocks, poses, intr: Intrinsics, model: IntrinsicsModel, n_params: int, sqrt_w, k2: float,
                lens: LensPrior, principal_point, sigma_known: bool, known_k2: float | None = None) -> ModelCheck:
    """The :class:`ModelCheck` of a fit of ``blocks`` (:class:`solver.refine.Block`, unweighted)
    at ``poses`` and ``intr`` with ``model`` (``n_params`` = 6 P + 1 + e estimated parameters).

    ``sqrt_w`` (n, 2, 2) or None: each point's whitening as the estimator weighted it (its
    noise is taken as k^2 W^-1); ``k2`` the noise scale of the whitened residuals (px^2 when
    unweighted); ``lens`` the plausible ranges; ``principal_point`` (2,) px the assumed one
    (the image width for the principal point's range); ``sigma_known``: the noise was given,
    not estimated from these residuals; ``known_k2`` (None: not tested) the noise scale of the
    whitened residuals a known noise implies, against which the score test is made again
    (``known_log_p``; with ``lens.marginalise`` against a departure drawn from the prior, not
    none). ``added`` is zeros when ``lens.marginalise`` is False or
    nothing can be computed (a point behind the camera, a singular information).

    The residuals are taken orthogonal to the estimated parameters' columns before the score:
    the fit's estimate is not exactly the whitened least squares this linearises (robust
    weights, eccentricity-corrected points, a stop short of convergence), and a residual with a
    component along J_e makes the score test's statistic unbounded by the residuals' own size
    (on rendered frames of an ideal pinhole camera it flagged a quarter to three quarters of
    them at p < 1e-3: bench/results/marker_sampling/README.md, "The camera-model check")."""
    est, unest, names = _split_columns(n_params, model)
    zero = ModelCheck(model.name, (), 0.0, 0, 0.0, True, np.zeros((n_params, n_params)), {})
    half = np.array([lens.half_range(n, principal_point) for n in names])
    res, jac, valid = stack_blocks(blocks, poses, intr, ALL_EXTRAS)
    if not names or not valid or not (k2 > 0 and math.isfinite(k2)):
        return zero
    if sqrt_w is not None:
        res, jac = whitened(sqrt_w, res, jac)
    je, ju = jac[:, est], jac[:, unest]
    a_inv = inverse_spd(je.T @ je)
    if not np.all(np.isfinite(a_inv)):
        return zero
    g = a_inv @ (je.T @ ju)                               # d estimate / d theta
    f_info = (ju.T @ ju - (ju.T @ je) @ g) / k2
    res = res - je @ (a_inv @ (je.T @ res))               # orthogonal to J_e (see above)
    score = ju.T @ res / k2
    stat, q, log_p, tested = _score_test(f_info, score, half, sigma_known, res.size - n_params)
    mu, added = _posterior(f_info, score, half, g, lens.marginalise)
    explains = not log_p <= math.log(lens.misfit_alpha)
    known = None if known_k2 is None else _score_test(f_info * (k2 / known_k2), score * (k2 / known_k2), half,
                                                      True, 0, lens.marginalise)[2]
    return ModelCheck(model.name, tuple(n for n, t in zip(names, tested) if t), float(stat), q,
                      float(log_p), explains, added, dict(zip(names, mu.tolist())), known,
                      pp_offset_ncp(f_info, half, names))


def _marker_indicator(marker_of_point: np.ndarray) -> np.ndarray:
    """S (2n, 2K): 1 where row (point i, axis a) belongs to (marker, axis a); markers unseen
    dropped."""
    n = marker_of_point.size
    s = np.zeros((2 * n, 2 * (int(marker_of_point.max()) + 1)))
    s[np.arange(2 * n), 2 * np.repeat(marker_of_point, 2) + np.tile([0, 1], n)] = 1.0
    return s[:, s.any(axis=0)]


def _noise_and_bias(moments: np.ndarray, rr: float, sr: float, tr_c2: float, known: float | None,
                    dof: int):
    """(sigma^2, tau^2) from the moments (2, 2) of :func:`persistent_bias_covariance`, r^T r =
    ``rr``, |S^T r|^2 = ``sr`` and tr(C^2) = ``tr_c2`` (C = S^T M T M S); ``known`` sigma^2 or
    None; ``dof`` the residual degrees of freedom. tau^2 is 0 (and sigma^2 the residuals' alone)
    unless the bias is significant at BIAS_ALPHA: without a bias, |S^T r|^2 / sigma^2 is a sum
    of chi-squares weighted by C's eigenvalues, taken as g chi2_h (Satterthwaite: g = tr C^2 /
    tr C, h = (tr C)^2 / tr C^2), against an F(h, dof) when sigma^2 is estimated."""
    if known is not None:
        sigma2, tau2 = known, (sr - known * moments[1, 0]) / moments[1, 1]
    else:
        (a, b), (c, d) = moments                 # two moment equations in two unknowns (Cramer's rule)
        det = a * d - b * c
        sigma2, tau2 = float((rr * d - b * sr) / det), float((a * sr - c * rr) / det)
    null = known if known is not None else rr / moments[0, 0]
    g, h = tr_c2 / moments[1, 0], moments[1, 0] ** 2 / tr_c2
    stat = sr / (null * g)
    log_p = chi2_logsf(stat, h) if known is not None or dof < 1 else f_logsf(stat / h, h, dof)
    if tau2 > 0 and log_p < math.log(BIAS_ALPHA):
        return max(float(sigma2), 0.0), float(tau2)     # the bias may explain all of the residuals
    return null, 0.0


def marker_bias_covariance(jac: np.ndarray, res: np.ndarray, marker_of_point: np.ndarray,
                           sigma_px: float | None, shapes: np.ndarray | None = None,
                           floor_px: float | None = None):
    """:func:`persistent_bias_covariance` with a bias of each marker that persists across the
    frames it is seen in, independent between markers (``marker_of_point`` (n,) int: which
    marker each point is): the indicator S (m, 2K) of each row's marker and axis as the factor."""
    return persistent_bias_covariance(jac, res, _marker_indicator(marker_of_point), sigma_px, shapes, floor_px)


def spatial_bias_factor(points_px: np.ndarray, groups: np.ndarray, length_px: float, extent_px) -> np.ndarray:
    """F (2n, 2q) with F F^T the correlation of a bias field over the image: points i, j of one
    group (a section) correlated exp(-d_ij / ``length_px``) (d their image distance, px), per
    axis alike, none across groups. ``points_px`` (n, 2), ``groups`` (n,) labels, ``extent_px``
    (W, H) the image's size.

    Up to as many points as the image holds inducing points (a grid spaced GRID_STEP correlation
    lengths, per group) the factor is the kernel's own (eigenvalues below 1e-9 of the largest
    dropped); beyond, the field is represented on that grid (Nystrom: F = K_nm K_mm^-1/2), so F's
    columns stop growing however many frames a run has (memory and time linear in the points;
    the field's variation faster than the grid is left out: a point keeps about 0.9 of its
    variance, the correlations beyond half a length are the kernel's to 0.01)."""
    pts = np.asarray(points_px, dtype=np.float64).reshape(-1, 2)
    grp = np.asarray(groups)
    step = GRID_STEP * float(length_px)
    axes = [np.linspace(0.0, float(e), int(np.ceil(float(e) / step)) + 1) for e in extent_px]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 2)
    labels = list(dict.fromkeys(grp.tolist()))
    if len(pts) <= len(labels) * len(grid):
        kernel = _exp_kernel(pts, pts, length_px) * (grp[:, None] == grp[None, :])
        lam, vec = np.linalg.eigh(kernel)
        keep = lam > 1e-9 * lam[-1]
        return np.kron(vec[:, keep] * np.sqrt(lam[keep]), np.eye(2))
    lam, vec = np.linalg.eigh(_exp_kernel(grid, grid, length_px))
    keep = lam > 1e-9 * lam[-1]
    inv_sqrt = vec[:, keep] / np.sqrt(lam[keep])
    q = inv_sqrt.shape[1]
    f1 = np.zeros((len(pts), len(labels) * q))
    for k, label in enumerate(labels):
        rows = np.flatnonzero(grp == label)
        f1[rows, k * q:(k + 1) * q] = _exp_kernel(pts[rows], grid, length_px) @ inv_sqrt
    return np.kron(f1, np.eye(2))


def _exp_kernel(a: np.ndarray, b: np.ndarray, length_px: float) -> np.ndarray:
    """exp(-|a_i - b_j| / length_px) (len(a), len(b))."""
    return np.exp(-np.hypot(a[:, None, 0] - b[None, :, 0], a[:, None, 1] - b[None, :, 1]) / float(length_px))


def persistent_bias_covariance(jac: np.ndarray, res: np.ndarray, factor: np.ndarray, sigma_px: float | None,
                               shapes: np.ndarray | None = None, floor_px: float | None = None):
    """(covariance (p, p), sigma^2, tau^2) of a least-squares fit whose centre errors are noise
    (sigma^2 T_i for point i) plus a bias that persists across a run's frames with correlation
    S S^T over the rows (tau^2 per axis; ``factor`` S (m, q): :func:`_marker_indicator` for one
    bias per marker, :func:`spatial_bias_factor` for a field correlated between nearby points):
    a docking run's camera and lens are fixed, so a centre is biased much the same way in every
    frame (lens, lighting and colour effects on the detector), which one frame's residuals
    cannot tell from noise.

    ``jac`` (m, p) and ``res`` (m,) the unweighted fit's Jacobian and residuals, rows 2n
    interleaved (u, v) over n points; ``shapes`` (n, 2, 2) the relative noise covariance T_i of
    each point (None: I). With M = I - H (H the hat matrix) and Q = S^T M S, the moments
    E[r^T r] = sigma^2 tr(M T) + tau^2 tr Q and E[|S^T r|^2] = sigma^2 tr(S^T M T M S) +
    tau^2 tr Q^2 give sigma^2 and tau^2 (``sigma_px`` given: sigma^2 is its square over the
    mean of tr T_i / 2, and the second moment gives tau^2; tau^2 is 0 unless |S^T r|^2 exceeds
    its bias-free distribution at BIAS_ALPHA, :func:`_noise_and_bias`: noise alone widens an
    ideal run's covariance about once in 20 runs). The covariance is the sandwich A^-1 J^T (sigma^2 T +
    tau^2 S S^T) J A^-1, an estimated sigma never below ``floor_px`` (per axis, as
    :func:`solver.refine.covariance_from_jacobian`'s floor) (A = J^T J); sigma^2 is returned per
    axis averaged over the points (px^2). Not finite when A is singular."""
    m, p = jac.shape
    n = m // 2
    t = np.broadcast_to(np.eye(2), (n, 2, 2)) if shapes is None else np.asarray(shapes, dtype=np.float64)
    s = np.asarray(factor, dtype=np.float64)
    a_inv = inverse_spd(jac.T @ jac)
    if not np.all(np.isfinite(a_inv)) or m <= p:
        return a_inv, float("inf"), 0.0
    jr = jac.reshape(n, 2, p)
    meat = jac.T @ np.einsum("nab,nbq->naq", t, jr).reshape(m, p)     # J^T T J (one BLAS product)
    js = jac.T @ s
    sm = (s.T - js.T @ a_inv @ jac.T).reshape(-1, n, 2)              # S^T M, rows by point
    q = sm.reshape(-1, m) @ s
    tsm = np.einsum("nab,knb->kna", t, sm).reshape(-1, m)
    c = sm.reshape(-1, m) @ tsm.T                                    # S^T M T M S
    moments = np.array([[float(np.trace(t, axis1=1, axis2=2).sum() - np.sum(a_inv * meat)), float(np.trace(q))],
                        [float(np.trace(c)), float(np.sum(q * q))]])
    rr, sr = float(res @ res), float(np.sum((s.T @ res) ** 2))
    mean_var = float(np.trace(t, axis1=1, axis2=2).mean()) / 2.0
    known = None if sigma_px is None else float(sigma_px) ** 2 / mean_var
    sigma2, tau2 = _noise_and_bias(moments, rr, sr, float(np.sum(c * c)), known, m - p)
    if sigma_px is None and floor_px is not None:
        sigma2 = max(sigma2, float(floor_px) ** 2 / mean_var)
    g = a_inv @ js
    return a_inv @ (sigma2 * meat) @ a_inv + tau2 * (g @ g.T), float(sigma2) * mean_var, tau2
