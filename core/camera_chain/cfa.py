"""Colour filter array: the sensor side of a Bayer camera (which colour each pixel samples).

A Bayer pattern is named by the colours of its top-left 2x2 block, row by row: ``"RGGB"`` has red
at (row 0, col 0), green at (0, 1) and (1, 0), blue at (1, 1); the block tiles the frame. Channel
indices are RGB order: R = 0, G = 1, B = 2, the order of every ``(H, W, 3)`` array here.

``mosaic`` turns a full-colour image into the raw frame the sensor records (one channel per
pixel); ``apply_crosstalk`` mixes the channels first, as overlapping filter spectra do.
``demosaic`` is the inverse side (the ISP).
"""
from __future__ import annotations

from functools import lru_cache

from dockfactory.core.cv import cv2
import numpy as np

PATTERNS = ("RGGB", "BGGR", "GRBG", "GBRG")
_CHANNEL = {"R": 0, "G": 1, "B": 2}


def pattern_channels(pattern: str) -> np.ndarray:
    """Channel index (R=0, G=1, B=2) at each site of the 2x2 block of ``pattern``: a new (2, 2)
    int64 array, ``[row][col]``. ValueError naming the value unless ``pattern`` is one of
    :data:`PATTERNS` (exact, upper case)."""
    if not isinstance(pattern, str) or pattern not in PATTERNS:
        raise ValueError(f"cfa pattern must be one of {', '.join(PATTERNS)}, got {pattern!r}")
    return np.array([_CHANNEL[c] for c in pattern], dtype=np.int64).reshape(2, 2)


def pattern_sites(pattern: str) -> tuple[tuple[int, int, int], ...]:
    """The four sites of ``pattern``'s 2x2 block as (row, col, channel), row by row.
    ``image[row::2, col::2]`` are the pixels of one site. ValueError as :func:`pattern_channels`."""
    ch = pattern_channels(pattern)
    return tuple((dy, dx, int(ch[dy, dx])) for dy in (0, 1) for dx in (0, 1))


@lru_cache(maxsize=16)
def channel_map(pattern: str, height: int, width: int) -> np.ndarray:
    """Channel index (R=0, G=1, B=2) of every pixel of a ``height`` x ``width`` frame under
    ``pattern``: (height, width) uint8, read-only and shared (cached: copy it to modify it).
    Any size >= 1 (odd sizes cut the last block). ValueError for an unknown pattern or a size
    that is not a positive integer."""
    for name, n in (("height", height), ("width", width)):
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
            raise ValueError(f"channel map {name} must be a positive integer, got {n!r}")
    block = pattern_channels(pattern).astype(np.uint8)
    cmap = np.tile(block, ((height + 1) // 2, (width + 1) // 2))[:height, :width].copy()
    cmap.flags.writeable = False
    return cmap


def mosaic(rgb: np.ndarray, pattern: str) -> np.ndarray:
    """The raw frame a ``pattern`` sensor records of ``rgb``: each pixel keeps only its own
    channel. ``rgb`` is (H, W, 3) in RGB order, any dtype, any H, W >= 1; returns a new (H, W)
    array of the same dtype (values unchanged, no scaling). ValueError for another shape or an
    unknown pattern."""
    rgb = np.asarray(rgb)
    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.shape[0] < 1 or rgb.shape[1] < 1:
        raise ValueError(f"mosaic needs an (H, W, 3) RGB image, got shape {rgb.shape}")
    raw = np.empty(rgb.shape[:2], dtype=rgb.dtype)
    for dy, dx, c in pattern_sites(pattern):
        raw[dy::2, dx::2] = rgb[dy::2, dx::2, c]
    return raw


def apply_crosstalk(rgb: np.ndarray, matrix) -> np.ndarray:
    """Spectral overlap of the colour filters: ``out[..., i] = sum_j matrix[i, j] * rgb[..., j]``.

    ``rgb`` is (H, W, 3) float (linear scene-referred values, RGB order), ``matrix`` (3, 3) finite
    (row i: how much of each true colour reaches a channel-i pixel; rows summing to 1 keep a grey
    grey, the identity changes nothing). Returns a new (H, W, 3) float32 array, computed in float32
    (``cv2.transform``). ValueError for another shape, a non-float image or a bad matrix.
    """
    rgb = np.asarray(rgb)
    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.shape[0] < 1 or rgb.shape[1] < 1:
        raise ValueError(f"crosstalk needs an (H, W, 3) RGB image, got shape {rgb.shape}")
    if not np.issubdtype(rgb.dtype, np.floating):
        raise ValueError(f"crosstalk needs a float image (linear values), got dtype {rgb.dtype}")
    m = np.asarray(matrix, dtype=np.float64)
    if m.shape != (3, 3) or not np.all(np.isfinite(m)):
        raise ValueError(f"crosstalk matrix must be a finite 3x3 matrix, got {np.asarray(matrix).tolist()}")
    src = np.ascontiguousarray(rgb, dtype=np.float32)
    return cv2.transform(src, m.astype(np.float32))
