"""A common offset of each section's centres: the model error a section's pose absorbs unseen.

The detector's centre errors of one section's markers in a frame share a part (its colour through
the lens and the sensor, the blur of its depth): a shift d of every centre of the section. A
fit's residuals cannot show it, since the section's pose absorbs it (to first order a shift of a
section's image is a move of its pose), so the estimate carries G d with G = A^-1 J^T W S
(A = J^T W J the estimator's information, W its weights, S the rows' indicator of each section
and axis) and no residual-based noise estimate sees it. With a prior std per axis (``shift_px``,
measured on other labelled frames of the camera class: eval.section_shift), the covariance
grows by G diag(shift^2) G^T.

Why and how: docs/solver.md, "Section shift".
"""
from __future__ import annotations

import numpy as np

from dockfactory.solver.refine import inverse_spd, whitened

__all__ = ["shift_indicator", "section_shift_covariance"]


def shift_indicator(group_of_point, shift_px) -> np.ndarray:
    """S (2n, 2K) of n points (rows interleaved u, v): column 2k + a is ``shift_px[a]`` on the
    rows of axis a of the points of group k (``group_of_point`` (n,) ints 0..K-1), else 0."""
    groups = np.asarray(group_of_point, dtype=int).reshape(-1)
    k = int(groups.max()) + 1 if groups.size else 0
    s = np.zeros((2 * groups.size, 2 * k))
    for a in range(2):
        s[2 * np.arange(groups.size) + a, 2 * groups + a] = float(shift_px[a])
    return s


def section_shift_covariance(jac: np.ndarray, group_of_point, shift_px, sqrt_w=None) -> np.ndarray:
    """(p, p): what a common shift of each group's points (std ``shift_px`` (2,) px per axis,
    independent between groups and axes) adds to the covariance of a least-squares estimate
    with Jacobian ``jac`` (2n, p; rows interleaved u, v over n points), weighted by ``sqrt_w``
    (n, 2, 2; None: unweighted). Zeros when the shift is zero or the information is singular."""
    p = jac.shape[1]
    if shift_px is None or not np.any(np.asarray(shift_px, dtype=float) > 0):
        return np.zeros((p, p))
    s = shift_indicator(group_of_point, shift_px)
    if sqrt_w is not None:
        _, jac = whitened(sqrt_w, np.zeros(jac.shape[0]), jac)
        _, s = whitened(sqrt_w, np.zeros(s.shape[0]), s)
    a_inv = inverse_spd(jac.T @ jac)
    if not np.all(np.isfinite(a_inv)):
        return np.zeros((p, p))
    g = a_inv @ (jac.T @ s)
    return g @ g.T
