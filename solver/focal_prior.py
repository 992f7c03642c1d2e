"""A known zoom range as a prior on one section's focal length.

Near-planar, fronto-parallel points can put the maximum of the likelihood at an affine camera
(f -> infinity; the measured case: results/README.md). When the camera's focal range is known (``focal_range_px = (lo, hi)``, e.g. from the
lens's zoom range in px), an estimate outside it is replaced by the constrained maximum
likelihood: the pose refined with the focal fixed at the nearer bound. Its covariance is that
of the full 7-parameter problem with the range as a Gaussian prior on f (the variance of a
uniform distribution over the range), so the pose's uncertainty still carries the focal's.
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from dockfactory.solver.errors import InvalidSolverInput
from dockfactory.solver.estimate import PnPfResult
from dockfactory.solver.options import RefineOptions
from dockfactory.solver.refine import covariance_from_jacobian, inverse_spd, refine_pnpf

__all__ = ["check_focal_range", "apply_focal_range"]


def check_focal_range(value) -> tuple[float, float] | None:
    """``(lo, hi)`` px with 0 < lo < hi, both finite, or None; InvalidSolverInput otherwise."""
    if value is None:
        return None
    try:
        lo, hi = (float(v) for v in value)
    except (TypeError, ValueError):
        raise InvalidSolverInput(f"focal_range_px must be (lo, hi) in px, got {value!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi) and 0.0 < lo < hi):
        raise InvalidSolverInput(f"focal_range_px must satisfy 0 < lo < hi (finite), got ({lo}, {hi})")
    return lo, hi


def apply_focal_range(p3, p2, pp, result: PnPfResult, focal_range, sigma_px,
                      options: RefineOptions) -> PnPfResult:
    """``result`` if its focal is inside ``focal_range`` (px), else the pose refined at the
    nearer bound, with ``focal_at_bound`` set (see the module docstring)."""
    lo, hi = focal_range
    if lo <= result.focal_px <= hi:
        return result
    f = min(max(result.focal_px, lo), hi)
    # keep the image of the points: scale the translation with the focal (weak perspective)
    start_t = result.translation * (f / result.focal_px)
    ref = refine_pnpf(p3, p2, pp, result.rotation, start_t, f, options, fix_focal=True)
    _, sigma = covariance_from_jacobian(ref.jacobian, ref.residuals, sigma_px, options.sigma_floor_px)
    info = ref.jacobian.T @ ref.jacobian / sigma ** 2
    info[6, 6] += 12.0 / (hi - lo) ** 2
    cam = np.eye(4)
    cam[:3, :3], cam[:3, 3] = ref.rotation, ref.translation
    return replace(result, cam_from_world=cam, focal_px=float(f), rmse_px=ref.rmse_px,
                   covariance=inverse_spd(info), sigma_px=sigma, iterations=ref.iterations,
                   residuals_px=ref.residuals.reshape(-1, 2), focal_determined=False, focal_at_bound=True)
