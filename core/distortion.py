"""Lens distortion: OpenCV's Brown-Conrady model, in OpenCV's coefficient order (k1, k2, p1, p2, k3).

The one definition shared by the factory (distorted images and labels) and the solver (camera
models beyond the pinhole). On normalised image coordinates (x, y) = (X / Z, Y / Z)::

    r2 = x^2 + y^2,  radial = 1 + k1 r2 + k2 r2^2 + k3 r2^3
    x_d = x radial + 2 p1 x y + p2 (r2 + 2 x^2)
    y_d = y radial + p1 (r2 + 2 y^2) + 2 p2 x y

then pixels u = fx x_d + cx, v = fy y_d + cy (no skew; fy = pixel_aspect fx, 1 for square
pixels: the convention of ``core.geometry.intrinsics``). ``cv2.projectPoints`` with that K and
``distCoeffs = (k1, k2, p1, p2, k3)`` gives the same numbers (tests/core/test_distortion.py).
The pinhole side of :func:`distort_pixels` / :func:`undistort_pixels` has square pixels at fx (the
factory's render): u = fx x + cx, v = fx y + cy.
"""
from __future__ import annotations

import numpy as np

N_COEFFS = 5   # k1, k2, p1, p2, k3
COEFF_NAMES = ("k1", "k2", "p1", "p2", "k3")


def coeffs_array(coeffs) -> np.ndarray:
    """(5,) float64 of ``coeffs`` (fewer values are padded with zeros: (k1,), (k1, k2), ...)."""
    c = np.zeros(N_COEFFS)
    given = np.asarray(coeffs if coeffs is not None else (), dtype=np.float64).ravel()
    if len(given) > N_COEFFS or not np.all(np.isfinite(given)):
        raise ValueError(f"distortion coefficients: expected up to {N_COEFFS} finite values "
                         f"(k1, k2, p1, p2, k3), got {given.tolist()}")
    c[: len(given)] = given
    return c


def is_ideal(coeffs) -> bool:
    return not np.any(coeffs_array(coeffs))


def distort_normalized(xy, coeffs) -> np.ndarray:
    """Distorted normalised coordinates (N, 2) of undistorted ones ``xy`` (N, 2)."""
    k1, k2, p1, p2, k3 = coeffs_array(coeffs)
    xy = np.asarray(xy, dtype=np.float64)
    x, y = xy[..., 0], xy[..., 1]
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    return np.stack([xd, yd], axis=-1)


def distortion_jacobian(xy, coeffs) -> tuple[np.ndarray, np.ndarray]:
    """Derivatives of :func:`distort_normalized` at ``xy`` (N, 2): d(xd, yd)/d(x, y) as (N, 2, 2)
    and d(xd, yd)/d(k1, k2, p1, p2, k3) as (N, 2, 5)."""
    k1, k2, p1, p2, k3 = coeffs_array(coeffs)
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    x, y = xy[:, 0], xy[:, 1]
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    dradial_dr2 = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)
    j_xy = np.empty((len(xy), 2, 2))
    j_xy[:, 0, 0] = radial + 2.0 * x * x * dradial_dr2 + 2.0 * p1 * y + 6.0 * p2 * x
    j_xy[:, 0, 1] = 2.0 * x * y * dradial_dr2 + 2.0 * p1 * x + 2.0 * p2 * y
    j_xy[:, 1, 0] = 2.0 * x * y * dradial_dr2 + 2.0 * p1 * x + 2.0 * p2 * y
    j_xy[:, 1, 1] = radial + 2.0 * y * y * dradial_dr2 + 6.0 * p1 * y + 2.0 * p2 * x
    j_c = np.empty((len(xy), 2, N_COEFFS))
    j_c[:, 0, 0], j_c[:, 1, 0] = x * r2, y * r2
    j_c[:, 0, 1], j_c[:, 1, 1] = x * r2 ** 2, y * r2 ** 2
    j_c[:, 0, 2], j_c[:, 1, 2] = 2.0 * x * y, r2 + 2.0 * y * y
    j_c[:, 0, 3], j_c[:, 1, 3] = r2 + 2.0 * x * x, 2.0 * x * y
    j_c[:, 0, 4], j_c[:, 1, 4] = x * r2 ** 3, y * r2 ** 3
    return j_xy, j_c


def undistort_normalized(xy_d, coeffs, iterations: int = 20, tol: float = 1e-14) -> np.ndarray:
    """Undistorted normalised coordinates of distorted ones ``xy_d`` (N, 2): Newton's method on
    :func:`distort_normalized` (converges to ~1e-15 in a few steps for the lens ranges a camera
    has; a point where the model folds over raises ValueError)."""
    xy_d = np.asarray(xy_d, dtype=np.float64).reshape(-1, 2)
    if is_ideal(coeffs):
        return xy_d.copy()
    xy = xy_d.copy()
    for _ in range(iterations):
        r = distort_normalized(xy, coeffs) - xy_d
        if np.max(np.abs(r), initial=0.0) < tol:
            return xy
        j, _ = distortion_jacobian(xy, coeffs)
        det = j[:, 0, 0] * j[:, 1, 1] - j[:, 0, 1] * j[:, 1, 0]   # 2x2 solve in closed form (fast)
        xy = xy - np.stack([j[:, 1, 1] * r[:, 0] - j[:, 0, 1] * r[:, 1],
                            j[:, 0, 0] * r[:, 1] - j[:, 1, 0] * r[:, 0]], axis=1) / det[:, None]
    if np.max(np.abs(distort_normalized(xy, coeffs) - xy_d), initial=0.0) > 1e-9:
        raise ValueError("undistort: no convergence (a point outside the lens model's monotone range)")
    return xy


def _check_aspect(pixel_aspect) -> float:
    a = float(pixel_aspect)
    if not (np.isfinite(a) and a > 0):
        raise ValueError(f"pixel_aspect (fy / fx) must be positive and finite, got {pixel_aspect}")
    return a


def distort_pixels(uv, focal_px: float, principal_point, coeffs, pixel_aspect: float = 1.0) -> np.ndarray:
    """Delivered (distorted) pixels (N, 2) of pinhole pixels ``uv`` (N, 2) of one camera.

    ``uv``: the ideal pinhole image with square pixels at ``focal_px`` (= fx) and
    ``principal_point`` (cx, cy), px. Returns u = fx x_d + cx, v = fy y_d + cy with
    fy = ``pixel_aspect`` fx (module docstring; ``pixel_aspect`` 1: the same arithmetic as square
    pixels). ValueError for a non-positive ``pixel_aspect``.
    """
    a = _check_aspect(pixel_aspect)
    c = np.asarray(principal_point, dtype=np.float64)
    xy = (np.asarray(uv, dtype=np.float64) - c) / focal_px
    if a == 1.0:
        return distort_normalized(xy, coeffs) * focal_px + c
    return distort_normalized(xy, coeffs) * np.array([focal_px, focal_px * a]) + c


def undistort_pixels(uv_d, focal_px: float, principal_point, coeffs, pixel_aspect: float = 1.0) -> np.ndarray:
    """Pinhole pixels (N, 2) (square, at ``focal_px``) of delivered pixels ``uv_d`` (N, 2): the
    inverse of :func:`distort_pixels` with the same arguments (x_d = (u - cx) / fx,
    y_d = (v - cy) / fy, fy = ``pixel_aspect`` fx). ValueError as there, or where the lens folds."""
    a = _check_aspect(pixel_aspect)
    c = np.asarray(principal_point, dtype=np.float64)
    uv_d = np.asarray(uv_d, dtype=np.float64).reshape(-1, 2)
    if a == 1.0:
        return undistort_normalized((uv_d - c) / focal_px, coeffs) * focal_px + c
    return undistort_normalized((uv_d - c) / np.array([focal_px, focal_px * a]), coeffs) * focal_px + c
