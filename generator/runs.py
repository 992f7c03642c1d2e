"""Docking runs: frames i * per .. (i + 1) * per - 1 of the main frames form run i, taken by one
camera unit whose camera and zoom stay fixed (``unit_camera``) while B approaches A on a smooth
trajectory (``run_pose``).
"""
from __future__ import annotations

import itertools
from collections.abc import Iterable
from functools import lru_cache

import numpy as np

from dockfactory.core.config import Config, ConfigError
from dockfactory.core.geometry import transform_from_pose_components
from dockfactory.core.scene import FrameSpec
from dockfactory.generator.camera_units import largest_fitting_focal, unit_lens
from dockfactory.generator.draws import (
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


def run_count(cfg: Config) -> int:
    """Docking runs of the main frames (0 without runs)."""
    per = cfg.runs.frames_per_run
    return 0 if per == 0 else -(-cfg.dataset.frames // per)


def run_length(cfg: Config, run: int) -> int:
    per = cfg.runs.frames_per_run
    return min(per, cfg.dataset.frames - run * per)


def _pose_box_corners(cfg: Config) -> list[np.ndarray]:
    """d_from_b at the 64 corners of the poses a unit may see (runs and repeatability poses)."""
    p = cfg.pose
    xs = (min(cfg.runs.x_end_mm[0], p.x_mm[0]), p.x_mm[1])
    return [transform_from_pose_components(*v) for v in itertools.product(
        xs, p.y_mm, p.z_mm, p.alpha_deg, p.beta_deg, p.gamma_deg)]


@lru_cache(maxsize=256)
def unit_camera(cfg: Config, unit: int):
    """With runs: the fixed camera of a unit, (cam_from_d, focal_px, eye, target). Its zoom fits
    the markers at every corner of the pose ranges. Raises ConfigError (no source) if none fits."""
    rng = rng_for(cfg.dataset.seed, STREAM_UNIT_CAMERA, unit)
    cam_from_d, eye, target = aim_camera(cfg, rng, (cfg.runs.x_end_mm[0] + cfg.pose.x_mm[1]) / 2.0)
    static, lens = static_scene(cfg), unit_lens(cfg, unit)
    cap = min(largest_fitting_focal(cfg, cam_from_d, markers_in_d(static, t), lens) for t in _pose_box_corners(cfg))
    f_lo, f_hi = cfg.camera.focal_px[0], min(cfg.camera.focal_px[1], cap)
    if f_hi < f_lo:
        raise ConfigError(f"[camera] focal_px: camera unit {unit} cannot fit the markers of a whole docking run "
                          f"at {f_lo:g} px (largest that fits: {cap:.0f} px)")
    return cam_from_d, float(f_lo + rng.uniform() * (f_hi - f_lo)), eye, target


@lru_cache(maxsize=4096)
def _run_drift(cfg: Config, run: int) -> tuple:
    """A run's end gap and, for Y, Z, alpha, beta, gamma: (start, end, wobble, cycles, phase)."""
    rng = rng_for(cfg.dataset.seed, STREAM_RUN, run)
    x_end = uniform(rng, cfg.runs.x_end_mm)
    comps = tuple((float(rng.uniform(-RUN_DRIFT, RUN_DRIFT)), float(rng.uniform(-RUN_DRIFT, RUN_DRIFT)),
                   float(rng.uniform(-RUN_WOBBLE, RUN_WOBBLE)), float(rng.uniform(0.3, 1.5)),
                   float(rng.uniform(0.0, 2 * np.pi))) for _ in range(5))
    return x_end, comps


def run_pose(cfg: Config, run: int, run_frame: int) -> np.ndarray:
    """d_from_b of frame ``run_frame`` of docking run ``run``: frames evenly spaced in time t in
    [0, 1]; X falls from the top of [pose] x_mm to the run's end gap with a smooth (cosine) speed
    profile; Y, Z and the angles drift from a start to an end value with a slow sine on top,
    inside their ranges."""
    n = run_length(cfg, run)
    t = run_frame / (n - 1) if n > 1 else 0.0
    x_end, comps = _run_drift(cfg, run)
    x = x_end + (cfg.pose.x_mm[1] - x_end) * 0.5 * (1.0 + np.cos(np.pi * t))
    values = []
    for (lo, hi), (a, b, wobble, cycles, phase) in zip(
            (cfg.pose.y_mm, cfg.pose.z_mm, cfg.pose.alpha_deg, cfg.pose.beta_deg, cfg.pose.gamma_deg), comps):
        v = (1 - t) * a + t * b + wobble * np.sin(2 * np.pi * cycles * t + phase)
        values.append((lo + hi) / 2.0 + (hi - lo) / 2.0 * v)
    return transform_from_pose_components(x, *values)


def check_runs_fit(cfg: Config, specs: Iterable[FrameSpec], source: str) -> None:
    """With runs: every unit's fixed camera fits its markers at every frame of ``specs`` (the
    plan) it takes."""
    static = static_scene(cfg)
    for spec in specs:
        try:
            cam_from_d, focal, _, _ = unit_camera(cfg, spec.unit)
        except ConfigError as exc:
            raise ConfigError(f"{source}: {exc}; lower focal_px, raise distance_mm or narrow [pose]") from None
        d_from_b = run_pose(cfg, spec.run, spec.run_frame) if spec.run >= 0 else \
            sample_pose(cfg, rng_for(cfg.dataset.seed, STREAM_REPEAT_GEOMETRY, spec.pose_index))
        cap = largest_fitting_focal(cfg, cam_from_d, markers_in_d(static, d_from_b), unit_lens(cfg, spec.unit))
        if cap < focal:
            raise ConfigError(f"{source}: [runs] frames_per_run: frame {spec.frame_id} of camera unit {spec.unit} "
                              f"puts markers within {cfg.camera.margin_px:g} px of the border at the unit's "
                              f"{focal:.0f} px (largest that fits: {cap:.0f} px); narrow [pose] or lower focal_px")
