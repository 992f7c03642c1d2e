"""Image of a marker disc under a fitted camera (pinhole, optionally with OpenCV's lens
distortion :mod:`core.distortion`; OpenCV pixel convention).

Bottom layer of the solver (imports only core); used by the docking pipeline steps
:mod:`solver.suspects` and :mod:`solver.eccentricity`."""
from __future__ import annotations

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
