"""Single-section estimator: closed-form candidates -> the one refinement, on validated arrays.

Layer 3 of the solver (closed form :mod:`solver.upnp` and refinement :mod:`solver.refine`
below; the joint fit, RANSAC, identification and the public :func:`solver.solve_pnpf` above).

Fast path: the cheapest closed-form candidate, refined. Slow path (no valid camera, no
convergence, an RMS above the acceptable one, or a focal that ran off toward the orthographic
limit): every closed-form candidate plus the focal sweep, the best few refined, and as a last
resort a profile likelihood over the focal length. Thresholds: :class:`RefineOptions`.
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass, field, replace

import numpy as np

from dockfactory.solver.errors import FocalNotObservable, NoValidCamera, SolverError
from dockfactory.solver.options import RefineOptions
from dockfactory.solver.refine import (
    DEFAULT_REFINE,
    RefineResult,
    covariance_from_jacobian,
    refine_pnpf,
    rel_focal_std,
)
from dockfactory.solver.upnp import CameraPose, focal_sweep, upnp

MIN_NOISE_DOF = 20   # residual dof of a self-estimated noise below which a std is not gated on

__all__ = ["MIN_NOISE_DOF", "PnPfResult", "PnPfEstimate", "estimate_pnpf", "refine_best_candidate",
           "check_focal_observable", "focal_is_determined"]


@dataclass(frozen=True)
class PnPfResult(CameraPose):
    """Result of :func:`solver.solve_pnpf` (and :func:`solver.ransac.ransac_pnpf`).

    - ``cam_from_world`` (4, 4): world (the frame of ``points_3d``) to OpenCV camera;
    - ``focal_px``: focal length (px); ``rmse_px``: reprojection RMS, sqrt(mean |r_i|^2) over
      the points used (px, Euclidean per point);
    - ``candidates``: the closed-form :class:`solver.upnp.Candidate` computed, best first;
    - ``covariance`` (7, 7): sigma^2 (J^T J)^-1 over (w_x, w_y, w_z [rad], t_x, t_y, t_z [mm],
      f [px]) with w a left perturbation of the rotation; ``sigma_px`` the noise std used
      (given, or estimated from the residuals);
    - ``inliers`` (N,) bool: points used (all True unless the robust path rejected some);
    - ``iterations``: Levenberg-Marquardt iterations; ``residuals_px`` (n, 2) of the points used;
    - ``focal_determined``: False when the focal's relative standard deviation is above
      ``RefineOptions.max_focal_rel_std`` (near-planar, fronto-parallel points at this noise:
      the focal and the depth trade off). The covariance is then a linearisation at a poorly
      determined point and may understate the error of any parameter, the in-plane translation
      included: gate on ``uncertainty_determined``;
    - ``noise_dof``: the residual degrees of freedom the noise sigma was estimated from
      (2 n - 7), or inf when the caller gave the noise (``sigma_px``) or a floor for it
      (``RefineOptions.sigma_floor_px``);
    - ``focal_at_bound``: the estimate fell outside the ``focal_range_px`` given to
      :func:`solver.solve_pnpf` and is the pose refined at the nearer bound (solver.focal_prior);
    - ``other_focal_px``: the focal (px) of a separate basin of the focal profile that explains
      the points about as well (then ``focal_determined`` is False; :mod:`solver.focal_basins`),
      None when there is none.
    """

    cam_from_world: np.ndarray
    focal_px: float
    rmse_px: float
    candidates: tuple
    covariance: np.ndarray
    sigma_px: float
    inliers: np.ndarray
    iterations: int = 0
    residuals_px: np.ndarray = field(default=None, repr=False)
    focal_determined: bool = True
    focal_at_bound: bool = False
    noise_dof: float = float("inf")
    other_focal_px: float | None = None

    @property
    def std(self) -> np.ndarray:
        """Standard deviations (7,) of the parameters, from ``covariance``."""
        return np.sqrt(np.diag(self.covariance))

    @property
    def uncertainty_determined(self) -> bool:
        """True when ``covariance`` is a standard deviation a user can gate on at several sigmas:
        the focal is determined and the noise is known, floored, or estimated from at least
        ``MIN_NOISE_DOF`` residual degrees of freedom.

        Why: with the noise estimated from the frame's own nu residuals, error / std is Student-t
        with nu degrees of freedom; its tail beyond 6 stds (the variance factor nu / (nu - 2)
        included) is 1.9e-3 at nu = 3 (5 points), 2e-5 at nu = 13 and below 5e-6 from nu = 20,
        so a few-point solve without a known noise can be wrong by far more than its std says
        however the std is scaled."""
        return self.focal_determined and self.noise_dof >= MIN_NOISE_DOF

    @classmethod
    def from_refinement(cls, ref: RefineResult, sigma_px, candidates, inliers,
                        options: RefineOptions = DEFAULT_REFINE) -> PnPfResult:
        """Package a refinement with its covariance (``sigma_px`` None: from the residuals)."""
        cov, sigma = covariance_from_jacobian(ref.jacobian, ref.residuals, sigma_px, options.sigma_floor_px)
        cam = np.eye(4)
        cam[:3, :3] = ref.rotation
        cam[:3, 3] = ref.translation
        return cls(cam, float(ref.focal_px), ref.rmse_px, tuple(candidates), cov, sigma,
                   inliers, ref.iterations, ref.residuals.reshape(-1, 2),
                   focal_is_determined(ref.focal_px, cov, options))


@dataclass(frozen=True)
class PnPfEstimate:
    """Output of :func:`estimate_pnpf`: the chosen ``refinement``, its ``covariance`` (7, 7)
    and ``sigma_px``, and the closed-form ``candidates`` computed."""

    refinement: RefineResult
    covariance: np.ndarray
    sigma_px: float
    candidates: tuple
    focal_determined: bool = True

    @property
    def rotation(self) -> np.ndarray:
        return self.refinement.rotation

    @property
    def translation(self) -> np.ndarray:
        return self.refinement.translation

    @property
    def focal_px(self) -> float:
        return self.refinement.focal_px

    @property
    def rmse_px(self) -> float:
        return self.refinement.rmse_px

    def result(self, inliers: np.ndarray) -> PnPfResult:
        """The public :class:`PnPfResult` (``inliers`` (N,) bool)."""
        ref = self.refinement
        cam = np.eye(4)
        cam[:3, :3] = ref.rotation
        cam[:3, 3] = ref.translation
        return PnPfResult(cam, float(ref.focal_px), ref.rmse_px, tuple(self.candidates),
                          self.covariance, self.sigma_px, inliers, ref.iterations,
                          ref.residuals.reshape(-1, 2), self.focal_determined)


def refine_best_candidate(p3, p2, pp, cands, options: RefineOptions = DEFAULT_REFINE,
                          max_tries: int = 3) -> RefineResult:
    """Refine the best candidates (up to ``max_tries``, stopping at the first that converges)
    and keep the lowest cost. Raises NoValidCamera if none reaches a valid camera."""
    best = None
    errors = []
    for cand in cands[:max_tries]:
        try:
            ref = refine_pnpf(p3, p2, pp, cand.rotation, cand.translation, cand.focal_px,
                              options)
        except SolverError as exc:
            errors.append(str(exc))
            continue
        cost = float(ref.residuals @ ref.residuals)
        if best is None or cost < best[0]:
            best = (cost, ref)
        if ref.converged:
            break
    if best is None:
        raise NoValidCamera("refinement failed from every closed-form candidate: "
                            + "; ".join(errors))
    return best[1]


def focal_is_determined(focal_px: float, cov: np.ndarray, options: RefineOptions = DEFAULT_REFINE) -> bool:
    """False when the focal's relative std (from ``cov`` (7, 7)) is above ``options.max_focal_rel_std``."""
    return bool(rel_focal_std(cov, focal_px) <= options.max_focal_rel_std)


def check_focal_observable(focal_px: float, cov: np.ndarray, options: RefineOptions) -> None:
    """FocalNotObservable when the focal is not determined (:func:`focal_is_determined`)."""
    rel = rel_focal_std(cov, focal_px)
    if not rel <= options.max_focal_rel_std:
        raise FocalNotObservable(
            f"focal length is not observable from these points (estimate {focal_px:.4g} px "
            f"with relative std {rel:.3g}): the points are too close to planar and fronto-"
            "parallel for this noise level; use more points, a wider depth range, or "
            "solve_docking, which shares the focal length between two sections")


def estimate_pnpf(p3, p2, pp, *, sigma_px=None, all_candidates=False, check_focal=False,
                  accept_rmse=None, rescue_below=None, rescue: bool = True,
                  options: RefineOptions = DEFAULT_REFINE) -> PnPfEstimate:
    """Closed form + refinement on validated arrays ``p3`` (N, 3) mm, ``p2`` (N, 2) px, ``pp``
    (2,) px (see the module docstring).

    ``accept_rmse`` (px): a fast-path RMS above it takes the slow path; with ``rescue_below``
    only when the fast RMS is below that (a near miss worth rescuing; far worse fits are wrong
    models, e.g. wrong marker assignments, not local minima). ``all_candidates``: skip the fast
    path. ``check_focal``: raise FocalNotObservable for an unobservable focal (else the estimate
    says so in ``focal_determined``). ``rescue=False``:
    the fast path only, whatever its outcome (NoValidCamera when it gives no camera), for
    callers that only need to know whether the cheap fit explains the points.
    """
    cands = [] if all_candidates else upnp(p3, p2, pp, checked=True, first_only=True)
    ref = None
    if cands:
        try:
            ref = refine_best_candidate(p3, p2, pp, cands, options, max_tries=1)
        except SolverError:
            ref = None
    worth = ref is not None and (rescue_below is None or ref.rmse_px <= rescue_below)
    near_miss = worth and accept_rmse is not None and ref.rmse_px > accept_rmse
    if not rescue and ref is None:
        raise NoValidCamera("the cheapest closed-form candidate gave no valid camera")
    if rescue and (ref is None or not ref.converged or near_miss or _focal_ran_off(ref, p2, pp, options)
                   or (worth and not _determined(ref, sigma_px, options))):
        try:
            cands = upnp(p3, p2, pp, checked=True, sweep_above_px=0.0)
            ref = _slow_path(p3, p2, pp, cands, ref, accept_rmse, options)
        except NoValidCamera:
            if rescue_below is not None:
                raise
            ref = None
        if rescue_below is None and (ref is None or _implausible(ref, sigma_px, accept_rmse, options)):
            ref = _subset_starts(p3, p2, pp, ref, options)
    elif rescue and p3.shape[0] <= options.few_points and (ref is None or (
            accept_rmse is not None and ref.rmse_px > accept_rmse)):
        # a few points (an identification hypothesis of an occluded section): the over-determined
        # closed form is unstable there and a right hypothesis can land in a wrong basin far
        # beyond any rescue (results/README.md: the measured case)
        ref = _subset_starts(p3, p2, pp, ref, options)
    cov, sigma = covariance_from_jacobian(ref.jacobian, ref.residuals, sigma_px, options.sigma_floor_px)
    if check_focal:
        check_focal_observable(ref.focal_px, cov, options)
    return PnPfEstimate(ref, cov, sigma, tuple(cands), focal_is_determined(ref.focal_px, cov, options))


def _slow_path(p3, p2, pp, cands, fast, accept_rmse, options: RefineOptions) -> RefineResult:
    """Best of: the fast-path refinement (may be None), the best ``options.fallback_starts``
    candidates refined, and (when still unacceptable) the profile likelihood over f."""
    best = _refine_lowest(p3, p2, pp, cands[:options.fallback_starts], None, options)
    if fast is not None and (best is None or fast.rmse_px <= best.rmse_px):
        best = fast
    if best is None or (accept_rmse is not None and best.rmse_px > accept_rmse) \
            or not best.converged:
        prof = _profile_focal(p3, p2, pp, options)
        if prof is not None and (best is None or prof.rmse_px < best.rmse_px):
            best = prof
    if best is None:
        raise NoValidCamera("refinement failed from every closed-form candidate")
    return best


def _implausible(ref: RefineResult, sigma_px, accept_rmse, options: RefineOptions) -> bool:
    """A residual test: the fit's RMS is above what noise explains (``accept_rmse``, else
    ``options.plausible_rmse_px``), or its focal is not determined."""
    limit = accept_rmse if accept_rmse is not None else options.plausible_rmse_px
    return ref.rmse_px > limit or not _determined(ref, sigma_px, options)


def _subset_starts(p3, p2, pp, best: RefineResult | None, options: RefineOptions) -> RefineResult:
    """Last resort for a few points (at most ``options.subset_max_points``): the closed-form
    candidates of every 4-point subset (the minimal problem, where a near-planar 5-point set's
    over-determined closed form is unstable), ranked by their RMS over all points, the best few
    refined (:func:`_best_subset_fit`); what it recovers: results/README.md.
    Raises NoValidCamera when neither ``best`` (None: the other starts gave no camera) nor any
    subset gives one."""
    n = p3.shape[0]
    if n <= options.subset_max_points:
        best = _best_subset_fit(p3, p2, pp, best, options)
    if best is None:
        raise NoValidCamera("points behind the camera: no closed-form start, of all the points or of any "
                            "4 of them, refines to a camera in front of the points")
    return best


def _best_subset_fit(p3, p2, pp, best: RefineResult | None, options: RefineOptions) -> RefineResult | None:
    """The closed-form candidates of every 4-point subset, ranked by their RMS over all the
    points; the best ``options.subset_refines`` refined on all points (lowest RMS wins)."""
    n, ranked = p3.shape[0], []
    for sub in itertools.combinations(range(n), 4):
        idx = list(sub)
        try:
            cands = upnp(p3[idx], p2[idx], pp, checked=True, sweep_above_px=0.0)
        except SolverError:
            continue
        ranked += [(_rms_on(p3, p2, pp, c), k, c) for k, c in enumerate(cands)]
    ranked.sort(key=lambda t: (t[0], t[1]))
    return _refine_lowest(p3, p2, pp, [c for _, _, c in ranked[:options.subset_refines]], best, options)


def _refine_lowest(p3, p2, pp, cands, best: RefineResult | None, options: RefineOptions) -> RefineResult | None:
    """Each candidate refined on all points; the lowest RMS of those and ``best`` (may be None)."""
    for cand in cands:
        try:
            r = refine_pnpf(p3, p2, pp, cand.rotation, cand.translation, cand.focal_px, options)
        except SolverError:
            continue
        if best is None or r.rmse_px < best.rmse_px:
            best = r
    return best


def _rms_on(p3, p2, pp, cand) -> float:
    """Reprojection RMS (px) of a closed-form candidate over all the points (inf if any is behind)."""
    pc = p3 @ cand.rotation.T + cand.translation
    if not np.all(pc[:, 2] > 0):
        return float("inf")
    uv = cand.focal_px * pc[:, :2] / pc[:, 2:3] + pp
    return float(np.sqrt(np.mean(np.sum((uv - p2) ** 2, axis=1))))


def _determined(ref: RefineResult, sigma_px, options: RefineOptions) -> bool:
    """The refinement's focal is determined: an undetermined one may be a wrong basin (5 points:
    the fast path's undetermined results were 100 bound-sigmas off in rotation), so the other
    starts are tried."""
    cov, _ = covariance_from_jacobian(ref.jacobian, ref.residuals, sigma_px, options.sigma_floor_px)
    return focal_is_determined(ref.focal_px, cov, options)


def _focal_ran_off(ref, p2, pp, options: RefineOptions) -> bool:
    """True when f ended above ``options.focal_runaway`` x the points' image extent."""
    extent = float(np.max(np.abs(np.asarray(p2) - np.asarray(pp)))) + 1.0
    return not (ref.focal_px < options.focal_runaway * extent)


def _profile_focal(p3, p2, pp, options: RefineOptions):
    """Profile likelihood over the focal length: calibrated refinement at each focal of a grid
    (from the sweep's poses), then a full refinement from the best grid point. Robust to the
    several basins a near-planar, few-point problem can have in f; slow, so a last resort."""
    short = replace(options, max_iterations=options.profile_iterations)
    best = None
    for cand in focal_sweep(p3, p2, pp, num=options.profile_focals):
        try:
            r = refine_pnpf(p3, p2, pp, cand.rotation, cand.translation, cand.focal_px, short,
                            fix_focal=True)
        except SolverError:
            continue
        if best is None or r.rmse_px < best.rmse_px:
            best = r
    if best is None:
        return None
    try:
        return refine_pnpf(p3, p2, pp, best.rotation, best.translation, best.focal_px, options)
    except SolverError:
        return None
