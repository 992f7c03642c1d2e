"""The light before the sensor, after the lens: auto exposure, exposure offset, vignetting and
veiling glare (pure numpy + OpenCV).

In: the delivered image's scene-linear radiance ``(H, W, 3) float32``. Out: the exposure-normalised
linear image the sensor integrates (1.0 fills the full well; linear sRGB primaries). Auto exposure
brings the mean luminance of the central region to 0.18 (``TARGET_GREY``); the frame's exposure
offset (2^ev; several stops down in low light), the lens's vignetting and its veiling glare (an
energy-conserving wide blur of part of the light) follow, in that order (``light_on_sensor``).
"""
from __future__ import annotations

from functools import lru_cache

from dockfactory.core.cv import cv2
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


def light_on_sensor(img: np.ndarray, p: SensorParams, scale: float) -> np.ndarray:
    """The stage: ``img`` (H, W, 3) float32 scene-linear radiance (scaled in place) -> the
    exposure-normalised linear light on the sensor, (H, W, 3) float32. ``scale``: the frame's
    :func:`auto_exposure_scale`. An ideal camera (``p.ideal``) takes the auto exposure only; any
    other the exposure offset 2^``exposure_ev``, then vignetting, then veiling glare (``bloom``)."""
    if p.ideal:
        img *= np.float32(scale)
        return img
    img *= np.float32(scale * 2.0 ** p.exposure_ev)
    if p.vignetting > 0:
        img *= 1.0 - np.float32(p.vignetting) * _radius2(*img.shape[:2])
    if p.bloom > 0:
        img = veiling_glare(img, p.bloom)
    return img
