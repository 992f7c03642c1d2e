"""Camera units: the lens of each unit (principal point, distortion, chromatic aberration, depth of
field, JPEG), drawn once per unit from [camera_units] with the dataset seed; the units dealt to
frames or runs; the frame's camera through a unit's lens and the largest focal that keeps the
markers inside its image.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from dockfactory.core.config import Config, ConfigError
from dockfactory.core.distortion import distort_normalized
from dockfactory.core.geometry import transform_points
from dockfactory.core.scene import CameraModel, mat4, vec
from dockfactory.core.camera_chain import configured_sensor
from dockfactory.core.emva import EmvaSensor
from dockfactory.generator.draws import STREAM_UNIT_LENS, STREAM_UNIT_SENSOR, STREAM_UNITS, rng_for, uniform


@dataclass(frozen=True)
class UnitLens:
    """The lens of one camera unit, drawn once from [camera_units] with the dataset seed."""
    unit: int
    principal_offset: tuple[float, float]   # principal point - image centre, px
    distortion: tuple[float, ...]           # k1, k2, p1, p2, k3 (OpenCV order)
    aberration_px: tuple[float, float]      # red, blue vs green at the farthest image corner
    f_number: float                         # 0: no depth of field
    focus_error_mm: float
    jpeg_quality: int                       # 0: no JPEG encoding

    def is_ideal(self) -> bool:
        return not any(self.distortion) and not any(self.principal_offset)


@lru_cache(maxsize=256)
def unit_lens(cfg: Config, unit: int) -> UnitLens:
    """Lens of camera unit ``unit``: a function of (config, seed, unit); every value is drawn, in a
    fixed order, whether its feature is on or not."""
    u = cfg.camera_units
    rng = rng_for(cfg.dataset.seed, STREAM_UNIT_LENS, unit)
    offset = (uniform(rng, u.principal_offset_x_px), uniform(rng, u.principal_offset_y_px))
    k1, k2, k3, p1, p2 = (uniform(rng, getattr(u, key)) for key in ("k1", "k2", "k3", "p1", "p2"))
    aberration = (uniform(rng, u.aberration_red_px), uniform(rng, u.aberration_blue_px))
    f_number, focus_error = uniform(rng, u.f_number), uniform(rng, u.focus_error_mm)
    quality = int(rng.integers(u.jpeg_quality[0], u.jpeg_quality[1] + 1))
    dof = u.depth_of_field
    return UnitLens(unit, offset, (k1, k2, p1, p2, k3), aberration, f_number if dof else 0.0,
                    focus_error if dof else 0.0, quality if u.jpeg else 0)


@dataclass(frozen=True)
class UnitSensor:
    """The colour sensor and ISP of one camera unit ([sensor] presets), drawn once with the
    dataset seed: ``seed`` is the seed of its fixed patterns (DSNU, PRNU)."""
    unit: int
    preset: str
    sensor: EmvaSensor
    cfa: str
    demosaic: str
    crosstalk: float
    sharpen: float
    seed: int


@lru_cache(maxsize=256)
def unit_sensor(cfg: Config, unit: int) -> UnitSensor | None:
    """Colour sensor of camera unit ``unit``: the per-unit lists' item ``unit % len``, the draws
    from the unit's own stream (crosstalk, sharpening, pattern seed, in that order); None without
    [sensor] presets (the three-chip noise model)."""
    s = cfg.sensor
    if not s.presets:
        return None
    rng = rng_for(cfg.dataset.seed, STREAM_UNIT_SENSOR, unit)
    crosstalk, sharpen = uniform(rng, s.crosstalk), uniform(rng, s.sharpen)
    seed = int(rng.integers(2**62))
    name = s.presets[unit % len(s.presets)]
    return UnitSensor(unit, name, configured_sensor(name, s.overrides, s.adc_bits), s.cfa[unit % len(s.cfa)],
                      s.demosaic[unit % len(s.demosaic)], crosstalk, sharpen, seed)


def balanced_units(seed: int, n: int, count: int, key: int) -> np.ndarray:
    """Camera unit of each of ``n`` items (frames or runs): a seeded permutation dealt round robin,
    so the units' counts differ by at most one. (n,) int."""
    out = np.zeros(n, dtype=int)
    if count > 1:
        out[rng_for(seed, STREAM_UNITS, key).permutation(n)] = np.arange(n) % count
    return out


def repeat_unit(cfg: Config) -> int:
    """The one camera unit that takes every repeatability capture."""
    count = cfg.camera_units.count
    return 0 if count == 1 else int(rng_for(cfg.dataset.seed, STREAM_UNITS, 2).integers(count))


def principal_point(cfg: Config, lens: UnitLens) -> tuple[float, float]:
    return ((cfg.image.width - 1) / 2.0 + lens.principal_offset[0],
            (cfg.image.height - 1) / 2.0 + lens.principal_offset[1])


def largest_fitting_focal(cfg: Config, cam_from_d: np.ndarray, points_d: np.ndarray,
                          lens: UnitLens | None = None) -> float:
    """Largest focal (px) that keeps every marker disc ``margin_px`` inside the image, through the
    unit's lens (principal point and distortion; pixel offsets from the principal point scale with
    the focal, so the bound is closed-form)."""
    pc = transform_points(cam_from_d, points_d)
    z = pc[:, 2]
    if np.any(z <= 0):
        return 0.0
    r = cfg.markers.diameter_mm / 2.0
    if lens is None or lens.is_ideal():
        half_w = cfg.image.width / 2.0 - cfg.camera.margin_px
        half_h = cfg.image.height / 2.0 - cfg.camera.margin_px
        ext_x = (np.abs(pc[:, 0]) + r) / z
        ext_y = (np.abs(pc[:, 1]) + r) / z
        return float(min(half_w / ext_x.max(), half_h / ext_y.max()))
    corners = np.concatenate([(pc[:, :2] + r * np.array(sign)) / z[:, None]
                              for sign in ((1, 1), (1, -1), (-1, 1), (-1, -1))])
    xd = distort_normalized(corners, lens.distortion)
    pp, size, margin = principal_point(cfg, lens), (cfg.image.width, cfg.image.height), cfg.camera.margin_px
    caps = [np.inf]
    for axis in (0, 1):
        room_hi, room_lo = size[axis] - 0.5 - margin - pp[axis], pp[axis] + 0.5 - margin
        if min(room_hi, room_lo) <= 0:
            return 0.0
        d = xd[:, axis]
        caps += list(room_hi / d[d > 0]) + list(room_lo / -d[d < 0])
    return float(min(caps))


def camera_model(cfg: Config, lens: UnitLens, focal_px: float, cam_from_d, eye, target) -> CameraModel:
    """The frame's camera: pinhole K with the unit's principal point, plus the unit's lens."""
    distance = float(np.linalg.norm(np.asarray(eye) - np.asarray(target)))
    return CameraModel(cfg.image.width, cfg.image.height, float(focal_px), principal_point(cfg, lens),
                       mat4(cam_from_d), vec(target), distance, lens.unit, lens.distortion, lens.aberration_px,
                       lens.f_number, distance + lens.focus_error_mm if lens.f_number > 0 else 0.0,
                       cfg.camera_units.sensor_width_mm, lens.jpeg_quality, cfg.camera_units.jpeg_subsampling)


def check_lenses(cfg: Config, source: str) -> None:
    """Every unit's lens is usable at the smallest focal (no fold, a bounded render canvas)."""
    for unit in range(cfg.camera_units.count):
        lens = unit_lens(cfg, unit)
        cam = camera_model(cfg, lens, cfg.camera.focal_px[0], np.eye(4), np.zeros(3), np.array([0, 0, 1.0]))
        try:
            cam.canvas()
        except ValueError as exc:
            raise ConfigError(f"{source}: [camera_units] k1: camera unit {unit} (k1, k2, p1, p2, k3 = "
                              f"{', '.join(f'{v:g}' for v in lens.distortion)}) at {cam.focal_px:g} px: "
                              f"{exc}") from None
