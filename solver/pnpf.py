"""``solve_pnpf``: pose and focal length of one rigid point set (closed form + refinement)."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from dockfactory.solver.checks import as_principal_point, check_correspondences
from dockfactory.solver.errors import SolverError
from dockfactory.solver.refine import covariance_from_jacobian, refine_pnpf
from dockfactory.solver.upnp import Candidate, upnp

__all__ = ["PnPfResult", "solve_pnpf", "MAX_FOCAL_REL_STD"]

# A focal estimate whose standard deviation exceeds this fraction of itself is not reported:
# the points do not determine the focal length (e.g. a near fronto-parallel planar set at high
# noise, where the estimate runs off toward an affine camera).
MAX_FOCAL_REL_STD = 1.0


@dataclass(frozen=True)
class PnPfResult:
    """Result of :func:`solve_pnpf`.

    - ``cam_from_world`` (4, 4): world (the frame of ``points_3d``) to OpenCV camera;
    - ``focal_px``: focal length (px); ``rmse_px``: reprojection RMS, sqrt(mean |r_i|^2) over
      the points used (px, Euclidean per point);
    - ``candidates``: every closed-form :class:`solver.upnp.Candidate`, best first;
    - ``covariance`` (7, 7): sigma^2 (J^T J)^-1 over (w_x, w_y, w_z [rad], t_x, t_y, t_z [mm],
      f [px]) with w a left perturbation of the rotation; ``sigma_px`` the noise std used
      (given, or estimated from the residuals);
    - ``inliers`` (N,) bool: points used (all True unless the robust path rejected some);
    - ``iterations``: Levenberg-Marquardt iterations.
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

    @property
    def rotation(self) -> np.ndarray:
        return self.cam_from_world[:3, :3]

    @property
    def translation(self) -> np.ndarray:
        return self.cam_from_world[:3, 3]

    @property
    def std(self) -> np.ndarray:
        """Standard deviations (7,) of the parameters, from ``covariance``."""
        return np.sqrt(np.diag(self.covariance))


def _check_sigma(sigma_px):
    if sigma_px is None:
        return None
    s = float(sigma_px)
    if not np.isfinite(s) or s <= 0:
        raise SolverError(f"sigma_px must be positive and finite, got {sigma_px}")
    return s


def refine_candidates(p3, p2, pp, cands, sigma_px=None, max_tries: int = 3):
    """Refine the best candidates (up to ``max_tries``) and keep the lowest cost.

    Returns (RefineResult, covariance (7, 7), sigma used). Raises SolverError if none converges
    to a valid camera or the focal length is unobservable.
    """
    best = None
    errors = []
    for cand in cands[:max_tries]:
        try:
            ref = refine_pnpf(p3, p2, pp, cand.rotation, cand.translation, cand.focal_px)
        except SolverError as exc:
            errors.append(str(exc))
            continue
        cost = float(ref.residuals @ ref.residuals)
        if best is None or cost < best[0]:
            best = (cost, ref)
        if ref.converged:
            break
    if best is None:
        raise SolverError("refinement failed from every closed-form candidate: "
                          + "; ".join(errors))
    ref = best[1]
    cov, sigma = covariance_from_jacobian(ref.jacobian, ref.residuals, sigma_px)
    return ref, cov, sigma


def _check_focal_observable(ref, cov):
    v = cov[6, 6]
    rel = float(np.sqrt(v)) / ref.focal_px if np.isfinite(v) and v >= 0 else np.inf
    if not rel <= MAX_FOCAL_REL_STD:
        raise SolverError(
            f"focal length is not observable from these points (estimate {ref.focal_px:.4g} px "
            f"with relative std {rel:.3g}): the points are too close to planar and fronto-"
            "parallel for this noise level; use more points, a wider depth range, or "
            "solve_docking, which shares the focal length between two sections")


def solve_pnpf(points_3d, points_2d, principal_point, *, sigma_px: float | None = None,
               robust: bool = False, rng: np.random.Generator | None = None,
               threshold_px: float = 4.0, all_candidates: bool = False) -> PnPfResult:
    """Pose and focal length from 3D-2D correspondences (UPnP closed form + Levenberg-Marquardt).

    ``points_3d``: (N, 3) float64, mm, N >= 4, in the world frame.
    ``points_2d``: (N, 2) float64, pixels, OpenCV convention (centre of the top-left pixel is
    (0, 0)). ``principal_point``: (2,) float64, pixels (e.g. ((W - 1) / 2, (H - 1) / 2)).
    ``sigma_px``: pixel noise std for the covariance; None estimates it from the residuals.
    ``robust``: reject outliers by LO-RANSAC (:func:`solver.ransac.ransac_pnpf`) with inlier
    threshold ``threshold_px``; needs ``rng`` (a numpy Generator) for its samples.

    The closed form first tries the smallest determined null-space dimension only (K = 1 for
    N >= 6), refines it, and falls back to every candidate (K = 1, 2, 3, planar, focal sweep)
    if that gives no valid camera or the refinement fails; ``candidates`` holds the candidates
    that were computed (``all_candidates=True``: always every one).

    Returns a :class:`PnPfResult`. Raises :class:`SolverError` for: shape mismatch, NaN/inf,
    fewer than 4 points, collinear points, no valid camera (points behind the camera),
    an unobservable focal length.
    """
    sigma_px = _check_sigma(sigma_px)
    p3, p2 = check_correspondences(points_3d, points_2d)
    pp = as_principal_point(principal_point)
    if robust:
        from dockfactory.solver.ransac import ransac_pnpf
        if not isinstance(rng, np.random.Generator):
            raise SolverError("robust=True needs rng, a numpy.random.Generator (explicit seed)")
        return ransac_pnpf(p3, p2, pp, rng, threshold_px=threshold_px, sigma_px=sigma_px)
    accept = None if sigma_px is None else 3.0 * sigma_px
    ref, cov, sigma, cands = solve_checked(p3, p2, pp, sigma_px, all_candidates,
                                           accept_rmse=accept)
    return make_result(ref, cov, sigma, tuple(cands), np.ones(p3.shape[0], dtype=bool))


def solve_checked(p3, p2, pp, sigma_px=None, all_candidates=False, check_focal=True,
                  accept_rmse=None, rescue_below=None):
    """Closed form + refinement on validated arrays: (RefineResult, cov, sigma, candidates).

    Fast path: the cheapest closed-form candidate, refined. Slow path (when that gives no valid
    camera, does not converge, or ends above ``accept_rmse`` px): every closed-form candidate
    plus the focal sweep, the best few refined, the lowest cost kept. With ``rescue_below``
    the slow path runs only when the fast RMS is below it (a near miss worth rescuing; far
    worse fits are wrong models, e.g. wrong marker assignments, not local minima).
    """
    cands = [] if all_candidates else upnp(p3, p2, pp, checked=True, first_only=True)
    ref = None
    if cands:
        try:
            ref, cov, sigma = refine_candidates(p3, p2, pp, cands, sigma_px, max_tries=1)
        except SolverError:
            ref = None
    near_miss = accept_rmse is not None and ref is not None and ref.rmse_px > accept_rmse and (
        rescue_below is None or ref.rmse_px <= rescue_below)
    if ref is None or not ref.converged or near_miss or _focal_ran_off(ref, p2, pp):
        fast = ref
        cands = upnp(p3, p2, pp, checked=True, sweep_above_px=0.0)
        best = None
        for cand in cands[:4]:
            try:
                r = refine_pnpf(p3, p2, pp, cand.rotation, cand.translation, cand.focal_px)
            except SolverError:
                continue
            if best is None or r.rmse_px < best.rmse_px:
                best = r
        if fast is not None and (best is None or fast.rmse_px <= best.rmse_px):
            best = fast
        if best is None or (accept_rmse is not None and best.rmse_px > accept_rmse) \
                or not best.converged:
            prof = _profile_focal(p3, p2, pp)
            if prof is not None and (best is None or prof.rmse_px < best.rmse_px):
                best = prof
        if best is None:
            raise SolverError("refinement failed from every closed-form candidate")
        ref = best
        cov, sigma = covariance_from_jacobian(ref.jacobian, ref.residuals, sigma_px)
    if check_focal:
        _check_focal_observable(ref, cov)
    return ref, cov, sigma, cands


# A refinement that ends with the focal length this many times the image extent of the points
# has slid toward the orthographic limit (f and depth growing together): on a few near-planar
# points that is the signature of a start in the wrong basin (measured: the cheapest closed-form
# candidate at f 2261 px ran off to 9e11 px with 26 px RMS; the next one, f 1842, converged to
# 1885 px with 0.42 px RMS; true f 1938), so the other candidates are tried.
FOCAL_RUNAWAY = 1000.0


def _focal_ran_off(ref, p2, pp) -> bool:
    extent = float(np.max(np.abs(np.asarray(p2) - np.asarray(pp)))) + 1.0
    return not (ref.focal_px < FOCAL_RUNAWAY * extent)


def _profile_focal(p3, p2, pp):
    """Profile likelihood over the focal length: calibrated refinement at each focal of a grid
    (from the sweep's poses), then a full refinement from the best grid point. Robust to the
    several basins a near-planar, few-point problem can have in f; slow, so a last resort."""
    from dockfactory.solver.upnp import focal_sweep
    best = None
    for cand in focal_sweep(p3, p2, pp, num=9):
        try:
            r = refine_pnpf(p3, p2, pp, cand.rotation, cand.translation, cand.focal_px,
                            max_iter=6, fix_focal=True)
        except SolverError:
            continue
        if best is None or r.rmse_px < best.rmse_px:
            best = r
    if best is None:
        return None
    try:
        return refine_pnpf(p3, p2, pp, best.rotation, best.translation, best.focal_px)
    except SolverError:
        return None


def make_result(ref, cov, sigma, cands, inliers) -> PnPfResult:
    cam = np.eye(4)
    cam[:3, :3] = ref.rotation
    cam[:3, 3] = ref.translation
    return PnPfResult(cam, float(ref.focal_px), ref.rmse_px, tuple(cands), cov, sigma, inliers,
                      ref.iterations, ref.residuals.reshape(-1, 2))


__all__ += ["refine_candidates", "make_result", "solve_checked", "Candidate"]
