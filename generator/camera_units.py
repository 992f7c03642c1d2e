"""Camera units: the lens of each unit (principal point, distortion, pixel aspect, chromatic
aberration, depth of field, JPEG), drawn once per unit from [camera_units] with the dataset seed;
the units dealt to frames or runs; the frame's camera through a unit's lens and the largest focal
that keeps the markers inside its image.

Every function takes the config sections it reads ([camera_units], [sensor], [image]) and the
dataset seed, never the whole config (``ImageFit.of`` picks what the focal fit reads).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from dockfactory.core.config import CameraUnitsConfig, Config, ConfigError, ImageConfig, SensorConfig
from dockfactory.core.distortion import distort_normalized
from dockfactory.core.geometry import transform_points
from dockfactory.core.scene import CameraModel, mat4, vec
from dockfactory.core.camera_chain.colour_sensor import configured_sensor
from dockfactory.core.camera_chain.emva import EmvaSensor
from dockfactory.generator.random_draws import STREAM_UNIT_LENS, STREAM_UNIT_SENSOR, STREAM_UNITS, rng_for, uniform


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
    pixel_aspect: float = 1.0               # fy / fx of the unit's pixels

    def is_ideal(self) -> bool:
        return not any(self.distortion) and not any(self.principal_offset) and self.pixel_aspect == 1.0


@lru_cache(maxsize=256)
def unit_lens(units: CameraUnitsConfig, seed: int, unit: int) -> UnitLens:
    """Lens of camera unit ``unit``: a function of ([camera_units], dataset seed, unit) alone, drawn
    from the unit's STREAM_UNIT_LENS stream; every value is drawn, in a fixed order, whether its
    feature is on or not (principal offset x, y; k1, k2, k3, p1, p2; aberration red, blue;
    f-number, focus error; JPEG quality; pixel aspect)."""
    rng = rng_for(seed, STREAM_UNIT_LENS, unit)
    offset = (uniform(rng, units.principal_offset_x_px), uniform(rng, units.principal_offset_y_px))
    k1, k2, k3, p1, p2 = (uniform(rng, getattr(units, key)) for key in ("k1", "k2", "k3", "p1", "p2"))
    aberration = (uniform(rng, units.aberration_red_px), uniform(rng, units.aberration_blue_px))
    f_number, focus_error = uniform(rng, units.f_number), uniform(rng, units.focus_error_mm)
    quality = int(rng.integers(units.jpeg_quality[0], units.jpeg_quality[1] + 1))
    aspect = uniform(rng, units.pixel_aspect)
    dof = units.depth_of_field
    return UnitLens(unit, offset, (k1, k2, p1, p2, k3), aberration, f_number if dof else 0.0,
                    focus_error if dof else 0.0, quality if units.jpeg else 0, aspect)


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
def unit_sensor(sensor: SensorConfig, seed: int, unit: int) -> UnitSensor | None:
    """Colour sensor of camera unit ``unit``: the per-unit lists of [sensor] give item
    ``unit % len``; the draws come from the unit's STREAM_UNIT_SENSOR stream of the dataset
    ``seed`` (crosstalk, sharpening, pattern seed, in that order). None without [sensor] presets
    (the three-chip noise model)."""
    if not sensor.presets:
        return None
    rng = rng_for(seed, STREAM_UNIT_SENSOR, unit)
    crosstalk, sharpen = uniform(rng, sensor.crosstalk), uniform(rng, sensor.sharpen)
    pattern_seed = int(rng.integers(2**62))
    name = sensor.presets[unit % len(sensor.presets)]
    return UnitSensor(unit, name, configured_sensor(name, sensor.overrides, sensor.adc_bits),
                      sensor.cfa[unit % len(sensor.cfa)], sensor.demosaic[unit % len(sensor.demosaic)],
                      crosstalk, sharpen, pattern_seed)


def balanced_units(seed: int, n: int, count: int, key: int) -> np.ndarray:
    """Camera unit of each of ``n`` items (frames or runs): a seeded permutation dealt round robin,
    so the units' counts differ by at most one. (n,) int."""
    out = np.zeros(n, dtype=int)
    if count > 1:
        out[rng_for(seed, STREAM_UNITS, key).permutation(n)] = np.arange(n) % count
    return out


def repeat_unit(seed: int, count: int) -> int:
    """The one camera unit (of ``count``) that takes every repeatability capture: drawn from the
    dataset ``seed``'s STREAM_UNITS stream, key 2; 0 with a single unit (nothing drawn)."""
    return 0 if count == 1 else int(rng_for(seed, STREAM_UNITS, 2).integers(count))


@dataclass(frozen=True)
class ImageFit:
    """What keeping the markers inside a frame's image reads: the image size ([image], px), the
    margin the marker discs keep from its border ([camera] margin_px, px) and the discs' radius
    ([markers] diameter_mm / 2, mm)."""
    image: ImageConfig
    margin_px: float
    disc_radius_mm: float

    @classmethod
    def of(cls, cfg: Config) -> ImageFit:
        return cls(cfg.image, cfg.camera.margin_px, cfg.markers.diameter_mm / 2.0)


def principal_point(image: ImageConfig, lens: UnitLens) -> tuple[float, float]:
    """The unit's principal point (cx, cy), OpenCV pixels: the image centre
    ((W - 1) / 2, (H - 1) / 2) plus the lens's offset."""
    return ((image.width - 1) / 2.0 + lens.principal_offset[0],
            (image.height - 1) / 2.0 + lens.principal_offset[1])


def largest_fitting_focal(fit: ImageFit, cam_from_d: np.ndarray, points_d: np.ndarray,
                          lens: UnitLens | None = None) -> float:
    """Largest focal (px) that keeps every marker disc (centres ``points_d`` (N, 3) mm in D, seen
    by a camera at ``cam_from_d`` (4, 4)) ``fit.margin_px`` inside the image, through the unit's
    lens (principal point, distortion and pixel aspect; pixel offsets from the principal point
    scale with the focal, so the bound is closed-form). 0 when a marker is behind the camera or
    the principal point leaves no room; an ideal lens (or None) uses the centred pinhole's bound."""
    pc = transform_points(cam_from_d, points_d)
    z = pc[:, 2]
    if np.any(z <= 0):
        return 0.0
    r, image, margin = fit.disc_radius_mm, fit.image, fit.margin_px
    if lens is None or lens.is_ideal():
        half_w = image.width / 2.0 - margin
        half_h = image.height / 2.0 - margin
        ext_x = (np.abs(pc[:, 0]) + r) / z
        ext_y = (np.abs(pc[:, 1]) + r) / z
        return float(min(half_w / ext_x.max(), half_h / ext_y.max()))
    corners = np.concatenate([(pc[:, :2] + r * np.array(sign)) / z[:, None]
                              for sign in ((1, 1), (1, -1), (-1, 1), (-1, -1))])
    xd = distort_normalized(corners, lens.distortion)
    pp, size = principal_point(image, lens), (image.width, image.height)
    caps = [np.inf]
    for axis, aspect in ((0, 1.0), (1, lens.pixel_aspect)):
        room_hi, room_lo = size[axis] - 0.5 - margin - pp[axis], pp[axis] + 0.5 - margin
        if min(room_hi, room_lo) <= 0:
            return 0.0
        d = xd[:, axis] * aspect
        caps += list(room_hi / d[d > 0]) + list(room_lo / -d[d < 0])
    return float(min(caps))


def camera_model(image: ImageConfig, units: CameraUnitsConfig, lens: UnitLens, focal_px: float,
                 cam_from_d, eye, target) -> CameraModel:
    """The frame's camera: K (fx = ``focal_px``, fy = the unit's pixel aspect fx, the unit's
    principal point) at ``cam_from_d`` (4, 4), aimed from ``eye`` at ``target`` ((3,) mm in D),
    plus the unit's lens and the shared body of [camera_units] (sensor width, JPEG chroma
    subsampling)."""
    distance = float(np.linalg.norm(np.asarray(eye) - np.asarray(target)))
    return CameraModel(image.width, image.height, float(focal_px), principal_point(image, lens),
                       mat4(cam_from_d), vec(target), distance, lens.unit, lens.distortion, lens.aberration_px,
                       lens.f_number, distance + lens.focus_error_mm if lens.f_number > 0 else 0.0,
                       units.sensor_width_mm, lens.jpeg_quality, units.jpeg_subsampling, lens.pixel_aspect)


def check_lenses(units: CameraUnitsConfig, image: ImageConfig, seed: int, focal_px: float, source: str) -> None:
    """Raise ConfigError (naming ``source``) unless every unit's lens is usable at ``focal_px``
    (the smallest of [camera] focal_px): no fold, a bounded render canvas."""
    for unit in range(units.count):
        lens = unit_lens(units, seed, unit)
        cam = camera_model(image, units, lens, focal_px, np.eye(4), np.zeros(3), np.array([0, 0, 1.0]))
        try:
            cam.canvas()
        except ValueError as exc:
            raise ConfigError(f"{source}: [camera_units] k1: camera unit {unit} (k1, k2, p1, p2, k3 = "
                              f"{', '.join(f'{v:g}' for v in lens.distortion)}) at {cam.focal_px:g} px: "
                              f"{exc}") from None
