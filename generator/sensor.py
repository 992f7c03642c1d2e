"""Camera model applied to the linear render (pure numpy + OpenCV).

linear radiance -> auto exposure (mean luminance of the central region to 0.18) -> lens:
vignetting and veiling glare (an energy-conserving wide blur of part of the light) -> exposure
offset (2^ev; several stops down in low light) -> sensor: electrons (full well at 1.0, clipped),
shot noise, read noise -> ADC (``adc_bits``) -> digital gain (2^gain_ev) -> sRGB, 8 bit.
Shot noise uses the Gaussian approximation N(e, e), accurate above a few electrons.
"""
from __future__ import annotations

from functools import lru_cache

import cv2
import numpy as np

from dockfactory.core.scene import SensorParams

TARGET_GREY = 0.18
LUMA = np.array([0.2126, 0.7152, 0.0722], dtype=np.float32)


def auto_exposure_scale(linear: np.ndarray) -> float:
    """Scale that brings the mean luminance of the central 60 % of the image to 0.18.

    ``linear``: (H, W, 3) float32. Luminance is clipped at 4 so a lamp in view does not darken
    the frame.
    """
    h, w = linear.shape[:2]
    crop = linear[int(0.2 * h):int(0.8 * h), int(0.2 * w):int(0.8 * w)]
    lum = np.minimum(crop @ LUMA, 4.0)
    mean = float(lum.mean())
    return TARGET_GREY / max(mean, 1e-6)


@lru_cache(maxsize=4)
def _radius2(h: int, w: int) -> np.ndarray:
    y, x = np.mgrid[0:h, 0:w].astype(np.float32)
    r2 = ((x - (w - 1) / 2) ** 2 + (y - (h - 1) / 2) ** 2) / (((w - 1) / 2) ** 2 + ((h - 1) / 2) ** 2)
    return r2[..., None]


@lru_cache(maxsize=4)
def _srgb_lut(levels: int) -> np.ndarray:
    x = np.arange(levels, dtype=np.float64) / (levels - 1)
    s = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    return np.clip(np.rint(s * 255.0), 0, 255).astype(np.uint8)


VEIL_SOURCE_CAP = 64.0  # radiance (x mid-grey 0.18 -> 11.5) above which a source adds no more veil


def veiling_glare(linear: np.ndarray, amount: float) -> np.ndarray:
    """L + amount * (wide_blur(min(L, cap)) - min(L, cap)): light scattered in the lens.

    A halo around bright sources and a veil that lowers contrast. The scattered radiance is
    capped (``VEIL_SOURCE_CAP`` x mid-grey) so that a lamp in view washes out its neighbourhood,
    not the whole frame. ``linear``: (H, W, 3) float32, exposure-normalised.
    """
    h, w = linear.shape[:2]
    src = np.minimum(linear, np.float32(VEIL_SOURCE_CAP * TARGET_GREY))
    small = cv2.resize(src, (max(1, w // 8), max(1, h // 8)), interpolation=cv2.INTER_AREA)
    sigma = 0.03 * max(small.shape[:2])
    blurred = cv2.GaussianBlur(small, (0, 0), sigmaX=sigma) * 0.6 + \
        cv2.GaussianBlur(small, (0, 0), sigmaX=4 * sigma) * 0.4
    big = cv2.resize(blurred, (w, h), interpolation=cv2.INTER_LINEAR)
    return linear + np.float32(amount) * (big - src)


def apply_sensor(linear: np.ndarray, p: SensorParams) -> tuple[np.ndarray, dict]:
    """8-bit sRGB image (H, W, 3) uint8 (RGB order) and the values it derived (exposure scale).

    ``linear``: (H, W, 3) float32 scene-linear render.
    """
    if linear.ndim != 3 or linear.shape[2] != 3:
        raise ValueError(f"linear image must be (H, W, 3), got {linear.shape}")
    img = np.nan_to_num(np.array(linear, dtype=np.float32), copy=False, nan=0.0, posinf=0.0, neginf=0.0)
    scale = auto_exposure_scale(img)
    levels = 2 ** p.adc_bits
    lut = _srgb_lut(levels)
    if p.ideal:
        img *= np.float32(scale)
        idx = np.rint(np.clip(img, 0.0, 1.0) * (levels - 1)).astype(np.int32)
        return lut[idx], {"auto_exposure_scale": scale}
    img *= np.float32(scale * 2.0 ** p.exposure_ev)
    if p.vignetting > 0:
        img *= 1.0 - np.float32(p.vignetting) * _radius2(*img.shape[:2])
    if p.bloom > 0:
        img = veiling_glare(img, p.bloom)
    rng = np.random.default_rng(p.noise_seed)
    electrons = np.clip(img, 0.0, 1.0, out=img)
    electrons *= np.float32(p.full_well_e)
    sigma = np.sqrt(electrons + np.float32(p.read_noise_e ** 2))
    sigma *= rng.standard_normal(electrons.shape, dtype=np.float32)
    electrons += sigma
    electrons *= np.float32((levels - 1) / p.full_well_e)
    dn = np.clip(np.rint(electrons, out=electrons), 0, levels - 1, out=electrons)
    if p.gain_ev != 0:
        dn = np.minimum(np.rint(dn * np.float32(2.0 ** p.gain_ev)), levels - 1)
    idx = dn.astype(np.int32)
    return lut[idx], {"auto_exposure_scale": scale}
