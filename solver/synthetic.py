"""Seeded synthetic docking scenes for the solver's tests and benchmark (pure numpy, no bpy).

The geometry mirrors the factory's sampler (``generator/sampler.py``): the default marker
layout on two cylinders of radius 300 mm, B placed by ``d_from_b`` within the pose ranges, a
camera 1.0-1.8 m from a look-at point on the seam, tilted by up to 4 deg about X and Y and rolled
by up to 2 deg, focal length drawn so that every marker stays ``margin_px`` inside the image.
It is a re-statement for testing, not an import of the factory's sampler, so that solver tests do
not move when the factory's sampling changes.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dockfactory.core.geometry import (
    look_at_cam_from_world,
    make_transform,
    rot_x,
    rot_y,
    rot_z,
    transform_from_pose_components,
    transform_points,
)
from dockfactory.core.layout import (
    DEFAULT_LAYOUT_A,
    DEFAULT_LAYOUT_B,
    build_layout,
    marker_points,
)

__all__ = ["DockingScene", "default_layout", "docking_scene", "project"]

IMAGE_SIZE = (1280, 960)


def default_layout():
    """The factory's markers: ``build_layout(DEFAULT_LAYOUT_A, DEFAULT_LAYOUT_B, 300, 20)``."""
    return build_layout(DEFAULT_LAYOUT_A, DEFAULT_LAYOUT_B, radius_mm=300.0, diameter_mm=20.0)


@dataclass(frozen=True)
class DockingScene:
    """Ground truth of one synthetic frame.

    ``points_a`` (Na, 3) mm in A's frame (= D), ``points_b`` (Nb, 3) mm in B's frame;
    ``uv_a`` (Na, 2), ``uv_b`` (Nb, 2) noise-free pixels; ``cam_from_d``, ``d_from_b`` (4, 4).
    """

    cam_from_d: np.ndarray
    d_from_b: np.ndarray
    focal_px: float
    principal_point: np.ndarray
    points_a: np.ndarray
    points_b: np.ndarray
    uv_a: np.ndarray
    uv_b: np.ndarray

    @property
    def cam_from_b(self) -> np.ndarray:
        return self.cam_from_d @ self.d_from_b


def project(cam_from_x: np.ndarray, focal_px: float, principal_point, points) -> np.ndarray:
    """Pixels (N, 2) of ``points`` (N, 3) (no visibility check)."""
    pc = transform_points(cam_from_x, points)
    return focal_px * pc[:, :2] / pc[:, 2:3] + np.asarray(principal_point, dtype=np.float64)


def docking_scene(rng: np.random.Generator, *, markers=None, focal_range=(1200.0, 2400.0),
                  distance_range=(1000.0, 1800.0), tilt_deg=4.0, roll_deg=2.0,
                  lateral_jitter_mm=30.0, margin_px=48.0, image_size=IMAGE_SIZE,
                  radius_mm=300.0) -> DockingScene:
    """Draw one docking frame from ``rng`` (redraws geometry until the focal range fits)."""
    markers = default_layout() if markers is None else markers
    pa = marker_points(markers, "A")
    pb = marker_points(markers, "B")
    w, h = image_size
    pp = np.array([(w - 1) / 2.0, (h - 1) / 2.0])
    diam = max(m.diameter_mm for m in markers)
    for _ in range(1000):
        d_from_b = transform_from_pose_components(
            rng.uniform(5.0, 150.0), rng.uniform(-15.0, 15.0), rng.uniform(-15.0, 15.0),
            rng.uniform(-1.5, 1.5), rng.uniform(-1.5, 1.5), rng.uniform(-5.0, 5.0))
        jx, jy = rng.uniform(-lateral_jitter_mm, lateral_jitter_mm, size=2)
        tx, ty = np.radians(rng.uniform(-tilt_deg, tilt_deg, size=2))
        roll = np.radians(rng.uniform(-roll_deg, roll_deg))
        distance = rng.uniform(*distance_range)
        target = np.array([d_from_b[0, 3] / 2.0 + jx, jy, radius_mm])
        eye = target + distance * (rot_y(ty) @ rot_x(tx) @ np.array([0.0, 0.0, 1.0]))
        cam_from_d = make_transform(rot_z(roll), np.zeros(3)) @ look_at_cam_from_world(eye, target)
        pc = transform_points(cam_from_d, np.vstack([pa, transform_points(d_from_b, pb)]))
        ext_x = (np.abs(pc[:, 0]) + diam / 2) / pc[:, 2]
        ext_y = (np.abs(pc[:, 1]) + diam / 2) / pc[:, 2]
        f_cap = min((w / 2.0 - margin_px) / ext_x.max(), (h / 2.0 - margin_px) / ext_y.max())
        f_hi = min(focal_range[1], f_cap)
        if f_hi < focal_range[0]:
            continue
        f = float(rng.uniform(focal_range[0], f_hi))
        cam_from_b = cam_from_d @ d_from_b
        return DockingScene(cam_from_d, d_from_b, f, pp, pa, pb, project(cam_from_d, f, pp, pa),
                            project(cam_from_b, f, pp, pb))
    raise RuntimeError("could not place a camera that fits the markers (check the ranges)")
