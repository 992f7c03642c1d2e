"""Validation of solver inputs: shapes, finiteness, counts, degenerate geometry, the layout.

Bottom layer (imports only core and :mod:`solver.errors`). Every public entry point runs its
arguments through these before any math; they raise :class:`solver.errors.InvalidSolverInput`,
:class:`~solver.errors.TooFewPoints` or :class:`~solver.errors.DegenerateGeometry` (all
``ValueError`` subclasses, never ``assert``) with a message naming the argument.
"""
from __future__ import annotations

import numpy as np

from dockfactory.core.names import SECTIONS
from dockfactory.solver.errors import (
    DegenerateGeometry,
    InvalidSolverInput,
    TooFewPoints,
)

__all__ = ["as_points", "as_principal_point", "as_point_covariances", "check_correspondences",
           "check_shift_px", "check_sigma", "row_array", "layout_arrays", "collinear_2d",
           "collinear_3d", "MIN_POINTS", "COLLINEAR_TOL", "MAX_SIGMA_PX"]

MIN_POINTS = 4
# Largest centre noise (px) the solver takes: a centre known no better than this gives no pose, and
# squares of larger numbers would overflow the covariances.
MAX_SIGMA_PX = 100.0
# Relative spread below which a point set counts as collinear (second principal axis / first).
COLLINEAR_TOL = 1e-6


def as_points(name: str, value, dim: int) -> np.ndarray:
    """``value`` as a finite (N, dim) float64 array, or InvalidSolverInput naming ``name``."""
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InvalidSolverInput(f"{name}: not a numeric array ({exc})") from None
    if arr.ndim != 2 or arr.shape[1] != dim:
        raise InvalidSolverInput(f"{name}: expected shape (N, {dim}), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        bad = np.flatnonzero(~np.all(np.isfinite(arr), axis=1))
        raise InvalidSolverInput(f"{name}: contains NaN or inf (rows {bad[:10].tolist()})")
    return arr


def as_point_covariances(name: str, value, n: int) -> np.ndarray:
    """``value`` as (n, 2, 2) float64 symmetric positive definite matrices (one per point), or
    InvalidSolverInput naming ``name``."""
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InvalidSolverInput(f"{name}: not a numeric array ({exc})") from None
    if arr.shape != (n, 2, 2):
        raise InvalidSolverInput(f"{name}: expected shape ({n}, 2, 2), got {arr.shape}")
    det = arr[:, 0, 0] * arr[:, 1, 1] - arr[:, 0, 1] * arr[:, 1, 0]
    ok = np.all(np.isfinite(arr), axis=(1, 2)) & (arr[:, 0, 0] > 0) & (det > 0) \
        & (np.abs(arr[:, 0, 1] - arr[:, 1, 0]) <= 1e-9 * np.abs(arr[:, 0, 0] + arr[:, 1, 1]))
    if not np.all(ok):
        raise InvalidSolverInput(f"{name}: not symmetric positive definite (points "
                                 f"{np.flatnonzero(~ok)[:10].tolist()})")
    return arr


def as_principal_point(value) -> np.ndarray:
    """``value`` as a finite (2,) float64 array in pixels, or InvalidSolverInput."""
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InvalidSolverInput(f"principal_point: not a numeric array ({exc})") from None
    if arr.shape != (2,):
        raise InvalidSolverInput(f"principal_point: expected shape (2,), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise InvalidSolverInput("principal_point: contains NaN or inf")
    return arr


def check_sigma(sigma_px) -> float | None:
    """The pixel noise std: None (estimate it from the residuals) or a float in (0, MAX_SIGMA_PX]."""
    if sigma_px is None:
        return None
    try:
        s = float(sigma_px)
    except (TypeError, ValueError):
        raise InvalidSolverInput(f"sigma_px must be a number of pixels, got {sigma_px!r}") from None
    if not np.isfinite(s) or s <= 0 or s > MAX_SIGMA_PX:
        raise InvalidSolverInput(f"sigma_px must be in (0, {MAX_SIGMA_PX:g}] px, got {sigma_px}")
    return s


def check_shift_px(shift_px) -> tuple[float, float]:
    """A section shift's std per axis: two finite numbers of pixels in [0, MAX_SIGMA_PX]
    (InvalidSolverInput naming ``section_shift_px`` otherwise)."""
    try:
        x, y = (float(v) for v in shift_px)
    except (TypeError, ValueError):
        raise InvalidSolverInput(f"section_shift_px must be two numbers of pixels (x, y), got {shift_px!r}") from None
    if not all(np.isfinite(v) and 0 <= v <= MAX_SIGMA_PX for v in (x, y)):
        raise InvalidSolverInput(f"section_shift_px must be in [0, {MAX_SIGMA_PX:g}] px per axis, got {shift_px!r}")
    return (x, y)


def row_array(value, n, shape, name, dtype):
    """None, or ``value`` as an (n, *shape) array of ``dtype`` (one row per detection); NaN and
    inf refused (InvalidSolverInput naming ``name``)."""
    if value is None:
        return None
    try:
        arr = np.asarray(value, dtype=dtype)
    except (TypeError, ValueError) as exc:
        raise InvalidSolverInput(f"{name}: not an array of {dtype.__name__}: {exc}") from None
    if arr.shape != (n, *shape):
        raise InvalidSolverInput(f"{name}: expected shape {(n, *shape)} (one row per "
                                 f"detection), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise InvalidSolverInput(f"{name}: contains NaN or inf")
    return arr


def collinear_3d(points: np.ndarray) -> bool:
    """True when the (N, 3) points lie on a line (relative spread below COLLINEAR_TOL)."""
    centred = points - points.sum(axis=0) * (1.0 / points.shape[0])
    lam = np.linalg.eigvalsh(centred.T @ centred)
    return not lam[1] > (COLLINEAR_TOL ** 2) * lam[2]


def collinear_2d(points: np.ndarray) -> bool:
    """True when the (N, 2) points lie on a line (relative spread below COLLINEAR_TOL)."""
    centred = points - points.sum(axis=0) * (1.0 / points.shape[0])
    (a, b), (_, c) = (centred.T @ centred).tolist()
    mean, dev = 0.5 * (a + c), float(np.hypot(0.5 * (a - c), b))
    return not (mean - dev) > (COLLINEAR_TOL ** 2) * (mean + dev)


def check_correspondences(points_3d, points_2d, what: str = "") -> tuple[np.ndarray, np.ndarray]:
    """Validate a 3D-2D correspondence set.

    ``points_3d``: (N, 3) float64, mm. ``points_2d``: (N, 2) float64, pixels. Returns both as
    float64 arrays. Raises InvalidSolverInput (wrong shapes, N mismatch, NaN/inf), TooFewPoints
    (fewer than 4 points) or DegenerateGeometry (collinear or coincident 3D points, collinear
    image points).
    """
    pre = f"{what}: " if what else ""
    p3 = as_points(f"{pre}points_3d", points_3d, 3)
    p2 = as_points(f"{pre}points_2d", points_2d, 2)
    if p3.shape[0] != p2.shape[0]:
        raise InvalidSolverInput(f"{pre}points_3d has {p3.shape[0]} rows but points_2d has "
                                 f"{p2.shape[0]}: shapes do not match")
    if p3.shape[0] < MIN_POINTS:
        raise TooFewPoints(f"{pre}{p3.shape[0]} usable points, at least {MIN_POINTS} are needed")
    if collinear_3d(p3):
        raise DegenerateGeometry(f"{pre}the 3D points are collinear (or coincide): pose is "
                                 "undetermined")
    if collinear_2d(p2):
        raise DegenerateGeometry(f"{pre}the image points are collinear (or coincide): pose is "
                                 "undetermined")
    return p3, p2


def layout_arrays(markers):
    """(ids tuple (M,), sections tuple (M,), points (M, 3) mm in each marker's section frame)
    of a layout: a sequence of :class:`core.layout.Marker` of both sections."""
    try:
        ids = tuple(m.id for m in markers)
        sections = tuple(m.section for m in markers)
        pts = np.array([m.center_mm for m in markers], dtype=np.float64).reshape(-1, 3)
    except (AttributeError, TypeError) as exc:
        raise InvalidSolverInput(f"markers: expected a sequence of core.layout.Marker ({exc})") \
            from None
    if len(set(ids)) != len(ids):
        raise InvalidSolverInput("markers: duplicate marker ids in the layout")
    bad = set(sections) - set(SECTIONS)
    if bad:
        raise InvalidSolverInput(f"markers: unknown sections {sorted(bad)} (expected 'A' and "
                                 "'B')")
    if not np.all(np.isfinite(pts)):
        raise InvalidSolverInput("markers: a marker centre is NaN or inf")
    return ids, sections, pts
