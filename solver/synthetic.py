"""Seeded synthetic docking scenes for the solver's tests and benchmark (pure numpy, no bpy).

The geometry mirrors the factory's sampler (``generator/sampler.py``): the default marker
layout on two cylinders of radius 300 mm, B placed by ``d_from_b`` within the pose ranges, a
camera 1.0-1.8 m from a look-at point on the seam, tilted by up to 4 deg about X and Y and rolled
by up to 2 deg, focal length drawn so that every marker stays ``margin_px`` inside the image.
It is a re-statement for testing, not an import of the factory's sampler, so that solver tests do
not move when the factory's sampling changes.

Real cameras: a principal point offset and OpenCV distortion (:mod:`core.distortion`
applied to the exact projections) per frame (:func:`docking_scene`) or per docking run
(:func:`docking_run`: a fixed camera, B approaching A).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from dockfactory.core.distortion import coeffs_array, distort_normalized, is_ideal
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
from dockfactory.solver.camera_models import Intrinsics

__all__ = ["DockingScene", "DockingRun", "default_layout", "docking_scene", "docking_run",
           "project", "image_centre"]

IMAGE_SIZE = (1280, 960)
# d_from_b ranges (X, Y, Z mm; alpha, beta, gamma deg) of the factory's sampler
POSE_RANGES = ((5.0, 150.0), (-15.0, 15.0), (-15.0, 15.0), (-1.5, 1.5), (-1.5, 1.5),
               (-5.0, 5.0))


def default_layout():
    """The factory's markers: ``build_layout(DEFAULT_LAYOUT_A, DEFAULT_LAYOUT_B, 300, 20)``."""
    return build_layout(DEFAULT_LAYOUT_A, DEFAULT_LAYOUT_B, radius_mm=300.0, diameter_mm=20.0)


def image_centre(image_size=IMAGE_SIZE) -> np.ndarray:
    """(2,) px: ((W - 1) / 2, (H - 1) / 2), the principal point of an unshifted camera."""
    w, h = image_size
    return np.array([(w - 1) / 2.0, (h - 1) / 2.0])


@dataclass(frozen=True)
class DockingScene:
    """Ground truth of one synthetic frame.

    ``points_a`` (Na, 3) mm in A's frame (= D), ``points_b`` (Nb, 3) mm in B's frame;
    ``uv_a`` (Na, 2), ``uv_b`` (Nb, 2) noise-free pixels (distorted by the camera's lens);
    ``cam_from_d``, ``d_from_b`` (4, 4); ``principal_point`` (2,) px the TRUE principal point
    (the image centre plus the camera's offset); ``coeffs`` (5,) the lens's distortion
    (k1, k2, p1, p2, k3; zeros for the ideal camera); ``image_size`` (W, H).
    """

    cam_from_d: np.ndarray
    d_from_b: np.ndarray
    focal_px: float
    principal_point: np.ndarray
    points_a: np.ndarray
    points_b: np.ndarray
    uv_a: np.ndarray
    uv_b: np.ndarray
    coeffs: np.ndarray = field(default_factory=lambda: np.zeros(5))
    image_size: tuple = IMAGE_SIZE

    @property
    def cam_from_b(self) -> np.ndarray:
        return self.cam_from_d @ self.d_from_b

    @property
    def image_centre(self) -> np.ndarray:
        """(2,) px: the principal point a solver assumes for an uncalibrated camera."""
        return image_centre(self.image_size)

    @property
    def intrinsics(self) -> Intrinsics:
        """The true camera (:class:`solver.camera_models.Intrinsics`)."""
        return Intrinsics(self.focal_px, self.principal_point.copy(), self.coeffs.copy())


@dataclass(frozen=True)
class DockingRun:
    """A docking run filmed by one fixed camera: ``frames`` (F DockingScene) sharing
    ``cam_from_d``, focal, principal point and distortion; B approaches A along X."""

    frames: tuple

    @property
    def intrinsics(self) -> Intrinsics:
        return self.frames[0].intrinsics

    @property
    def cam_from_d(self) -> np.ndarray:
        return self.frames[0].cam_from_d


def project(cam_from_x: np.ndarray, focal_px: float, principal_point, points,
            coeffs=None) -> np.ndarray:
    """Pixels (N, 2) of ``points`` (N, 3) (no visibility check); ``coeffs`` the lens's
    distortion (OpenCV order, :mod:`core.distortion`) applied to the exact projection."""
    pc = transform_points(cam_from_x, points)
    if coeffs is None or is_ideal(coeffs):
        return focal_px * pc[:, :2] / pc[:, 2:3] + np.asarray(principal_point, dtype=np.float64)
    xd = distort_normalized(pc[:, :2] / pc[:, 2:3], coeffs)
    return focal_px * xd + np.asarray(principal_point, dtype=np.float64)


def _place_camera(rng, pa, pb, d_from_bs, target_x, cam):
    """Draw a camera looking at the seam near ``target_x`` (mm) that sees every marker of A
    and of B at every pose ``d_from_bs`` ``margin_px`` inside the image (from the centre);
    (cam_from_d, f) or None when the focal range does not fit. ``cam``: the camera ranges."""
    jx, jy = rng.uniform(-cam["lateral_jitter_mm"], cam["lateral_jitter_mm"], size=2)
    tx, ty = np.radians(rng.uniform(-cam["tilt_deg"], cam["tilt_deg"], size=2))
    roll = np.radians(rng.uniform(-cam["roll_deg"], cam["roll_deg"]))
    distance = rng.uniform(*cam["distance_range"])
    target = np.array([target_x + jx, jy, cam["radius_mm"]])
    eye = target + distance * (rot_y(ty) @ rot_x(tx) @ np.array([0.0, 0.0, 1.0]))
    cam_from_d = make_transform(rot_z(roll), np.zeros(3)) @ look_at_cam_from_world(eye, target)
    pc = transform_points(cam_from_d, np.vstack([pa] + [transform_points(d, pb)
                                                        for d in d_from_bs]))
    w, h = cam["image_size"]
    margin, diam = cam["margin_px"], cam["diameter_mm"]
    ext_x = (np.abs(pc[:, 0]) + diam / 2) / pc[:, 2]
    ext_y = (np.abs(pc[:, 1]) + diam / 2) / pc[:, 2]
    f_cap = min((w / 2.0 - margin) / ext_x.max(), (h / 2.0 - margin) / ext_y.max())
    f_hi = min(cam["focal_range"][1], f_cap)
    if f_hi < cam["focal_range"][0]:
        return None
    return cam_from_d, float(rng.uniform(cam["focal_range"][0], f_hi))


def _scene(cam_from_d, d_from_b, f, pa, pb, pp_offset_px, coeffs, image_size) -> DockingScene:
    """The frame of a placed camera: true principal point = image centre + offset."""
    pp = image_centre(image_size) + np.asarray(pp_offset_px, dtype=np.float64)
    co = coeffs_array(coeffs)
    return DockingScene(cam_from_d, d_from_b, f, pp, pa, pb,
                        project(cam_from_d, f, pp, pa, co),
                        project(cam_from_d @ d_from_b, f, pp, pb, co), co, tuple(image_size))


def docking_scene(rng: np.random.Generator, *, markers=None, focal_range=(1200.0, 2400.0),
                  distance_range=(1000.0, 1800.0), tilt_deg=4.0, roll_deg=2.0,
                  lateral_jitter_mm=30.0, margin_px=48.0, image_size=IMAGE_SIZE,
                  radius_mm=300.0, pp_offset_px=(0.0, 0.0), coeffs=None) -> DockingScene:
    """Draw one docking frame from ``rng`` (redraws geometry until the focal range fits).

    ``pp_offset_px`` (2,): the true principal point's offset from the image centre (px);
    ``coeffs``: the lens's distortion (k1, k2, p1, p2, k3; fewer values are padded with
    zeros). Neither changes the draws: the same ``rng`` gives the same geometry for every
    camera (the margin is checked for the ideal camera; a +-40 px offset and |k1| <= 0.15 keep
    the default layout inside the image)."""
    markers = default_layout() if markers is None else markers
    pa = marker_points(markers, "A")
    pb = marker_points(markers, "B")
    cam = dict(focal_range=focal_range, distance_range=distance_range, tilt_deg=tilt_deg,
               roll_deg=roll_deg, lateral_jitter_mm=lateral_jitter_mm, margin_px=margin_px,
               image_size=image_size, radius_mm=radius_mm,
               diameter_mm=max(m.diameter_mm for m in markers))
    for _ in range(1000):
        d_from_b = transform_from_pose_components(*(rng.uniform(lo, hi) for lo, hi in POSE_RANGES))
        placed = _place_camera(rng, pa, pb, [d_from_b], d_from_b[0, 3] / 2.0, cam)
        if placed is None:
            continue
        return _scene(placed[0], d_from_b, placed[1], pa, pb, pp_offset_px, coeffs, image_size)
    raise RuntimeError("could not place a camera that fits the markers (check the ranges)")


def _trajectory(rng, n_frames, x_start_mm, x_end_mm) -> list:
    """d_from_b (4, 4) of each frame: X evenly from a start near the top of its range down to
    a few mm, Y, Z and the angles drifting between two draws along a smoothstep."""
    x0, x1 = rng.uniform(*x_start_mm), rng.uniform(*x_end_mm)
    ends = [(rng.uniform(lo, hi), rng.uniform(lo, hi)) for lo, hi in POSE_RANGES[1:]]
    out = []
    for s in np.linspace(0.0, 1.0, n_frames):
        smooth = s * s * (3.0 - 2.0 * s)
        rest = [a + (b - a) * smooth for a, b in ends]
        out.append(transform_from_pose_components(x0 + (x1 - x0) * s, *rest))
    return out


def docking_run(rng: np.random.Generator, n_frames: int, *, markers=None,
                x_start_mm=(135.0, 150.0), x_end_mm=(2.0, 8.0), focal_range=(1200.0, 2400.0),
                distance_range=(1000.0, 1800.0), tilt_deg=4.0, roll_deg=2.0,
                lateral_jitter_mm=30.0, margin_px=48.0, image_size=IMAGE_SIZE,
                radius_mm=300.0, pp_offset_px=(0.0, 0.0), coeffs=None) -> DockingRun:
    """Draw a docking run of ``n_frames`` frames from ``rng``: one fixed camera (pose, focal,
    principal point offset ``pp_offset_px``, distortion ``coeffs``), A fixed, B approaching
    along X from ``x_start_mm`` (a range near the top of the factory's 5-150 mm) down to
    ``x_end_mm``, frames evenly spaced; Y, Z and the angles drift smoothly within the
    factory's ranges. The camera sees every frame's markers (ideal-camera margin)."""
    if int(n_frames) < 2:
        raise ValueError(f"a docking run needs at least 2 frames, got {n_frames}")
    markers = default_layout() if markers is None else markers
    pa, pb = marker_points(markers, "A"), marker_points(markers, "B")
    cam = dict(focal_range=focal_range, distance_range=distance_range, tilt_deg=tilt_deg,
               roll_deg=roll_deg, lateral_jitter_mm=lateral_jitter_mm, margin_px=margin_px,
               image_size=image_size, radius_mm=radius_mm,
               diameter_mm=max(m.diameter_mm for m in markers))
    for _ in range(1000):
        traj = _trajectory(rng, int(n_frames), x_start_mm, x_end_mm)
        mid = 0.25 * (traj[0][0, 3] + traj[-1][0, 3])
        placed = _place_camera(rng, pa, pb, traj, mid, cam)
        if placed is None:
            continue
        return DockingRun(tuple(_scene(placed[0], d, placed[1], pa, pb, pp_offset_px, coeffs,
                                       image_size) for d in traj))
    raise RuntimeError("could not place a camera that fits the run (check the ranges)")
