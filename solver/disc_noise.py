"""Centre noise of a marker's image: the shape of its 2 x 2 covariance, from the disc's ellipse.

The detector's centre (detector.centre) is a least-squares fit of the edge of the disc's image,
an ellipse with semi-axes a >= b (axis ratio rho = b / a). An edge point fixes the centre only
along the edge normal n, so the information about the centre along a direction e is the edge
integral of (n . e)^2 ds: relative to the minor axis it falls along the major axis as
rho^SHAPE_EXPONENT (the exact integral: 8.3, 2.68, 1.35 at rho 0.25, 0.52, 0.82 against
rho^-1.5 = 8.0, 2.67, 1.35), and it grows with the length of the edge (SIZE_EXPONENT: ~ a).
Hence the relative covariance of a disc's centre, ``noise_shapes``:

    T = (REFERENCE_RADIUS_PX / a)^SIZE_EXPONENT (rho^-SHAPE_EXPONENT u u^T + v v^T),

u, v the major and minor axis directions; T = I for a round disc of REFERENCE_RADIUS_PX. The
scale (px) is measured, never assumed here. The exponents are the edge fit's, checked on the
refinement's errors on true boxes (bench/centre_bias.py ``collect``, every condition, errors
of 0.5 px or more left out; a scale per condition): (1.5, 1) is within 5.1 and 0.6
log-likelihood units of the best exponents on out/detector (configs/detector.toml, 4078 markers)
and on out/centre_b (configs/centre_scene_b.toml, larger sections and discs, 819 markers);
isotropic noise (0, 0) is 852 and 154 units worse, shape exponents 1 and 2 (size 1) 58 / 71 and
16 / 8 units worse. On out/detector the RMS along the major axis is 0.149 / 0.092 / 0.055 px for
rho < 0.3 / 0.45-0.6 / > 0.9, along the minor axis 0.052-0.064 px throughout. The discs of a docking camera's view are squeezed vertically (the
sections are cylinders seen from the side), so the centres' x noise is larger than their y noise.

The ellipse is the first-order (affine) image of the disc at its centre, lens distortion left
out. :func:`with_disc_noise` is the docking pipeline's step that gives a fit the covariance of
this noise model (layer 5, beside :mod:`solver.eccentricity`).
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from dockfactory.core.names import SECTIONS
from dockfactory.solver.camera_models import Intrinsics, camera_model
from dockfactory.solver.joint import JointFit, JointFitter, SectionPoints
from dockfactory.solver.refine import (
    Block,
    covariance_from_jacobian,
    d_from_b_jacobian,
    stack_blocks,
)

__all__ = ["SHAPE_EXPONENT", "SIZE_EXPONENT", "REFERENCE_RADIUS_PX", "disc_ellipses",
           "noise_shapes", "section_noise_shapes", "with_disc_noise"]

SHAPE_EXPONENT = 1.5
SIZE_EXPONENT = 1.0
REFERENCE_RADIUS_PX = 10.0


def disc_ellipses(centres_cam, normals_cam, diameters_mm, focal_px: float) -> np.ndarray:
    """(N, 2, 2) px^2: S = A A^T of each disc's image {c + A (cos t, sin t)}, whose eigenvalues
    are the squared semi-axes (first order at the disc's centre, pinhole ``focal_px``).

    ``centres_cam`` (N, 3) mm and ``normals_cam`` (N, 3) in the camera frame (OpenCV: z
    forward, every z > 0), ``diameters_mm`` (N,)."""
    c = np.asarray(centres_cam, dtype=np.float64).reshape(-1, 3)
    n = np.asarray(normals_cam, dtype=np.float64).reshape(-1, 3)
    n = n / np.linalg.norm(n, axis=1, keepdims=True)
    ref = np.where(np.abs(n[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    e1 = np.cross(ref, n)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = np.cross(n, e1)
    iz = 1.0 / c[:, 2]
    zero = np.zeros_like(iz)
    jp = focal_px * iz[:, None, None] * np.stack(
        [np.stack([1.0 + zero, zero, -c[:, 0] * iz], 1),
         np.stack([zero, 1.0 + zero, -c[:, 1] * iz], 1)], 1)          # d(u, v) / d(x, y, z)
    a = np.einsum("nij,njk->nik", jp, np.stack([e1, e2], 2))
    a *= 0.5 * np.asarray(diameters_mm, dtype=np.float64).reshape(-1, 1, 1)
    return a @ np.transpose(a, (0, 2, 1))


def noise_shapes(ellipses) -> np.ndarray:
    """(N, 2, 2): the relative centre covariance T of each disc image ``ellipses`` (N, 2, 2) px^2
    (:func:`disc_ellipses`), see the module docstring."""
    lam, vec = np.linalg.eigh(np.asarray(ellipses, dtype=np.float64).reshape(-1, 2, 2))
    minor, major = np.sqrt(np.maximum(lam[:, 0], 0.0)), np.sqrt(lam[:, 1])
    rho = np.clip(minor / major, 1e-3, 1.0)
    size = (REFERENCE_RADIUS_PX / major) ** SIZE_EXPONENT
    d = np.stack([size, size * rho ** -SHAPE_EXPONENT], 1)        # eigh: minor first
    return np.einsum("nij,nj,nkj->nik", vec, d, vec)


def section_noise_shapes(markers, cam_from_s, focal_px: float) -> np.ndarray:
    """(m, 2, 2): :func:`noise_shapes` of ``markers`` (core.layout.Marker, all of one section)
    seen by ``cam_from_s`` (4, 4), the camera from their section's frame."""
    if len(markers) == 0:
        return np.zeros((0, 2, 2))
    cam = np.asarray(cam_from_s, dtype=np.float64)
    centres = np.array([m.center_mm for m in markers]) @ cam[:3, :3].T + cam[:3, 3]
    normals = np.array([m.normal for m in markers]) @ cam[:3, :3].T
    return noise_shapes(disc_ellipses(centres, normals, [m.diameter_mm for m in markers],
                                      focal_px))


def with_disc_noise(fit: JointFit, points: SectionPoints, fitter: JointFitter, keep: dict,
                    points_2d: dict | None = None) -> JointFit:
    """``fit`` with the covariance of the disc noise model (:func:`solver.refine.
    covariance_from_jacobian` with ``point_cov``: the sandwich of the unweighted fit, the scale
    estimated from the residuals as the fitter's options say): pose and intrinsics unchanged.

    ``points`` and ``keep`` ({section: (n_s,) bool}) are the points the fit used, ``points_2d``
    their pixels if not ``points.points_2d`` (e.g. eccentricity-corrected). The fit is returned
    as it is when a point falls behind the camera.

    The detector's noise floor (``RefineOptions.sigma_floor_px``, the noise card) is not applied
    here: it is an RMS over every centre, gross errors included, while the scale of this model
    is the core of the errors. Measured RMS of z = error / std of X, Y, alpha with and without it
    (configs/detector.toml test split, 61 frames, and configs/centre_scene_b.toml, 60 frames):
    with the floor 0.97 / 0.75 / 1.01 and 1.02 / 0.87 / 0.99, without 1.11 / 0.87 / 1.13 and
    1.15 / 0.99 / 1.09 (target 0.85-1.2: Y's std was 1.3x too cautious with it)."""
    p2 = points.points_2d if points_2d is None else points_2d
    blocks, shapes = [], []
    for k, s in enumerate(SECTIONS):
        rows = [r for r, ok in zip(points.rows[s], keep[s]) if ok]
        blocks.append(Block(points.points_3d[s][keep[s]], p2[s][keep[s]], k))
        shapes.append(section_noise_shapes([points.markers[r] for r in rows], fit.cams[s],
                                           fit.focal_px))
    intr = fit.intrinsics or Intrinsics.pinhole(fit.focal_px, fitter.principal_point)
    poses = tuple((c[:3, :3], c[:3, 3]) for c in (fit.cam_from_a, fit.cam_from_b))
    res, jac, valid = stack_blocks(blocks, poses, intr, camera_model(fit.model))
    if not valid:
        return fit
    cov, sigma = covariance_from_jacobian(jac, res, fitter.sigma_px, None, np.concatenate(shapes))
    prop = d_from_b_jacobian(*poses[0], *poses[1])
    return replace(fit, covariance=prop @ cov[:12, :12] @ prop.T, covariance_params=cov,
                   sigma_px=sigma)
