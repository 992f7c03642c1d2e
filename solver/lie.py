"""Small rotation helpers (radians): exponential map, rotation angle, projection onto SO(3).

Bottom layer of the solver (numpy only)."""
from __future__ import annotations

import math

import numpy as np

__all__ = ["so3_exp", "rotation_angle_deg", "project_to_so3"]


def so3_exp(w) -> np.ndarray:
    """Rotation matrix (3, 3) of the rotation vector ``w`` (3,) in radians (Rodrigues)."""
    x, y, z = float(w[0]), float(w[1]), float(w[2])
    th2 = x * x + y * y + z * z
    if th2 < 1e-16:
        a, b = 1.0 - th2 / 6.0, 0.5 - th2 / 24.0
    else:
        th = math.sqrt(th2)
        a, b = math.sin(th) / th, (1.0 - math.cos(th)) / th2
    return np.array([
        [1.0 - b * (y * y + z * z), b * x * y - a * z, b * x * z + a * y],
        [b * x * y + a * z, 1.0 - b * (x * x + z * z), b * y * z - a * x],
        [b * x * z - a * y, b * y * z + a * x, 1.0 - b * (x * x + y * y)]])


def rotation_angle_deg(r_a, r_b) -> np.ndarray:
    """Angle (deg) of ``r_a @ r_b.T``; works on (3, 3) or stacks (F, 3, 3)."""
    r = np.einsum("...ij,...kj->...ik", r_a, r_b)
    c = (np.trace(r, axis1=-2, axis2=-1) - 1.0) / 2.0
    # arccos loses precision near 0: use the skew part as well.
    s = 0.5 * np.sqrt((r[..., 2, 1] - r[..., 1, 2]) ** 2 + (r[..., 0, 2] - r[..., 2, 0]) ** 2
                      + (r[..., 1, 0] - r[..., 0, 1]) ** 2)
    return np.degrees(np.arctan2(s, c))


def project_to_so3(m: np.ndarray) -> np.ndarray:
    """Nearest rotation (Frobenius) to ``m`` (..., 3, 3)."""
    u, _, vt = np.linalg.svd(m)
    d = np.sign(np.linalg.det(u @ vt))
    d = np.where(d == 0, 1.0, d)
    u = u.copy()
    u[..., :, 2] *= d[..., None]
    return u @ vt
