"""The colour sensor of the camera chain: colour filters -> EMVA 1288 sensor (pure numpy/OpenCV).

``sense`` takes the exposure-normalised linear light (linear sRGB primaries, 1.0 = the level that
fills the green pixels' full well) and returns the raw frame the sensor reads out (DN): colour
filters (a 3x3 camera response, ``camera_response``: crosstalk and each channel's quantum
efficiency), sampled through the CFA ``pattern`` of ``cfa`` (or three sensors, ``cfa`` "none"),
then the sensor (``emva.expose``). ``ColourChain`` is one frame's colour camera after the lens
(its sensor's and its ISP's settings); ``configured_sensor`` reads a [sensor] preset.

Why and how: docs/colour_cameras.md, "The camera chain".
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

from dockfactory.core.cv import cv2
import numpy as np

from dockfactory.core.camera_chain.cfa import PATTERNS, apply_crosstalk, mosaic
from dockfactory.core.camera_chain.demosaic import DEMOSAICS
from dockfactory.core.camera_chain.emva import EmvaSensor, expose, fixed_patterns, with_adc_bits
from dockfactory.core.sensor_presets import preset, with_overrides

CFA_CHOICES = ("none",) + PATTERNS


@dataclass(frozen=True)
class ColourChain:
    """One frame's colour camera after the lens. ``sensor``: its EMVA 1288 figures;
    ``unit_seed``: the camera unit's seed of the fixed patterns (DSNU, PRNU); ``crosstalk``:
    share of each channel's light that reaches each of the other two; ``wb_error``: the white
    balance's relative error of the red and blue gains this frame (0 = exact)."""
    cfa: str
    sensor: EmvaSensor
    unit_seed: int
    crosstalk: float
    exposure_s: float
    demosaic: str
    wb_error: tuple[float, float]
    colour_correction: bool
    tone: str
    denoise: str
    sharpen_amount: float
    sharpen_sigma_px: float

    def check(self) -> None:
        """ValueError naming the field and value of anything the chain cannot run."""
        if self.cfa not in CFA_CHOICES:
            raise ValueError(f"cfa must be one of {', '.join(CFA_CHOICES)}, got {self.cfa!r}")
        if self.demosaic not in DEMOSAICS:
            raise ValueError(f"demosaic must be one of {', '.join(DEMOSAICS)}, got {self.demosaic!r}")
        if not 0.0 <= self.crosstalk < 1.0 / 3.0:
            raise ValueError(f"crosstalk must be in [0, 1/3), got {self.crosstalk}")
        if not all(-0.9 < e < 10.0 for e in self.wb_error):
            raise ValueError(f"wb_error must be in (-0.9, 10), got {self.wb_error}")
        if not (np.isfinite(self.exposure_s) and self.exposure_s >= 0):
            raise ValueError(f"exposure_s must be >= 0, got {self.exposure_s}")


@lru_cache(maxsize=16)
def _response(qe: tuple, crosstalk: float) -> np.ndarray:
    mix = np.full((3, 3), crosstalk) + np.eye(3) * (1.0 - 3.0 * crosstalk)
    rel = np.asarray(qe, dtype=np.float64) / qe[1]
    out = rel[:, None] * mix
    out.flags.writeable = False
    return out


def camera_response(sensor: EmvaSensor, crosstalk: float) -> np.ndarray:
    """(3, 3) float64 R: camera channel i's signal (fraction of the green full well) per unit of
    linear sRGB channel j, R = diag(QE / QE_green) @ X, X = crosstalk to each other channel,
    1 - 2 crosstalk kept (rows of X sum to 1)."""
    return _response(tuple(float(q) for q in sensor.quantum_efficiency), float(crosstalk))


def sense(linear: np.ndarray, chain: ColourChain, rng: np.random.Generator) -> np.ndarray:
    """The stage: ``linear: (H, W, 3) float32`` exposure-normalised linear sRGB -> raw frame, DN, uint16:
    ``(H, W)`` through a CFA, ``(H, W, 3)`` for a three-chip sensor (``cfa`` "none": three sensors,
    each with its own fixed patterns, exposed as one (3H, W) frame)."""
    cam = apply_crosstalk(linear, camera_response(chain.sensor, chain.crosstalk))
    np.maximum(cam, 0.0, out=cam)
    cam *= np.float32(chain.sensor.saturation_e)
    h, w = cam.shape[:2]
    if chain.cfa != "none":
        patterns = fixed_patterns(chain.sensor, chain.unit_seed, h, w)
        return expose(mosaic(cam, chain.cfa), chain.sensor, chain.exposure_s, rng, patterns)
    planes = np.concatenate(cv2.split(cam), axis=0)                      # (3H, W): R, G, B sensors
    patterns = fixed_patterns(chain.sensor, chain.unit_seed, 3 * h, w)
    raw = expose(planes, chain.sensor, chain.exposure_s, rng, patterns)
    return cv2.merge([raw[:h], raw[h:2 * h], raw[2 * h:]])


def white_dn(sensor: EmvaSensor) -> float:
    """The DN of a green pixel at its saturation capacity (the ISP's white level)."""
    top = float(2 ** sensor.adc_bits - 1)
    return min(top, sensor.black_level_dn + sensor.gain_dn_per_e * sensor.saturation_e)


QE_KEYS = ("qe_red", "qe_green", "qe_blue")
OVERRIDE_KEYS = ("dark_noise_e", "saturation_e", "gain_dn_per_e", "dark_current_e_per_s", "dsnu_dn",
                 "prnu_pct", "black_level_dn") + QE_KEYS


def configured_sensor(name: str, overrides, adc_bits: int) -> EmvaSensor:
    """The EMVA 1288 sensor of preset ``name`` read out at ``adc_bits`` (``emva.with_adc_bits``),
    then with ``overrides`` ((key, value) pairs of :data:`OVERRIDE_KEYS`; DN figures at
    ``adc_bits``; ``qe_red`` etc. replace one channel's quantum efficiency). ValueError naming
    the preset, key or value."""
    sensor = with_adc_bits(preset(name), adc_bits)
    values = dict(overrides)
    unknown = [k for k in values if k not in OVERRIDE_KEYS]
    if unknown:
        raise ValueError(f"unknown key {unknown[0]!r} (known: {', '.join(OVERRIDE_KEYS)})")
    qe = list(sensor.quantum_efficiency)
    for i, key in enumerate(QE_KEYS):
        qe[i] = values.pop(key, qe[i])
    return with_overrides(sensor, {**values, "quantum_efficiency": tuple(qe)}, f"sensor preset {name!r}")


