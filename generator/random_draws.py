"""The seeded streams of a dataset and the draws the frame sampler, the camera units and the
docking runs share: the static scene, B's pose and the camera's aim.

Every random choice comes from a ``numpy.random.Generator`` seeded with
``SeedSequence([seed, stream, ...])``, one named stream per purpose (the ``STREAM_*`` ids below;
an id once given keeps its meaning, so a dataset draws what it drew before).
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from dockfactory.core.config import CameraConfig, Config, PoseConfig
from dockfactory.core.geometry import (
    look_at_cam_from_world,
    make_transform,
    rot_x,
    rot_y,
    rot_z,
    transform_from_pose_components,
    transform_points,
)
from dockfactory.core.layout import BASE_EMBED_MM, RING_BASE_DEPTH_MM, base_depth_mm, marker_points
from dockfactory.core.mesh_markers import layout_on_parts
from dockfactory.core.scene import CLUTTER_SLOTS, PartMesh, StaticScene

STREAM_PLAN, STREAM_GEOMETRY, STREAM_LOOK, STREAM_REPEAT_GEOMETRY, STREAM_REPEAT_LOOK = range(5)
# camera units and docking runs (their own streams: configs without them draw what they drew before)
STREAM_UNITS, STREAM_UNIT_LENS, STREAM_UNIT_CAMERA, STREAM_RUN_PLAN, STREAM_RUN, STREAM_RUN_LOOK = range(5, 11)
# colour sensors: per unit (STREAM_UNIT_SENSOR), per frame (STREAM_FRAME_ISP: white balance, exposure time)
STREAM_UNIT_SENSOR, STREAM_FRAME_ISP = 11, 12
# motion ([motion]): per frame, B's velocity during the exposure
STREAM_FRAME_MOTION = 13


def rng_for(seed: int, *keys: int) -> np.random.Generator:
    """The Generator of one named stream of a dataset."""
    return np.random.default_rng(np.random.SeedSequence([int(seed), *map(int, keys)]))


def uniform(rng, lo_hi) -> float:
    """One uniform draw in the config range ``lo_hi`` = (lo, hi)."""
    return float(rng.uniform(lo_hi[0], lo_hi[1]))


@lru_cache(maxsize=8)
def static_scene(cfg: Config) -> StaticScene:
    """What stays fixed for a whole dataset, from [sections], [markers] and [occlusion] occluders
    (lengths in mm): built once from the config, then passed down to every frame and worker. A
    section with a part mesh carries it, and the markers' base reaches down to the deepest drop of
    the part under a ring (core.mesh_markers)."""
    s, m = cfg.sections, cfg.markers
    markers, drops = layout_on_parts(s, m)
    depth = base_depth_mm(m.form, m.raise_mm, m.diameter_mm, s.radius_mm)
    for drop in drops.values():
        reach = m.raise_mm + drop + BASE_EMBED_MM
        depth = max(depth, max(RING_BASE_DEPTH_MM, reach) if m.form == "puck" else reach)
    parts = {f"part_{k}": PartMesh(*(getattr(s, f"mesh_{k}_{f}") for f in
                                     ("vertices", "triangles", "materials", "triangle_materials")))
             for k in ("a", "b") if getattr(s, f"mesh_{k}_triangles")}
    return StaticScene(radius_mm=s.radius_mm, length_mm=s.length_mm, flange_width_mm=s.flange_width_mm,
                       flange_height_mm=s.flange_height_mm, markers=markers,
                       max_occluders=cfg.occlusion.occluders[1], clutter_slots=CLUTTER_SLOTS,
                       marker_base_depth_mm=depth, **parts)


def markers_in_d(static: StaticScene, d_from_b: np.ndarray) -> np.ndarray:
    """Marker centres (N, 3) mm in D, in layout order; B's markers moved by ``d_from_b`` (4, 4)."""
    pa = marker_points(static.markers)
    is_b = np.array([m.section == "B" for m in static.markers])
    out = pa.copy()
    out[is_b] = transform_points(d_from_b, pa[is_b])
    return out


def sample_pose(pose: PoseConfig, rng: np.random.Generator) -> np.ndarray:
    """d_from_b (4, 4), mm: six uniform draws from ``rng`` over the [pose] ranges, in the order
    X, Y, Z (mm), alpha, beta, gamma (degrees; conventions.md, Frames)."""
    return transform_from_pose_components(uniform(rng, pose.x_mm), uniform(rng, pose.y_mm), uniform(rng, pose.z_mm),
                                          uniform(rng, pose.alpha_deg), uniform(rng, pose.beta_deg),
                                          uniform(rng, pose.gamma_deg))


def aim_camera(camera: CameraConfig, radius_mm: float, rng: np.random.Generator, b_x_mm: float):
    """A camera aimed near the seam: draws from ``rng`` the lateral jitter (X, Y), the tilt (about
    X, Y), the roll and the distance, in that order, from [camera]; the look-at point is on the
    sections' surface (Z = ``radius_mm``) halfway across the axial gap ``b_x_mm`` (B's X in D).

    Returns (cam_from_d (4, 4), eye (3,) mm in D, target (3,) mm in D); the camera frame is OpenCV's."""
    jx, jy = rng.uniform(-camera.lateral_jitter_mm, camera.lateral_jitter_mm, size=2)
    tx, ty = np.radians(rng.uniform(-camera.tilt_deg, camera.tilt_deg, size=2))
    roll = np.radians(rng.uniform(-camera.roll_deg, camera.roll_deg))
    distance = uniform(rng, camera.distance_mm)
    target = np.array([b_x_mm / 2.0 + jx, jy, radius_mm])
    eye = target + distance * (rot_y(ty) @ rot_x(tx) @ np.array([0.0, 0.0, 1.0]))
    cam_from_d = make_transform(rot_z(roll), np.zeros(3)) @ look_at_cam_from_world(eye, target)
    return cam_from_d, eye, target
