"""Image signal processor stages after the sensor (pure numpy + OpenCV), in the order a camera
applies them: black level -> white balance (on the mosaic) -> demosaic (``core.demosaic``) ->
colour correction -> digital gain -> tone curve -> denoise -> sharpen -> encoding.

Units: raw DN in, "camera linear" floats in [0, 1] (1 = the green channel's saturation) between
the stages, 8-bit display RGB out. Each stage is one pure function; ``core.camera_chain`` strings
them together.
"""
from __future__ import annotations

from functools import lru_cache

from dockfactory.core.cv import cv2
import numpy as np

from dockfactory.core.cfa import channel_map

TONE_CURVES = ("srgb", "gamma22")
DENOISERS = ("off", "bilateral")
JPEG_SUBSAMPLING = ("420", "444")
TONE_LUT_LEVELS = 1 << 16


def normalise_raw(raw_dn: np.ndarray, black_level_dn: float, white_dn: float) -> np.ndarray:
    """``raw_dn: (H, W)`` integer DN -> ``(H, W) float32`` (DN - black) / (white - black): 0 at the
    black level, 1 at ``white_dn`` (the DN of the saturation capacity); not clipped, so the
    noise around black keeps its zero mean."""
    if white_dn <= black_level_dn:
        raise ValueError(f"white level {white_dn} must be above the black level {black_level_dn}")
    out = raw_dn.astype(np.float32)
    out -= np.float32(black_level_dn)
    out *= np.float32(1.0 / (white_dn - black_level_dn))
    return out


def white_balance_mosaic(raw: np.ndarray, pattern: str, gains) -> np.ndarray:
    """``raw: (H, W) float32`` mosaic times the gain of each pixel's channel; ``gains``: (R, G, B)
    positive finite. Returns a new ``(H, W) float32`` array."""
    g = np.asarray(gains, dtype=np.float32)
    if g.shape != (3,) or not np.all(np.isfinite(g)) or np.any(g <= 0):
        raise ValueError(f"white balance gains must be 3 positive finite numbers, got {gains!r}")
    return raw * g[channel_map(pattern, *raw.shape)]


def white_balance_rgb(rgb: np.ndarray, gains) -> np.ndarray:
    """``rgb: (H, W, 3) float32`` times per-channel ``gains`` (R, G, B): a three-chip sensor's white
    balance."""
    g = np.asarray(gains, dtype=np.float32)
    if g.shape != (3,) or not np.all(np.isfinite(g)) or np.any(g <= 0):
        raise ValueError(f"white balance gains must be 3 positive finite numbers, got {gains!r}")
    return rgb * g


def colour_correct(rgb: np.ndarray, ccm: np.ndarray) -> np.ndarray:
    """``rgb: (H, W, 3) float32`` white-balanced camera RGB -> linear sRGB primaries:
    out = ccm @ rgb per pixel, ``ccm: (3, 3)`` (rows sum to 1, so a neutral stays neutral)."""
    m = np.asarray(ccm, dtype=np.float32)
    if m.shape != (3, 3) or not np.all(np.isfinite(m)):
        raise ValueError(f"colour-correction matrix must be a finite (3, 3), got shape {m.shape}")
    return cv2.transform(np.ascontiguousarray(rgb, dtype=np.float32), m)


@lru_cache(maxsize=4)
def _tone_lut(curve: str) -> np.ndarray:
    x = np.arange(TONE_LUT_LEVELS, dtype=np.float64) / (TONE_LUT_LEVELS - 1)
    if curve == "srgb":
        y = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    else:
        y = np.power(x, 1 / 2.2)
    lut = np.clip(np.rint(y * 255.0), 0, 255).astype(np.uint8)
    lut.flags.writeable = False
    return lut


def tone_map(linear: np.ndarray, curve: str) -> np.ndarray:
    """``linear: (H, W, 3) float32`` display-linear RGB, clipped to [0, 1] -> ``(H, W, 3) uint8``
    through the tone curve ``curve`` ("srgb": IEC 61966-2-1; "gamma22": a pure 1/2.2 power),
    looked up on 65536 levels (a step of 1.5e-5 of full scale, far below one output level)."""
    if curve not in TONE_CURVES:
        raise ValueError(f"tone curve must be one of {', '.join(TONE_CURVES)}, got {curve!r}")
    idx = np.clip(linear, 0.0, 1.0) * np.float32(TONE_LUT_LEVELS - 1)
    return _tone_lut(curve)[np.rint(idx).astype(np.int32)]


def denoise(image: np.ndarray, method: str) -> np.ndarray:
    """``image: (H, W, 3) uint8`` through the ISP's denoiser: "off", or "bilateral" (OpenCV,
    5 px diameter, colour sigma 12 levels, space sigma 2 px: an edge-keeping smoother)."""
    if method not in DENOISERS:
        raise ValueError(f"denoise must be one of {', '.join(DENOISERS)}, got {method!r}")
    if method == "off":
        return image
    return cv2.bilateralFilter(image, 5, 12.0, 2.0)


def unsharp_mask(image: np.ndarray, amount: float, sigma_px: float) -> np.ndarray:
    """``image: (H, W, 3) uint8`` sharpened: image + amount * (image - Gaussian(image, sigma_px)),
    rounded and clipped to 8 bits; ``amount`` 0 returns the image unchanged."""
    if not (np.isfinite(amount) and amount >= 0):
        raise ValueError(f"sharpen amount must be >= 0, got {amount}")
    if amount == 0:
        return image
    if not (np.isfinite(sigma_px) and sigma_px > 0):
        raise ValueError(f"sharpen sigma must be > 0 px, got {sigma_px}")
    blurred = cv2.GaussianBlur(image, (0, 0), sigma_px)
    return cv2.addWeighted(image, 1.0 + amount, blurred, -amount, 0.0)


def jpeg_round_trip(image: np.ndarray, quality: int, subsampling: str = "420") -> np.ndarray:
    """``image: (H, W, 3) uint8`` RGB as a JPEG of ``quality`` (1-100) with chroma ``subsampling``
    ("420": half resolution in both directions, what most cameras and libjpeg's default write;
    "444": full resolution) decodes (OpenCV's libjpeg)."""
    if subsampling not in JPEG_SUBSAMPLING:
        raise ValueError(f"JPEG subsampling must be one of {', '.join(JPEG_SUBSAMPLING)}, got {subsampling!r}")
    params = [cv2.IMWRITE_JPEG_QUALITY, int(quality)]
    if subsampling == "444":
        params += [cv2.IMWRITE_JPEG_SAMPLING_FACTOR, cv2.IMWRITE_JPEG_SAMPLING_FACTOR_444]
    ok, buf = cv2.imencode(".jpg", cv2.cvtColor(image, cv2.COLOR_RGB2BGR), params)
    if not ok:
        raise RuntimeError("JPEG encoding failed")
    return cv2.cvtColor(cv2.imdecode(buf, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
