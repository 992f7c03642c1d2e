"""``solve_pnpf``: pose and focal length of one rigid point set (public single-section entry).

Top of the single-section stack: validates the input, then runs the estimator
(:func:`solver.estimate.estimate_pnpf`: closed form -> refinement) or, with ``robust=True``,
LO-RANSAC (:func:`solver.ransac.ransac_pnpf`).
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from dockfactory.solver.checks import (
    as_principal_point,
    check_correspondences,
    check_sigma,
)
from dockfactory.solver.errors import InvalidSolverInput
from dockfactory.solver.estimate import PnPfResult, estimate_pnpf
from dockfactory.solver.focal_basins import settle_focal_basin
from dockfactory.solver.focal_prior import apply_focal_range, check_focal_range
from dockfactory.solver.focal_profile import widen_along_focal_profile
from dockfactory.solver.options import RansacOptions, RefineOptions
from dockfactory.solver.ransac import DEFAULT_RANSAC, ransac_pnpf
from dockfactory.solver.refine import DEFAULT_REFINE

__all__ = ["PnPfResult", "solve_pnpf"]


def solve_pnpf(points_3d, points_2d, principal_point, *, sigma_px: float | None = None,
               robust: bool = False, rng: np.random.Generator | None = None,
               all_candidates: bool = False, refine_options: RefineOptions = DEFAULT_REFINE,
               ransac_options: RansacOptions = DEFAULT_RANSAC,
               focal_range_px: tuple[float, float] | None = None) -> PnPfResult:
    """Pose and focal length from 3D-2D correspondences (UPnP closed form + Levenberg-Marquardt).

    Parameters
    ----------
    points_3d, points_2d, principal_point : (N, 3) mm, world frame, N >= 4; (N, 2) px; (2,) px; float64
        Pixels: OpenCV convention (top-left pixel centre (0, 0)); principal point e.g. ((W - 1) / 2, (H - 1) / 2).
    sigma_px : float or None
        Pixel noise std for the covariance; None estimates it from the residuals.
    robust, rng, ransac_options, refine_options : bool, numpy.random.Generator, RansacOptions, RefineOptions
        Reject outliers by LO-RANSAC (``ransac_options``); ``rng`` draws its samples.
    all_candidates : bool
        ``candidates`` holds every closed-form candidate; otherwise those computed: the smallest determined null-
        space dimension (K = 1 for N >= 6), refined; all (K = 1, 2, 3, planar, focal sweep) if that fails.
    focal_range_px : (lo, hi) px or None
        The zoom range; an estimate outside it is refined at the nearer bound (solver.focal_prior.focal_at_bound).

    Returns
    -------
    PnPfResult
        An undetermined focal (near-planar, fronto-parallel points at this noise, or a second basin of the focal
        explaining the points about as well: :mod:`solver.focal_basins`, ``other_focal_px``) gives
        ``focal_determined=False``, not a refusal: gate the covariance on ``uncertainty_determined`` (focal determined,
        noise given, floored or from enough residuals). A weak focal's covariance is widened along its likelihood
        profile where the linearised one is too narrow (:mod:`solver.focal_profile`).

    Raises
    ------
    SolverError : InvalidSolverInput (shape mismatch, NaN/inf; ``robust`` without ``rng``), TooFewPoints (N < 4),
        DegenerateGeometry (collinear points), NoValidCamera (no camera in front of the points fits), NoConsensus.
    """
    sigma_px = check_sigma(sigma_px)
    p3, p2 = check_correspondences(points_3d, points_2d)
    pp = as_principal_point(principal_point)
    focal_range = check_focal_range(focal_range_px)
    if robust:
        if not isinstance(rng, np.random.Generator):
            raise InvalidSolverInput("robust=True needs rng, a numpy.random.Generator "
                                     "(explicit seed)")
        res = ransac_pnpf(p3, p2, pp, rng, ransac_options, refine_options, sigma_px=sigma_px)
    else:
        accept = None if sigma_px is None else refine_options.accept_rmse_sigmas * sigma_px
        est = estimate_pnpf(p3, p2, pp, sigma_px=sigma_px, all_candidates=all_candidates,
                            accept_rmse=accept, options=refine_options)
        res = est.result(np.ones(p3.shape[0], dtype=bool))
    return _settled(p3, p2, pp, res, sigma_px, refine_options, focal_range)


def _settled(p3, p2, pp, res: PnPfResult, sigma_px, options: RefineOptions, focal_range) -> PnPfResult:
    """The estimate ``res`` in the focal profile's best basin (or flagged), at the zoom range's
    bound when outside it, its covariance widened along the profile, its noise dof stated."""
    keep = res.inliers
    res = settle_focal_basin(p3[keep], p2[keep], pp, res, sigma_px, options, focal_range)
    if focal_range is not None:
        res = apply_focal_range(p3[keep], p2[keep], pp, res, focal_range, sigma_px, options)
    if not res.focal_at_bound:
        res = widen_along_focal_profile(p3[keep], p2[keep], pp, res, options)
    return with_noise_dof(res, sigma_px, options)


def with_noise_dof(res: PnPfResult, sigma_px: float | None, options: RefineOptions) -> PnPfResult:
    """``res`` with ``noise_dof``: 2 n - 7 over its n inliers when the noise sigma came from the
    residuals alone, inf when the caller gave it or a floor for it."""
    if sigma_px is not None or options.sigma_floor_px is not None:
        return replace(res, noise_dof=float("inf"))
    return replace(res, noise_dof=float(2 * int(np.count_nonzero(res.inliers)) - 7))
