"""Perspective eccentricity: detections at the exact centroids of the discs' images (no noise)
give back the exact pose once the solver corrects for it; without the correction they do not."""
from __future__ import annotations

import numpy as np
import pytest

from dockfactory.core.geometry import (
    polygon_area_centroid,
    pose_components,
    transform_points,
)
from dockfactory.core.layout import marker_outline
from dockfactory.solver import DockingOptions, solve_docking
from dockfactory.solver.eccentricity import eccentricity_offset
from dockfactory.solver.synthetic import default_layout, docking_scene

LAYOUT = default_layout()


def _image_centroids(sc):
    cams = {"A": sc.cam_from_d, "B": sc.cam_from_d @ sc.d_from_b}
    out = []
    for m in LAYOUT:
        pc = transform_points(cams[m.section], marker_outline(m))
        uv = sc.focal_px * pc[:, :2] / pc[:, 2:3] + sc.principal_point
        out.append(polygon_area_centroid(uv)[1])
    return np.array(out)


@pytest.mark.parametrize("seed", range(5))
def test_exact_image_centroids_give_the_exact_pose(seed):
    sc = docking_scene(np.random.default_rng(seed))
    uv = _image_centroids(sc)
    cls = np.array([0 if m.section == "A" else 1 for m in LAYOUT])
    truth = pose_components(sc.d_from_b)
    plain = solve_docking(LAYOUT, sc.principal_point, detections=(cls, uv),
                          options=DockingOptions(eccentricity=False))
    fixed = solve_docking(LAYOUT, sc.principal_point, detections=(cls, uv))
    err = {k: abs(getattr(fixed, k) - truth[k]) for k in ("x_mm", "y_mm", "alpha_deg")}
    # the offsets come from the first fit's pose, so one correction leaves a second-order
    # residue (measured: about 1e-5 mm, 1e-6 deg, 2e-6 relative focal)
    assert err["x_mm"] < 1e-4 and err["y_mm"] < 1e-4 and err["alpha_deg"] < 1e-5, err
    assert abs(fixed.focal_px / sc.focal_px - 1) < 1e-5
    # without it the offsets (hundredths of a pixel) bias the pose: measured X +0.012 to
    # +0.026 mm and focal +0.11 % on these scenes
    assert plain.x_mm - truth["x_mm"] > 5e-3
    assert plain.focal_px / sc.focal_px - 1 > 5e-4


def test_offset_is_zero_for_a_disc_facing_the_camera_on_axis():
    m = LAYOUT[0]
    # camera on the marker's normal, 1 m away, looking at its centre: the image is a circle
    # centred on the projected centre
    n = np.asarray(m.normal)
    z = -n                                   # camera z axis points at the marker
    x = np.cross([0.0, 1.0, 0.0], z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    rot = np.vstack([x, y, z])
    eye = np.asarray(m.center_mm) + 1000.0 * n
    cam = np.eye(4)
    cam[:3, :3] = rot
    cam[:3, 3] = -rot @ eye
    off = eccentricity_offset(m, cam, 2000.0, (639.5, 479.5))
    assert np.abs(off).max() < 1e-9
    # moving the camera in its own plane keeps the disc parallel to the image: still no offset
    shifted = cam.copy()
    shifted[:3, 3] += [200.0, 0.0, 0.0]
    assert np.abs(eccentricity_offset(m, shifted, 2000.0, (639.5, 479.5))).max() < 1e-9
    # turning the camera 20 deg about its y axis makes the disc oblique: the image centroid
    # moves off the projected centre (hundredths of a pixel at this size and distance)
    c, s_ = np.cos(np.radians(20)), np.sin(np.radians(20))
    turn = np.eye(4)
    turn[:3, :3] = [[c, 0, s_], [0, 1, 0], [-s_, 0, c]]
    off = eccentricity_offset(m, turn @ cam, 2000.0, (639.5, 479.5))
    assert 1e-3 < np.abs(off).max() < 0.2
