"""Image of a marker disc under a fitted camera (pinhole, optionally with OpenCV's lens
distortion :mod:`core.distortion`; OpenCV pixel convention).

Bottom layer of the solver (imports only core); used by the docking pipeline steps
:mod:`solver.suspects` and :mod:`solver.eccentricity`. :func:`projected_outline` is the plain
one-marker path; :func:`projected_outlines` does the same arithmetic for all the markers of a
section in one numpy pass, on the discs' points memoised per marker."""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from dockfactory.core.distortion import distort_normalized, is_ideal
from dockfactory.core.geometry import transform_points
from dockfactory.core.layout import marker_outline


def projected_outline(marker, cam_from_s, focal_px, pp, coeffs=None):
    """(outline (n, 2) px, centre (2,) px) of the marker's disc edge and of its 3D centre, or
    None when part of the disc is behind the camera. ``cam_from_s`` (4, 4): the camera from the
    marker's section frame; ``coeffs`` the lens distortion (k1, k2, p1, p2, k3) or None."""
    pc = transform_points(cam_from_s, np.vstack([marker_outline(marker), marker.center_mm]))
    if np.any(pc[:, 2] <= 0):
        return None
    if coeffs is not None and not is_ideal(coeffs):
        xd = distort_normalized(pc[:, :2] / pc[:, 2:3], coeffs)
        uv = focal_px * xd + np.asarray(pp, dtype=float)
        return uv[:-1], uv[-1]
    uv = focal_px * pc[:, :2] / pc[:, 2:3] + np.asarray(pp, dtype=float)
    return uv[:-1], uv[-1]


@lru_cache(maxsize=1024)
def _disc_points(marker) -> np.ndarray:
    """(n + 1, 3) mm, read-only: the disc's edge (``marker_outline``) and then its centre. A
    pure function of the (frozen) marker, memoised: every frame of a layout projects the same
    discs."""
    pts = np.vstack([marker_outline(marker), marker.center_mm])
    pts.flags.writeable = False
    return pts


def disc_points(markers) -> np.ndarray:
    """(m, n + 1, 3) mm: :func:`_disc_points` of each marker (markers that cannot be hashed,
    e.g. with list fields, are computed afresh)."""
    try:
        return np.stack([_disc_points(m) for m in markers])
    except TypeError:
        return np.stack([np.vstack([marker_outline(m), m.center_mm]) for m in markers])


def projected_outlines(markers, cam_from_s, focal_px, pp, coeffs=None):
    """:func:`projected_outline` of every marker of one section frame at once (the same
    arithmetic): (outlines (m, n, 2) px, centres (m, 2) px, valid (m,) bool), valid False
    (and that marker's rows undefined) where part of the disc is behind the camera."""
    pts = disc_points(markers)
    m, k, _ = pts.shape
    cam = np.asarray(cam_from_s, dtype=np.float64)
    pc = (pts.reshape(-1, 3) @ cam[:3, :3].T + cam[:3, 3]).reshape(m, k, 3)
    valid = np.all(pc[:, :, 2] > 0, axis=1)
    every = bool(valid.all())
    pc_ok = pc if every else pc[valid]
    if coeffs is not None and not is_ideal(coeffs):
        xd = distort_normalized((pc_ok[..., :2] / pc_ok[..., 2:3]).reshape(-1, 2), coeffs)
        uv = focal_px * xd.reshape(-1, k, 2) + np.asarray(pp, dtype=float)
    else:
        uv = focal_px * pc_ok[..., :2] / pc_ok[..., 2:3] + np.asarray(pp, dtype=float)
    if not every:
        uv_ok, uv = uv, np.zeros((m, k, 2))
        uv[valid] = uv_ok
    return uv[:, :-1], uv[:, -1], valid
