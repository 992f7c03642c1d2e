"""Validation of solver inputs: shapes, finiteness, counts, degenerate geometry.

Every public entry point runs its arguments through these before any math, and they raise
:class:`solver.SolverError` (never ``assert``) with a message naming the argument.
"""
from __future__ import annotations

import numpy as np
from dockfactory.solver.errors import SolverError

__all__ = ["as_points", "as_principal_point", "check_correspondences", "MIN_POINTS"]

MIN_POINTS = 4
# Relative spread below which a point set counts as collinear (second principal axis / first).
COLLINEAR_TOL = 1e-6


def as_points(name: str, value, dim: int) -> np.ndarray:
    """``value`` as a finite (N, dim) float64 array, or SolverError naming ``name``."""
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise SolverError(f"{name}: not a numeric array ({exc})") from None
    if arr.ndim != 2 or arr.shape[1] != dim:
        raise SolverError(f"{name}: expected shape (N, {dim}), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        bad = np.flatnonzero(~np.all(np.isfinite(arr), axis=1))
        raise SolverError(f"{name}: contains NaN or inf (rows {bad[:10].tolist()})")
    return arr


def as_principal_point(value) -> np.ndarray:
    """``value`` as a finite (2,) float64 array in pixels, or SolverError."""
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise SolverError(f"principal_point: not a numeric array ({exc})") from None
    if arr.shape != (2,):
        raise SolverError(f"principal_point: expected shape (2,), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise SolverError("principal_point: contains NaN or inf")
    return arr


def _collinear_3d(points: np.ndarray) -> bool:
    centred = points - points.sum(axis=0) * (1.0 / points.shape[0])
    lam = np.linalg.eigvalsh(centred.T @ centred)
    return not lam[1] > (COLLINEAR_TOL ** 2) * lam[2]


def _collinear_2d(points: np.ndarray) -> bool:
    centred = points - points.sum(axis=0) * (1.0 / points.shape[0])
    (a, b), (_, c) = (centred.T @ centred).tolist()
    mean, dev = 0.5 * (a + c), float(np.hypot(0.5 * (a - c), b))
    return not (mean - dev) > (COLLINEAR_TOL ** 2) * (mean + dev)


def check_correspondences(points_3d, points_2d, what: str = "") -> tuple[np.ndarray, np.ndarray]:
    """Validate a 3D-2D correspondence set.

    ``points_3d``: (N, 3) float64, mm. ``points_2d``: (N, 2) float64, pixels. Returns both as
    float64 arrays. Raises SolverError for: wrong shapes, N mismatch, NaN/inf, fewer than
    4 points, collinear (or coincident) 3D points, collinear image points.
    """
    pre = f"{what}: " if what else ""
    p3 = as_points(f"{pre}points_3d", points_3d, 3)
    p2 = as_points(f"{pre}points_2d", points_2d, 2)
    if p3.shape[0] != p2.shape[0]:
        raise SolverError(f"{pre}points_3d has {p3.shape[0]} rows but points_2d has "
                          f"{p2.shape[0]}: shapes do not match")
    if p3.shape[0] < MIN_POINTS:
        raise SolverError(f"{pre}{p3.shape[0]} usable points, at least {MIN_POINTS} are needed")
    if _collinear_3d(p3):
        raise SolverError(f"{pre}the 3D points are collinear (or coincide): pose is undetermined")
    if _collinear_2d(p2):
        raise SolverError(f"{pre}the image points are collinear (or coincide): pose is "
                          "undetermined")
    return p3, p2
