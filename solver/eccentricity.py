"""Perspective eccentricity: the centre of a disc's image is not the image of its centre.

A detector measures the centroid of the disc's image (an ellipse under perspective); the solver
needs the projection of the disc's 3D centre. The two differ by a fraction of a pixel that
depends on the pose (its size: results/README.md, "Measurements behind the code's constants"),
and the difference is systematic: it follows the marker's tilt, not the image noise.
Once a pose is known, each marker's offset is predicted (centroid of the projected outline
polygon minus the projected centre), taken off its detected centre, and the pose refitted.
A step of the docking pipeline (layer 5, beside :mod:`solver.suspects`).
"""
from __future__ import annotations

import numpy as np

from dockfactory.core.geometry import polygon_area_centroid
from dockfactory.core.names import SECTIONS
from dockfactory.solver.joint import JointFit, JointFitter, SectionPoints
from dockfactory.solver.outline import projected_outline, projected_outlines

__all__ = ["eccentricity_offset", "eccentricity_offsets", "eccentricity_corrected",
           "section_keep", "correct_eccentricity"]


def eccentricity_offset(marker, cam_from_s, focal_px, pp, coeffs=None) -> np.ndarray:
    """(2,) px: centroid of the projected disc minus the projection of its centre (0 when the
    disc is not entirely in front of the camera); ``coeffs`` the lens distortion or None."""
    proj = projected_outline(marker, cam_from_s, focal_px, pp, coeffs)
    if proj is None:
        return np.zeros(2)
    outline, centre = proj
    area, centroid = polygon_area_centroid(outline)
    if area <= 0 or not np.all(np.isfinite(centroid)):
        return np.zeros(2)
    return centroid - centre


def _area_centroids(poly: np.ndarray):
    """(area (m,), centroid (m, 2)) of m polygons (m, n, 2): ``polygon_area_centroid`` of each
    (same arithmetic), area 0 where it is below 1e-12 (centroid then undefined)."""
    x, y = poly[:, :, 0], poly[:, :, 1]
    xn, yn = np.roll(x, -1, axis=1), np.roll(y, -1, axis=1)
    cross = x * yn - xn * y
    a = cross.sum(axis=1) / 2.0
    ok = np.abs(a) >= 1e-12
    den = 6 * np.where(ok, a, 1.0)
    cx = ((x + xn) * cross).sum(axis=1) / den
    cy = ((y + yn) * cross).sum(axis=1) / den
    return np.where(ok, np.abs(a), 0.0), np.stack([cx, cy], axis=1)


def eccentricity_offsets(markers, cam_from_s, focal_px, pp, coeffs=None) -> np.ndarray:
    """(m, 2) px: :func:`eccentricity_offset` of each of ``markers`` (all of one section frame
    ``cam_from_s``), in one numpy pass."""
    if len(markers) == 0:
        return np.zeros((0, 2))
    outline, centre, valid = projected_outlines(markers, cam_from_s, focal_px, pp, coeffs)
    area, centroid = _area_centroids(outline)
    ok = valid & (area > 0) & np.all(np.isfinite(centroid), axis=1)
    return np.where(ok[:, None], centroid - centre, 0.0)


def section_keep(points: SectionPoints, inliers) -> dict:
    """{section: (n_s,) bool}: which of ``points``' rows are ``inliers`` (N,) per input row."""
    return {s: np.array([bool(inliers[k]) for k in points.rows[s]], dtype=bool)
            for s in SECTIONS}


def eccentricity_corrected(fit: JointFit, points: SectionPoints, fitter: JointFitter) -> dict:
    """{section: (n_s, 2) px}: every point's centre moved by minus its predicted offset under
    ``fit``. ``points`` is not modified."""
    cams = fit.cams
    pp, coeffs = (fitter.principal_point, None) if fit.intrinsics is None else \
        (fit.intrinsics.principal_point, fit.intrinsics.coeffs)
    corrected = {}
    for s in SECTIONS:
        off = eccentricity_offsets([points.markers[k] for k in points.rows[s]], cams[s],
                                   fit.focal_px, pp, coeffs)
        corrected[s] = points.points_2d[s] - off
    return corrected


def correct_eccentricity(fit: JointFit, points: SectionPoints, fitter: JointFitter,
                         inliers) -> JointFit:
    """Refit with every inlier's centre moved by minus its predicted offset under ``fit``
    (``inliers`` (N,) bool per input row). ``points`` is not modified."""
    return fitter.refit(fit, points, section_keep(points, inliers),
                        points_2d=eccentricity_corrected(fit, points, fitter))
