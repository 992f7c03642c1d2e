"""Non-square pixels in the judge: a camera whose K has fy = pixel aspect times fx.

The factory delivers such a camera's image (core.scene.CameraModel: fx = ``focal_px``); the solver is
single-focal, so a frame of it is solved in the square-pixel pinhole at fx about the same principal
point (core.geometry.pinhole_intrinsics), to which a delivered pixel (u, v) goes as
(u, cy + (v - cy) / aspect). Figures the detector makes in delivered pixels (a centre's noise, a
disc's image) are taken there by S^-1 and back by S, S = diag(1, aspect). For square pixels
(aspect 1) every function that takes an aspect returns its input, or crb_d_from_b's bound, as it is.

Why and how: docs/acceptance.md, "Non-square pixels".
"""
from __future__ import annotations

import numpy as np

from dockfactory.solver.crb import DockingBound, crb_d_from_b

__all__ = ["label_pixel_aspect", "delivered_ellipses", "square_pixel_covariances", "square_pixel_shift",
           "crb_delivered"]


def label_pixel_aspect(label: dict) -> float:
    """fy / fx of a label's camera (its ``K``); 1.0 for a label without K (an older or synthetic one)."""
    k = label["camera"].get("K")
    return 1.0 if k is None else float(k[1][1]) / float(k[0][0])


def _aspect_grid(aspect: float, power: float) -> np.ndarray:
    """(2, 2) elementwise factors of S^power C S^power, S = diag(1, ``aspect``)."""
    s = np.array([1.0, float(aspect) ** power])
    return np.outer(s, s)


def delivered_ellipses(ellipses, aspect: float):
    """(N, 2, 2) px^2: S E S, the disc images ``ellipses`` (N, 2, 2) of the square-pixel pinhole at fx
    (solver.disc_noise.disc_ellipses) in the delivered image; ``ellipses`` itself for ``aspect`` 1."""
    if aspect == 1.0:
        return ellipses
    return np.asarray(ellipses, dtype=np.float64) * _aspect_grid(aspect, 1.0)


def square_pixel_covariances(covariances, aspect: float):
    """(N, 2, 2): S^-1 C S^-1, per-point covariances ``covariances`` (N, 2, 2) of delivered pixels in
    the square-pixel pinhole at fx; ``covariances`` itself for ``aspect`` 1."""
    if aspect == 1.0:
        return covariances
    return np.asarray(covariances, dtype=np.float64) * _aspect_grid(aspect, -1.0)


def square_pixel_shift(shift_px, aspect: float):
    """(x, y) px: S^-1 s, a per-axis std ``shift_px`` (x, y) of delivered pixels (a section's
    common offset) in the square-pixel pinhole at fx; ``shift_px`` itself for ``aspect`` 1."""
    if aspect == 1.0:
        return shift_px
    return (float(shift_px[0]), float(shift_px[1]) / float(aspect))


def _mean_axis_variance(shapes: np.ndarray) -> float:
    return float(np.trace(shapes, axis1=1, axis2=2).mean()) / 2.0


def crb_delivered(points_a, cam_from_a, points_b, cam_from_b, focal_px: float, principal_point,
                  sigma_px: float, pixel_aspect: float = 1.0, noise_shapes=None) -> DockingBound:
    """The Cramer-Rao bound on ``d_from_b`` (solver.crb.crb_d_from_b, the joint problem: shared focal
    estimated) of a camera with fx = ``focal_px`` and fy = ``pixel_aspect`` fx, its centres measured
    in delivered pixels.

    Parameters
    ----------
    points_a, cam_from_a, points_b, cam_from_b, focal_px, principal_point
        As crb_d_from_b (mm, (4, 4), px).
    sigma_px : float
        The centres' noise in delivered pixels, px per axis (averaged over the points with shapes).
    pixel_aspect : float
        fy / fx; 1: exactly crb_d_from_b's bound.
    noise_shapes : (shapes_a (Na, 2, 2), shapes_b (Nb, 2, 2)) or None
        Relative noise shapes in delivered pixels (None: isotropic there).

    Returns
    -------
    DockingBound
        The bound of the square-pixel pinhole at fx with each centre's delivered noise taken there
        (S^-1 C S^-1): the delivered measurement's Fisher information, the aspect known.

    Raises
    ------
    SolverError
        As crb_d_from_b.
    """
    if pixel_aspect == 1.0:
        return crb_d_from_b(points_a, cam_from_a, points_b, cam_from_b, focal_px, principal_point, sigma_px,
                            noise_shapes=noise_shapes)
    n_a, n_b = len(points_a), len(points_b)
    shapes = (np.broadcast_to(np.eye(2), (n_a + n_b, 2, 2)) if noise_shapes is None
              else np.concatenate([np.asarray(s, dtype=np.float64).reshape(-1, 2, 2) for s in noise_shapes]))
    square = square_pixel_covariances(shapes, pixel_aspect)
    sigma = sigma_px * float(np.sqrt(_mean_axis_variance(square) / _mean_axis_variance(shapes)))
    return crb_d_from_b(points_a, cam_from_a, points_b, cam_from_b, focal_px, principal_point, sigma,
                        noise_shapes=(square[:n_a], square[n_a:]))
