"""A colour camera after the lens: colour filters -> EMVA 1288 sensor -> ISP (pure numpy/OpenCV).

``develop`` takes the exposure-normalised linear image (linear sRGB primaries, 1.0 = the level
that fills the green pixels' full well) and returns what the camera delivers (8-bit RGB) and the
raw frame it read out (DN). The stages, in the order light travels: colour filters (a 3x3 camera
response, ``camera_response``, sampled through the CFA ``pattern`` of ``core.cfa``), the sensor
(``core.emva.expose``) and the ISP (``core.isp``; demosaic ``core.demosaic``; colour correction with the
inverse of the true camera response). JPEG encoding is the lens unit's (``isp.jpeg_round_trip``).

Why and how: docs/colour_cameras.md, "The camera chain".
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

from dockfactory.core.cv import cv2
import numpy as np

from dockfactory.core import isp
from dockfactory.core.cfa import PATTERNS, apply_crosstalk, mosaic, pattern_sites
from dockfactory.core.demosaic import DEMOSAICS, demosaic
from dockfactory.core.emva import EmvaSensor, expose, fixed_patterns, with_adc_bits
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


def white_balance_gains(response: np.ndarray, wb_error=(0.0, 0.0)) -> np.ndarray:
    """(3,) the gains the ISP applies: the exact ones (1 / the response to a neutral, so a grey
    comes out grey) with the red and blue gains off by ``wb_error`` (relative)."""
    exact = 1.0 / response.sum(axis=1)
    return exact * np.array([1.0 + wb_error[0], 1.0, 1.0 + wb_error[1]])


def colour_correction_matrix(response: np.ndarray) -> np.ndarray:
    """(3, 3) the ISP's colour correction: the inverse of the white-balanced response (rows sum
    to 1)."""
    return np.linalg.inv(response / response.sum(axis=1, keepdims=True))


def sense(linear: np.ndarray, chain: ColourChain, rng: np.random.Generator) -> np.ndarray:
    """``linear: (H, W, 3) float32`` exposure-normalised linear sRGB -> raw frame in DN, uint16:
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


def process(raw_dn: np.ndarray, chain: ColourChain, gain_ev: float = 0.0) -> np.ndarray:
    """The ISP: raw DN (``sense``'s output) -> ``(H, W, 3) uint8`` display RGB. ``gain_ev``: the
    digital gain (stops) applied in linear before the tone curve."""
    response = camera_response(chain.sensor, chain.crosstalk)
    gains = white_balance_gains(response, chain.wb_error)
    x = isp.normalise_raw(raw_dn, chain.sensor.black_level_dn, white_dn(chain.sensor))
    if chain.cfa != "none":
        rgb = demosaic(isp.white_balance_mosaic(x, chain.cfa, gains), chain.cfa, chain.demosaic)
    else:
        rgb = isp.white_balance_rgb(x, gains)
    if chain.colour_correction:
        rgb = isp.colour_correct(rgb, colour_correction_matrix(response))
    if gain_ev:
        rgb *= np.float32(2.0 ** gain_ev)
    out = isp.tone_map(rgb, chain.tone)
    out = isp.denoise(out, chain.denoise)
    return isp.unsharp_mask(out, chain.sharpen_amount, chain.sharpen_sigma_px)


def develop(linear: np.ndarray, chain: ColourChain, rng: np.random.Generator,
            gain_ev: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """(delivered ``(H, W, 3) uint8`` RGB, raw frame in DN) of one exposure: ``sense`` then
    ``process``. ``rng``: the frame's noise stream."""
    chain.check()
    if linear.ndim != 3 or linear.shape[2] != 3:
        raise ValueError(f"linear image must be (H, W, 3), got {linear.shape}")
    raw = sense(linear, chain, rng)
    return process(raw, chain, gain_ev), raw


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


def grey_world_gains(raw: np.ndarray, pattern: str) -> np.ndarray:
    """(3,) white-balance gains of a normalised mosaic ``raw`` (H, W) float32 by the grey-world
    assumption: each channel's mean brought to green's (a scene of mostly neutral surfaces)."""
    means = np.array([raw[dy::2, dx::2].mean() for dy in (0, 1) for dx in (0, 1)])
    chans = [c for _, _, c in pattern_sites(pattern)]
    per = np.array([means[[i for i, c in enumerate(chans) if c == k]].mean() for k in range(3)])
    if not np.all(per > 0):
        raise ValueError(f"raw frame: a colour channel has no signal (means {per.round(6).tolist()})")
    return per[1] / per


def develop_raw(raw_dn: np.ndarray, pattern: str, black_dn: float, white_dn: float, method: str,
                gains=None) -> np.ndarray:
    """A raw mosaic read from a camera, (H, W) integer DN, as 8-bit sRGB (H, W, 3) uint8: black
    level and white level (DN), white balance (``gains`` (R, G, B), else grey world), demosaic
    ``method``, sRGB tone curve. No colour correction: a camera's own matrix is not known here."""
    if raw_dn.ndim != 2:
        raise ValueError(f"a raw frame is one channel (H, W), got shape {raw_dn.shape}")
    x = isp.normalise_raw(raw_dn, black_dn, white_dn)
    g = grey_world_gains(x, pattern) if gains is None else np.asarray(gains, dtype=float)
    rgb = demosaic(isp.white_balance_mosaic(x, pattern, g), pattern, method)
    return isp.tone_map(rgb, "srgb")
