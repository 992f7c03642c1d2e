"""The ISP stage of the camera chain: raw DN -> 8-bit display RGB (pure numpy + OpenCV).

A colour camera's ISP (``process``), in the order it applies its stages: black level -> white
balance (on the mosaic) -> demosaic (``demosaic``) -> colour correction -> digital gain -> tone
curve -> denoise -> sharpen. Units: raw DN in, "camera linear" floats in [0, 1] (1 = the green
channel's saturation) between the stages, 8-bit display RGB out. ``develop_raw`` develops a raw
frame read from a real camera; ``display_from_dn`` is the plain sensor's ISP (digital gain, sRGB).
"""
from __future__ import annotations

from functools import lru_cache

from dockfactory.core.cv import cv2
import numpy as np

from dockfactory.core.camera_chain.cfa import channel_map, pattern_sites
from dockfactory.core.camera_chain.colour_sensor import ColourChain, camera_response, white_dn
from dockfactory.core.camera_chain.demosaic import demosaic

TONE_CURVES = ("srgb", "gamma22")
DENOISERS = ("off", "bilateral")
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


def white_balance_gains(response: np.ndarray, wb_error=(0.0, 0.0)) -> np.ndarray:
    """(3,) the gains the ISP applies: the exact ones (1 / the response to a neutral, so a grey
    comes out grey) with the red and blue gains off by ``wb_error`` (relative)."""
    exact = 1.0 / response.sum(axis=1)
    return exact * np.array([1.0 + wb_error[0], 1.0, 1.0 + wb_error[1]])


def colour_correction_matrix(response: np.ndarray) -> np.ndarray:
    """(3, 3) the ISP's colour correction: the inverse of the white-balanced response (rows sum
    to 1)."""
    return np.linalg.inv(response / response.sum(axis=1, keepdims=True))


def process(raw_dn: np.ndarray, chain: ColourChain, gain_ev: float = 0.0) -> np.ndarray:
    """The stage: raw DN (``colour_sensor.sense``'s output) -> ``(H, W, 3) uint8`` display RGB. ``gain_ev``: the
    digital gain (stops) applied in linear before the tone curve."""
    response = camera_response(chain.sensor, chain.crosstalk)
    gains = white_balance_gains(response, chain.wb_error)
    x = normalise_raw(raw_dn, chain.sensor.black_level_dn, white_dn(chain.sensor))
    if chain.cfa != "none":
        rgb = demosaic(white_balance_mosaic(x, chain.cfa, gains), chain.cfa, chain.demosaic)
    else:
        rgb = white_balance_rgb(x, gains)
    if chain.colour_correction:
        rgb = colour_correct(rgb, colour_correction_matrix(response))
    if gain_ev:
        rgb *= np.float32(2.0 ** gain_ev)
    out = tone_map(rgb, chain.tone)
    out = denoise(out, chain.denoise)
    return unsharp_mask(out, chain.sharpen_amount, chain.sharpen_sigma_px)


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
    """A raw mosaic read from a camera as 8-bit sRGB: black and white level, white balance,
    demosaic, sRGB tone curve. No colour correction: a camera's own matrix is not known here.

    Parameters
    ----------
    raw_dn : (H, W) integer array
        The raw frame, DN.
    pattern : str
        Its Bayer pattern, one of ``cfa.PATTERNS``.
    black_dn, white_dn : float
        The DN of black and of the saturation capacity (``white_dn`` > ``black_dn``).
    method : str
        The demosaic, one of ``demosaic.DEMOSAICS``.
    gains : (3,) positive floats or None
        White-balance gains (R, G, B); None: grey world (:func:`grey_world_gains`).

    Returns
    -------
    (H, W, 3) uint8
        sRGB.

    Raises
    ------
    ValueError
        A frame that is not one channel, a white level not above black, a pattern or method not
        known, bad gains, or (grey world) a colour channel without signal.
    """
    if raw_dn.ndim != 2:
        raise ValueError(f"a raw frame is one channel (H, W), got shape {raw_dn.shape}")
    x = normalise_raw(raw_dn, black_dn, white_dn)
    g = grey_world_gains(x, pattern) if gains is None else np.asarray(gains, dtype=float)
    rgb = demosaic(white_balance_mosaic(x, pattern, g), pattern, method)
    return tone_map(rgb, "srgb")


@lru_cache(maxsize=4)
def _srgb_lut(levels: int) -> np.ndarray:
    x = np.arange(levels, dtype=np.float64) / (levels - 1)
    s = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    return np.clip(np.rint(s * 255.0), 0, 255).astype(np.uint8)


def display_from_dn(dn: np.ndarray, adc_bits: int, gain_ev: float = 0.0) -> np.ndarray:
    """The plain sensor's ISP: DN ``dn`` (H, W, 3) float32 holding integers in [0, 2^adc_bits - 1]
    -> (H, W, 3) uint8 sRGB. The digital gain 2^``gain_ev`` is applied to the DN (rounded,
    clipped at the top code), the sRGB curve looked up at the ADC's levels."""
    levels = 2 ** adc_bits
    if gain_ev != 0:
        dn = np.minimum(np.rint(dn * np.float32(2.0 ** gain_ev)), levels - 1)
    return _srgb_lut(levels)[dn.astype(np.int32)]
