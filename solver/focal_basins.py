"""Another basin of the focal: choose it by evidence, or say the focal is undetermined.

Why and how: docs/solver.md, "Focal basins".
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

from dockfactory.core.cv import cv2
import numpy as np

from dockfactory.solver.errors import SolverError
from dockfactory.solver.estimate import PnPfResult
from dockfactory.solver.options import RefineOptions
from dockfactory.solver.refine import RefineResult, refine_pnpf

__all__ = ["BASIN_DELTA_CHI2", "BASIN_FOCALS", "BASIN_MIN_SEPARATION", "settle_focal_basin"]

BASIN_FOCALS = 25            # grid focals of the profile (factor 1.26 between neighbours over 0.25-64)
BASIN_DELTA_CHI2 = 16.0      # another basin this close (in sigma^2 of RSS) explains the points too
BASIN_MIN_SEPARATION = 0.1   # |log f_other / f| below this is the same basin


@dataclass(frozen=True)
class _GridPoint:
    """The pose at one grid focal held fixed: rotation (3, 3), translation (3,) mm, focal px, RSS px^2."""
    rotation: np.ndarray
    translation: np.ndarray
    focal_px: float
    rss: float


def _rss(ref) -> float:
    return float(ref.rss) if isinstance(ref, _GridPoint) else float(ref.residuals @ ref.residuals)


def _at_focal(p3, p2, pp, f: float) -> _GridPoint | None:
    """The calibrated pose at focal ``f`` (SQPnP, the calibrated problem's global minimum, then
    OpenCV's Levenberg-Marquardt), None when OpenCV gives none or a point lies behind it."""
    k = np.array([[f, 0.0, pp[0]], [0.0, f, pp[1]], [0.0, 0.0, 1.0]])
    obj, img = p3.reshape(-1, 1, 3), p2.reshape(-1, 1, 2)
    try:
        ok, rvec, tvec = cv2.solvePnP(obj, img, k, None, flags=cv2.SOLVEPNP_SQPNP)
        if not ok:
            return None
        rvec, tvec = cv2.solvePnPRefineLM(obj, img, k, None, rvec, tvec)
    except cv2.error:
        return None
    rot = cv2.Rodrigues(rvec)[0]
    pc = p3 @ rot.T + tvec.ravel()
    if not np.all(pc[:, 2] > 0):
        return None
    uv = f * pc[:, :2] / pc[:, 2:3] + pp
    return _GridPoint(rot, tvec.ravel().copy(), f, float(np.sum((uv - p2) ** 2)))


def focal_profile_grid(p3, p2, pp) -> list[_GridPoint]:
    """The pose at each focal of a geometric grid held fixed, in increasing focal order (grid
    points without a pose are left out). The grid: BASIN_FOCALS focals from 0.25 to 64 times the
    points' image extent (the largest distance from the principal point): fields of view from
    very wide to very narrow, as the closed form's sweep."""
    extent = float(np.max(np.abs(p2 - pp))) + 1.0
    out = (_at_focal(p3, p2, pp, f) for f in np.geomspace(0.25 * extent, 64.0 * extent, BASIN_FOCALS))
    return [g for g in out if g is not None]


def _local_minima(profile: list[_GridPoint]) -> list[_GridPoint]:
    """Grid points whose RSS is below both neighbours' (an end: below its one neighbour)."""
    rss = [_rss(r) for r in profile]
    return [profile[i] for i in range(len(profile))
            if (i == 0 or rss[i] < rss[i - 1]) and (i == len(profile) - 1 or rss[i] < rss[i + 1])]


def _full(p3, p2, pp, start, options: RefineOptions) -> RefineResult | None:
    try:
        return refine_pnpf(p3, p2, pp, start.rotation, start.translation, start.focal_px, options)
    except SolverError:
        return None


def _separate(res: PnPfResult, other) -> bool:
    """``other`` lies in another basin than ``res``: its focal beyond BASIN_MIN_SEPARATION in log f
    and 3 standard deviations of ``res``'s focal."""
    d = abs(other.focal_px - res.focal_px)
    return (abs(math.log(other.focal_px / res.focal_px)) > BASIN_MIN_SEPARATION
            and d > 3.0 * math.sqrt(max(float(res.covariance[6, 6]), 0.0)))


def settle_focal_basin(p3, p2, pp, res: PnPfResult, sigma_px, options: RefineOptions,
                       focal_range: tuple[float, float] | None = None) -> PnPfResult:
    """``res`` in the best basin of the focal profile, its ``focal_determined`` False when a
    separate basin explains the points within BASIN_DELTA_CHI2 sigma^2 (see the module
    docstring). ``p3`` (N, 3) mm, ``p2`` (N, 2) px: the points ``res`` used; ``sigma_px`` as the
    caller gave it (None: estimated from the residuals, as ``res`` was); ``focal_range`` (lo,
    hi) px: the camera's known zoom range, outside which no grid point is a basin."""
    lo, hi = focal_range if focal_range is not None else (0.0, math.inf)
    profile = [r for r in focal_profile_grid(p3, p2, pp) if lo <= r.focal_px <= hi]
    if not profile:
        return res
    rss0 = float(np.sum(res.residuals_px ** 2))
    lowest = min(profile, key=_rss)
    if _rss(lowest) < rss0:
        ref = _full(p3, p2, pp, lowest, options)
        if ref is not None and _rss(ref) < rss0:
            res = replace(PnPfResult.from_refinement(ref, sigma_px, res.candidates, res.inliers, options),
                          noise_dof=res.noise_dof)
            rss0 = _rss(ref)
    limit = rss0 + BASIN_DELTA_CHI2 * res.sigma_px ** 2
    for start in _local_minima(profile):
        if not _separate(res, start):
            continue
        other = _full(p3, p2, pp, start, options)
        if other is not None and lo <= other.focal_px <= hi and _separate(res, other) and _rss(other) < limit:
            return replace(res, focal_determined=False, other_focal_px=float(other.focal_px))
    return res
