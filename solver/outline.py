"""Image of a marker disc under a fitted camera (pinhole, OpenCV pixel convention).

Bottom layer of the solver (imports only core); used by the docking pipeline steps
:mod:`solver.suspects` and :mod:`solver.eccentricity`."""
from __future__ import annotations

import numpy as np

from dockfactory.core.geometry import transform_points
from dockfactory.core.layout import marker_outline


def projected_outline(marker, cam_from_s, focal_px, pp):
    """(outline (n, 2) px, centre (2,) px) of the marker's disc edge and of its 3D centre, or
    None when part of the disc is behind the camera. ``cam_from_s`` (4, 4): the camera from the
    marker's section frame."""
    pc = transform_points(cam_from_s, np.vstack([marker_outline(marker), marker.center_mm]))
    if np.any(pc[:, 2] <= 0):
        return None
    uv = focal_px * pc[:, :2] / pc[:, 2:3] + np.asarray(pp, dtype=float)
    return uv[:-1], uv[-1]
