"""Docking runs: frames i * per .. (i + 1) * per - 1 of the main frames form run i, taken by one
camera unit whose camera and zoom stay fixed (``unit_camera``) while B approaches A on a smooth
trajectory (``run_pose``, at the run's time ``run_time``).

The helpers take the config sections they read ([runs], [pose], [camera]) and the dataset seed;
only the plan-wide check ``check_runs_fit`` takes the whole config.
"""
from __future__ import annotations

import itertools
from collections.abc import Iterable
from functools import lru_cache

import numpy as np

from dockfactory.core.config import CameraConfig, Config, ConfigError, PoseConfig, RunsConfig
from dockfactory.core.geometry import transform_from_pose_components
from dockfactory.core.scene import FrameSpec, StaticScene
from dockfactory.generator.camera_units import ImageFit, UnitLens, largest_fitting_focal, unit_lens
from dockfactory.generator.random_draws import (
    STREAM_REPEAT_GEOMETRY,
    STREAM_RUN,
    STREAM_UNIT_CAMERA,
    aim_camera,
    markers_in_d,
    rng_for,
    sample_pose,
    static_scene,
    uniform,
)

RUN_DRIFT = 0.8    # a run's drifting components start and end within this share of their half range
RUN_WOBBLE = 0.2   # plus a slow sine of at most this share (together they stay inside the range)


def run_count(runs: RunsConfig, frames: int) -> int:
    """Docking runs of ``frames`` main frames ([dataset] frames): 0 without runs."""
    per = runs.frames_per_run
    return 0 if per == 0 else -(-frames // per)


def run_length(runs: RunsConfig, frames: int, run: int) -> int:
    """Frames of run ``run`` (the last run may be short)."""
    per = runs.frames_per_run
    return min(per, frames - run * per)


def run_time(runs: RunsConfig, frames: int, run: int, run_frame: int) -> float:
    """Time t in [0, 1] of frame ``run_frame`` of run ``run``: its frames evenly spaced, 0 for a
    run of one frame."""
    n = run_length(runs, frames, run)
    return run_frame / (n - 1) if n > 1 else 0.0


def _pose_box_corners(pose: PoseConfig, runs: RunsConfig) -> list[np.ndarray]:
    """d_from_b (4, 4) at the 64 corners of the poses a unit may see (runs and repeatability poses)."""
    xs = (min(runs.x_end_mm[0], pose.x_mm[0]), pose.x_mm[1])
    return [transform_from_pose_components(*v) for v in itertools.product(
        xs, pose.y_mm, pose.z_mm, pose.alpha_deg, pose.beta_deg, pose.gamma_deg)]


@lru_cache(maxsize=256)
def unit_camera(camera: CameraConfig, pose: PoseConfig, runs: RunsConfig, seed: int, lens: UnitLens,
                static: StaticScene, fit: ImageFit):
    """With runs: the fixed camera of the unit of ``lens``, (cam_from_d (4, 4), focal_px, eye (3,) mm,
    target (3,) mm; D frame). Drawn from the unit's STREAM_UNIT_CAMERA stream of ``seed``: the aim
    ([camera], at the middle of the runs' gaps), then the zoom within [camera] focal_px, capped so
    the markers fit (``fit``) at every corner of the pose ranges. Raises ConfigError (no source)
    if none fits."""
    rng = rng_for(seed, STREAM_UNIT_CAMERA, lens.unit)
    cam_from_d, eye, target = aim_camera(camera, static.radius_mm, rng, (runs.x_end_mm[0] + pose.x_mm[1]) / 2.0)
    cap = min(largest_fitting_focal(fit, cam_from_d, markers_in_d(static, t), lens)
              for t in _pose_box_corners(pose, runs))
    f_lo, f_hi = camera.focal_px[0], min(camera.focal_px[1], cap)
    if f_hi < f_lo:
        raise ConfigError(f"[camera] focal_px: camera unit {lens.unit} cannot fit the markers of a whole docking "
                          f"run at {f_lo:g} px (largest that fits: {cap:.0f} px)")
    return cam_from_d, float(f_lo + rng.uniform() * (f_hi - f_lo)), eye, target


@lru_cache(maxsize=4096)
def _run_drift(x_end_mm: tuple[float, float], seed: int, run: int) -> tuple:
    """A run's end gap (mm, from [runs] ``x_end_mm``) and, for Y, Z, alpha, beta, gamma: (start,
    end, wobble, cycles, phase), drawn from the run's STREAM_RUN stream in that order."""
    rng = rng_for(seed, STREAM_RUN, run)
    x_end = uniform(rng, x_end_mm)
    comps = tuple((float(rng.uniform(-RUN_DRIFT, RUN_DRIFT)), float(rng.uniform(-RUN_DRIFT, RUN_DRIFT)),
                   float(rng.uniform(-RUN_WOBBLE, RUN_WOBBLE)), float(rng.uniform(0.3, 1.5)),
                   float(rng.uniform(0.0, 2 * np.pi))) for _ in range(5))
    return x_end, comps


def run_pose(pose: PoseConfig, runs: RunsConfig, seed: int, run: int, t: float) -> np.ndarray:
    """d_from_b (4, 4) of docking run ``run`` at time ``t`` in [0, 1] (``run_time``): X falls from
    the top of [pose] x_mm to the run's end gap with a smooth (cosine) speed profile; Y, Z and the
    angles drift from a start to an end value with a slow sine on top, inside their [pose]
    ranges."""
    x_end, comps = _run_drift(runs.x_end_mm, seed, run)
    x = x_end + (pose.x_mm[1] - x_end) * 0.5 * (1.0 + np.cos(np.pi * t))
    values = []
    for (lo, hi), (a, b, wobble, cycles, phase) in zip(
            (pose.y_mm, pose.z_mm, pose.alpha_deg, pose.beta_deg, pose.gamma_deg), comps):
        v = (1 - t) * a + t * b + wobble * np.sin(2 * np.pi * cycles * t + phase)
        values.append((lo + hi) / 2.0 + (hi - lo) / 2.0 * v)
    return transform_from_pose_components(x, *values)


def check_runs_fit(cfg: Config, specs: Iterable[FrameSpec], source: str) -> None:
    """With runs: raise ConfigError (naming ``source``) unless every unit's fixed camera fits its
    markers at every frame of ``specs`` (the plan) it takes."""
    static, fit, seed = static_scene(cfg), ImageFit.of(cfg), cfg.dataset.seed
    for spec in specs:
        lens = unit_lens(cfg.camera_units, seed, spec.unit)
        try:
            cam_from_d, focal, _, _ = unit_camera(cfg.camera, cfg.pose, cfg.runs, seed, lens, static, fit)
        except ConfigError as exc:
            raise ConfigError(f"{source}: {exc}; lower focal_px, raise distance_mm or narrow [pose]") from None
        if spec.run >= 0:
            t = run_time(cfg.runs, cfg.dataset.frames, spec.run, spec.run_frame)
            d_from_b = run_pose(cfg.pose, cfg.runs, seed, spec.run, t)
        else:
            d_from_b = sample_pose(cfg.pose, rng_for(seed, STREAM_REPEAT_GEOMETRY, spec.pose_index))
        cap = largest_fitting_focal(fit, cam_from_d, markers_in_d(static, d_from_b), lens)
        if cap < focal:
            raise ConfigError(f"{source}: [runs] frames_per_run: frame {spec.frame_id} of camera unit {spec.unit} "
                              f"puts markers within {cfg.camera.margin_px:g} px of the border at the unit's "
                              f"{focal:.0f} px (largest that fits: {cap:.0f} px); narrow [pose] or lower focal_px")
