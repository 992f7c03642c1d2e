"""A covariance that covers the error when the focal length is weakly determined.

Why and how: docs/solver.md, "Focal profile".
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from dockfactory.solver.errors import SolverError
from dockfactory.solver.estimate import PnPfResult, focal_is_determined
from dockfactory.solver.options import RefineOptions
from dockfactory.solver.refine import refine_pnpf

__all__ = ["PROFILE_DELTA_CHI2", "PROFILE_MIN_RATIO", "PROFILE_MIN_REL_STD", "PROFILE_STEPS", "widen_along_focal_profile"]

PROFILE_DELTA_CHI2 = 9.0      # chi-square rise of a 3-sigma likelihood-ratio interval (1 parameter)
PROFILE_MIN_REL_STD = 0.01    # below this linearised relative std of f the valley is straight: no profile
PROFILE_MIN_RATIO = 1.25    # widen only when the interval's end lies beyond this x 3 linearised stds
PROFILE_STEPS = (1.0, 2.0, 3.0, 4.5, 6.5, 9.0, 13.0, 18.0, 26.0, 36.0, 50.0)   # x std of log f
PROFILE_MAX_FACTOR = 20.0     # the walk stays within f / 20 .. 20 f of the estimate


def so3_log(r: np.ndarray) -> np.ndarray:
    """Rotation vector (3,) rad of a rotation matrix ``r`` (3, 3) (angle below pi)."""
    c = min(max((float(np.trace(r)) - 1.0) / 2.0, -1.0), 1.0)
    v = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]]) / 2.0
    s = float(np.linalg.norm(v))
    angle = math.atan2(s, c)
    return v * (angle / s) if s > 1e-15 else v


def _delta(res: PnPfResult, ref) -> np.ndarray:
    """(7,) the parameters of refinement ``ref`` relative to ``res``, in the covariance's order."""
    w = so3_log(ref.rotation @ res.rotation.T)
    return np.concatenate([w, ref.translation - res.translation, [ref.focal_px - res.focal_px]])


def _profile_end(p3, p2, pp, res: PnPfResult, side: int, rss0: float, options: RefineOptions):
    """(7,) parameter change to where the profile of one side (``side`` -1: smaller f, +1:
    larger) has risen by PROFILE_DELTA_CHI2 sigma^2, interpolated between two steps; the last
    step reached when it never rises that far (within the grid and PROFILE_MAX_FACTOR, or before a
    refinement fails)."""
    s_log = math.sqrt(res.covariance[6, 6]) / res.focal_px
    limit = PROFILE_DELTA_CHI2 * res.sigma_px ** 2
    rot, t, f_prev, prev, prev_rise = res.rotation, res.translation, res.focal_px, np.zeros(7), 0.0
    for k in PROFILE_STEPS:
        f = res.focal_px * math.exp(side * min(k * s_log, math.log(PROFILE_MAX_FACTOR)))
        try:   # the start keeps the points' image: the translation scales with f (weak perspective)
            ref = refine_pnpf(p3, p2, pp, rot, t * (f / f_prev), f, options, fix_focal=True)
        except SolverError:
            return prev
        rise, d = float(ref.residuals @ ref.residuals) - rss0, _delta(res, ref)
        if rise >= limit:
            a = (limit - prev_rise) / max(rise - prev_rise, 1e-300)
            return prev + min(max(a, 0.0), 1.0) * (d - prev)
        rot, t, f_prev, prev, prev_rise = ref.rotation, ref.translation, f, d, max(rise, prev_rise)
        if k * s_log >= math.log(PROFILE_MAX_FACTOR):
            break
    return prev


def widen_along_focal_profile(p3, p2, pp, res: PnPfResult, options: RefineOptions) -> PnPfResult:
    """``res`` with its covariance widened along the focal's likelihood profile (see the module
    docstring) when an end of the profile's 3-sigma interval lies beyond 3 linearised standard
    deviations of f (``focal_determined`` then judged on the widened covariance: a focal whose
profile reaches beyond ``max_focal_rel_std`` is not determined); ``res`` itself when f's relative std is below PROFILE_MIN_REL_STD, is not
    finite, or both ends lie within. ``p3`` (N, 3) mm, ``p2`` (N, 2) px: the points ``res`` used."""
    var_f = float(res.covariance[6, 6])
    if not (math.isfinite(var_f) and PROFILE_MIN_REL_STD * res.focal_px < math.sqrt(var_f) < res.focal_px):
        return res
    rss0 = float(np.sum(res.residuals_px ** 2))
    d = max((_profile_end(p3, p2, pp, res, side, rss0, options) for side in (-1, 1)), key=lambda e: abs(e[6]))
    s2 = d[6] ** 2 / (9.0 * var_f)
    if s2 <= PROFILE_MIN_RATIO ** 2:
        return res
    cov = res.covariance + np.outer(d, d) / 9.0 * (1.0 - 1.0 / s2)
    cov = 0.5 * (cov + cov.T)
    return replace(res, covariance=cov,
                   focal_determined=res.focal_determined and focal_is_determined(res.focal_px, cov, options))
