"""Demosaicing: the ISP side of a Bayer camera (a full RGB image from the one-channel raw frame).

``demosaic(raw, pattern, method)`` with ``pattern`` one of ``cfa.PATTERNS``
(colours of the top-left 2x2 block) and ``method`` one of :data:`DEMOSAICS`: OpenCV's ``"bilinear"``,
``"edge_aware"`` and ``"vng"`` (8-bit only: other inputs are companded to 8 bits), and ``"mhc"`` (Malvar,
He, Cutler, ICASSP 2004, as four 5x5 linear filters). Every method returns the raw samples unchanged at
their own sites and fills the frame border as if the frame were mirrored about its edge pixels
(``BORDER_REFLECT_101``). The results are RGB; OpenCV's Bayer names (``_CV_BAYER``) and its VNG
displacement (:func:`vng_displacement`) are translated here.

Why and how: docs/colour_cameras.md, "Demosaicing".
"""
from __future__ import annotations

from functools import lru_cache

from dockfactory.core.cv import cv2
import numpy as np

from dockfactory.core.camera_chain.cfa import channel_map, pattern_channels, pattern_sites

DEMOSAICS = ("bilinear", "edge_aware", "vng", "mhc")
RAW_DTYPES = (np.uint8, np.uint16, np.float32)
MIN_SIZE = 4

# our pattern -> OpenCV's name for it (its second row's 2nd and 3rd pixels)
_CV_BAYER = {"RGGB": "BG", "BGGR": "RG", "GRBG": "GB", "GBRG": "GR"}
_CV_SUFFIX = {"bilinear": "", "edge_aware": "_EA", "vng": "_VNG"}
# reflected margin demosaiced with the frame (even: keeps the pattern's phase); wide enough that
# OpenCV's copied border rows/columns and VNG's displacement stay outside the frame
_CV_PAD = {"bilinear": 2, "edge_aware": 2, "vng": 4}

# Malvar-He-Cutler filters (weights / 8; symmetric, so correlation = convolution). At a green
# site "row" gives the colour of the horizontal neighbours, "col" that of the vertical ones; at a
# red or blue site "green" gives green and "diag" the other of red and blue.
_MHC_ROW = np.array([[0, 0, 0.5, 0, 0],
                     [0, -1, 0, -1, 0],
                     [-1, 4, 5, 4, -1],
                     [0, -1, 0, -1, 0],
                     [0, 0, 0.5, 0, 0]], np.float32) / 8
_MHC = {
    "green": np.array([[0, 0, -1, 0, 0],
                       [0, 0, 2, 0, 0],
                       [-1, 2, 4, 2, -1],
                       [0, 0, 2, 0, 0],
                       [0, 0, -1, 0, 0]], np.float32) / 8,
    "row": _MHC_ROW,
    "col": np.ascontiguousarray(_MHC_ROW.T),
    "diag": np.array([[0, 0, -1.5, 0, 0],
                      [0, 2, 0, 2, 0],
                      [-1.5, 0, 6, 0, -1.5],
                      [0, 2, 0, 2, 0],
                      [0, 0, -1.5, 0, 0]], np.float32) / 8,
}


def demosaic(raw: np.ndarray, pattern: str, method: str) -> np.ndarray:
    """Full-colour image of the Bayer frame ``raw`` taken through ``pattern``, by ``method``.

    ``raw``: (H, W) uint8, uint16 (any bit depth up to 16, values as recorded) or float32
    (finite, any range, e.g. linear [0, 1]); H and W even and >= 4. Returns a new (H, W, 3) array
    in RGB order, of ``raw``'s dtype and units, whose samples at their own sites equal ``raw``
    exactly. Integer results are rounded and clipped to the dtype's range (0..255, 0..65535), not
    to a lower bit depth: ``"mhc"`` (negative filter weights) overshoots at edges and may exceed
    e.g. 4095 on a 12-bit frame; ``"bilinear"`` and the 16-bit ``"vng"`` route stay within the
    frame's [min, max]. Float results are not clipped.

    Quantisation (the interpolated values only; samples are always restored exactly):

    * ``"bilinear"``, ``"edge_aware"`` on float32: the frame is mapped linearly from its own
      [min, max] onto 0..65535 for OpenCV and back, so interpolated values carry an error of up to
      half of (max - min) / 65535 (plus OpenCV's own integer rounding);
    * ``"vng"`` on uint16 or float32: the frame is companded to 8 bits by a square-root curve over
      its own [min, max] (code = round(255 sqrt((v - min) / (max - min)))), demosaiced, and
      expanded by the inverse curve: a step of (max - min) / 65025 near the minimum growing to
      about 0.8 % of (max - min) near the maximum. On uint8 input it is OpenCV's VNG itself, run
      on the reflected frame with OpenCV's output displacement undone (:func:`vng_displacement`);
    * ``"mhc"`` is computed in float32 on every dtype (exact for integer inputs before rounding).

    ValueError naming the value for an unknown pattern or method, a raw frame that is not 2-D,
    another dtype, an odd or too small size, or non-finite float values.
    """
    raw = _checked_raw(raw)
    pattern_channels(pattern)
    if not isinstance(method, str) or method not in DEMOSAICS:
        raise ValueError(f"demosaic method must be one of {', '.join(DEMOSAICS)}, got {method!r}")
    if method == "mhc":
        return _mhc(raw, pattern)
    if method == "vng":
        return _vng(raw, pattern)
    if raw.dtype == np.float32:
        return _via_uint16(raw, pattern, method)
    return _opencv(raw, pattern, method)


def _checked_raw(raw) -> np.ndarray:
    """``raw`` as a C-contiguous array after the checks of :func:`demosaic` (ValueError)."""
    raw = np.asarray(raw)
    if raw.ndim != 2:
        raise ValueError(f"demosaic needs a 2-D (H, W) raw frame, got {raw.ndim}-D shape {raw.shape}")
    if raw.dtype not in RAW_DTYPES:
        raise ValueError(f"demosaic needs a uint8, uint16 or float32 raw frame, got dtype {raw.dtype}")
    h, w = raw.shape
    if h % 2 or w % 2 or h < MIN_SIZE or w < MIN_SIZE:
        raise ValueError(f"demosaic needs an even height and width >= {MIN_SIZE}, got {h}x{w}")
    if raw.dtype == np.float32 and not np.isfinite(raw).all():
        raise ValueError("demosaic needs finite raw values, got NaN or infinity")
    return np.ascontiguousarray(raw)


def _opencv(raw: np.ndarray, pattern: str, method: str) -> np.ndarray:
    """``cv2.demosaicing`` of an 8/16-bit ``raw`` (VNG: 8-bit) for ``method`` in bilinear,
    edge_aware, vng: (H, W, 3) RGB of raw's dtype, computed on a reflected margin and cropped,
    VNG's displacement undone."""
    code = getattr(cv2, f"COLOR_Bayer{_CV_BAYER[pattern]}2BGR{_CV_SUFFIX[method]}")
    pad = _CV_PAD[method]
    bgr = cv2.demosaicing(cv2.copyMakeBorder(raw, pad, pad, pad, pad, cv2.BORDER_REFLECT_101), code)
    dy, dx = vng_displacement() if method == "vng" else (0, 0)
    h, w = raw.shape
    return np.ascontiguousarray(bgr[pad + dy:pad + dy + h, pad + dx:pad + dx + w, ::-1])


# upstream: https://github.com/opencv/opencv/issues/27225 (output two rows up, up to 4.11 at least)
@lru_cache(maxsize=1)
def vng_displacement() -> tuple[int, int]:
    """(rows, cols) by which this OpenCV's VNG output is displaced from its input: the value
    demosaiced for raw pixel (y, x) lands at (y + rows, x + cols). Found once by demosaicing a
    random frame and locating its samples; RuntimeError if no displacement within 2 px explains
    them (then the VNG route cannot be trusted)."""
    h = w = 32
    raw = np.random.default_rng(0).integers(16, 240, (h, w), dtype=np.uint8)
    rgb = cv2.demosaicing(raw, getattr(cv2, f"COLOR_Bayer{_CV_BAYER['RGGB']}2BGR_VNG"))[..., ::-1]
    inner = (slice(8, h - 8), slice(8, w - 8))
    own = channel_map("RGGB", h, w)[inner][..., None].astype(np.intp)
    for dy in range(-2, 3):
        for dx in range(-2, 3):
            moved = rgb[8 + dy:h - 8 + dy, 8 + dx:w - 8 + dx]
            if np.array_equal(np.take_along_axis(moved, own, axis=2)[..., 0], raw[inner]):
                return dy, dx
    raise RuntimeError(f"OpenCV {cv2.__version__}: VNG output does not keep the raw samples at any "
                       "displacement within 2 px; cannot use it")


def _restore_samples(rgb: np.ndarray, raw: np.ndarray, pattern: str) -> np.ndarray:
    """Write ``raw``'s samples back at their own sites of ``rgb`` (in place; returns it)."""
    for dy, dx, c in pattern_sites(pattern):
        rgb[dy::2, dx::2, c] = raw[dy::2, dx::2]
    return rgb


def _span(raw: np.ndarray) -> tuple[float, float]:
    """(min, max - min) of ``raw``; a flat frame gets a span of 1 (any non-zero value works)."""
    lo, hi = float(raw.min()), float(raw.max())
    return lo, (hi - lo) if hi > lo else 1.0


def _via_uint16(raw: np.ndarray, pattern: str, method: str) -> np.ndarray:
    """bilinear / edge_aware of a float32 ``raw`` through OpenCV's 16-bit route: [min, max] mapped
    linearly onto 0..65535 and back; float32 (H, W, 3) with the samples restored exactly."""
    lo, span = _span(raw)
    step = span / 65535.0
    q = np.clip(np.rint((raw - np.float32(lo)) * np.float32(1.0 / step)), 0, 65535).astype(np.uint16)
    rgb = _opencv(q, pattern, method).astype(np.float32)
    rgb *= np.float32(step)
    rgb += np.float32(lo)
    return _restore_samples(rgb, raw, pattern)


def _vng(raw: np.ndarray, pattern: str) -> np.ndarray:
    """VNG of ``raw``: OpenCV's directly for uint8; uint16 and float32 companded to 8 bits by a
    square-root curve over the frame's [min, max] and expanded back, samples restored exactly."""
    if raw.dtype == np.uint8:
        return _opencv(raw, pattern, "vng")
    lo, span = _span(raw)
    if raw.dtype == np.uint16:   # one table lookup for all 65536 codes
        levels = np.clip((np.arange(65536, dtype=np.float64) - lo) / span, 0.0, 1.0)
        codes = np.rint(255.0 * np.sqrt(levels)).astype(np.uint8)[raw]
    else:
        levels = np.clip((raw - np.float32(lo)) * np.float32(1.0 / span), 0.0, 1.0)
        codes = np.rint(np.float32(255.0) * np.sqrt(levels)).astype(np.uint8)
    expand = (np.arange(256, dtype=np.float64) / 255.0) ** 2 * span + lo
    if raw.dtype == np.uint16:
        expand = np.clip(np.rint(expand), 0, 65535).astype(np.uint16)
    else:
        expand = expand.astype(np.float32)
    rgb = cv2.LUT(_opencv(codes, pattern, "vng"), expand)
    return _restore_samples(rgb, raw, pattern)


def _mhc(raw: np.ndarray, pattern: str) -> np.ndarray:
    """Malvar-He-Cutler demosaicing of ``raw`` in float32 (``cv2.filter2D``, BORDER_REFLECT_101):
    (H, W, 3) RGB of raw's dtype, integers rounded (half to even) and clipped to the dtype's range."""
    ch = pattern_channels(pattern)
    f = raw.astype(np.float32)
    est = {k: cv2.filter2D(f, -1, kernel, borderType=cv2.BORDER_REFLECT_101) for k, kernel in _MHC.items()}
    # the colour planes are built inside the filter outputs (no new frame-sized arrays): green from
    # "green"; red from "row" and blue from "col", right at green sites with red horizontal
    # neighbours, swapped at the other green sites
    red, green, blue = est["row"], est["green"], est["col"]
    for dy, dx, c in pattern_sites(pattern):
        site = (slice(dy, None, 2), slice(dx, None, 2))
        if c == 1:
            green[site] = f[site]
            if ch[dy, 1 - dx] == 2:   # blue horizontal neighbours: red is "col", blue is "row"
                swapped = red[site].copy()
                red[site] = blue[site]
                blue[site] = swapped
        else:                          # red or blue site: its own sample, the other from "diag"
            own, other = (red, blue) if c == 0 else (blue, red)
            own[site] = f[site]
            other[site] = est["diag"][site]
    rgb = cv2.merge([red, green, blue])
    if raw.dtype == np.float32:
        return rgb
    # OpenCV's saturating conversion: the same numbers as np.rint then np.clip to the dtype's range
    return cv2.add(rgb, 0.0, dtype=cv2.CV_8U if raw.dtype == np.uint8 else cv2.CV_16U)
