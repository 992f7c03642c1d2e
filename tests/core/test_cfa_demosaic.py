"""core.cfa (Bayer sampling) and core.demosaic (its inverse): pattern mapping, sample preservation,
accuracy on smooth and natural-ish images, sub-pixel centroids, and bad input.

Tolerances are stated next to each assertion; the measured values behind them are in comments
(OpenCV 4.11, numpy 1.26)."""
from functools import lru_cache

import cv2
import numpy as np
import pytest

from dockfactory.core.camera_chain.cfa import (
    PATTERNS,
    apply_crosstalk,
    channel_map,
    mosaic,
    pattern_channels,
    pattern_sites,
)
from dockfactory.core.camera_chain.demosaic import _CV_BAYER, DEMOSAICS, demosaic, vng_displacement

DTYPES = (np.uint8, np.uint16, np.float32)
EXPECTED_CHANNELS = {"RGGB": [[0, 1], [1, 2]], "BGGR": [[2, 1], [1, 0]],
                     "GRBG": [[1, 0], [2, 1]], "GBRG": [[1, 2], [0, 1]]}


def full_scale(dtype) -> float:
    """Full scale used for test images: 8 bits, 12 bits in a uint16 (a typical sensor), 1.0 for float."""
    return {np.uint8: 255.0, np.uint16: 4095.0, np.float32: 1.0}[dtype]


def quantise(img01: np.ndarray, dtype) -> np.ndarray:
    """An image in [0, 1] (any float) at ``dtype``'s test full scale."""
    if dtype == np.float32:
        return img01.astype(np.float32)
    return np.rint(img01 * full_scale(dtype)).astype(dtype)


def rms(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2)))


def supersampled(h: int, w: int, fn, sub: int = 8) -> np.ndarray:
    """Box-filtered (anti-aliased) image of fn(x, y) -> (..., 3) in pixel coordinates (pixel (r, c)
    is centred on x = c, y = r)."""
    off = (np.arange(sub) + 0.5) / sub - 0.5
    ys = (np.arange(h)[:, None] + off).ravel()
    xs = (np.arange(w)[:, None] + off).ravel()
    y, x = np.meshgrid(ys, xs, indexing="ij")
    return fn(x, y).reshape(h, sub, w, sub, 3).mean(axis=(1, 3))


# ---------------------------------------------------------------------------------- core.cfa


def test_pattern_channels_and_sites():
    for pattern, expected in EXPECTED_CHANNELS.items():
        ch = pattern_channels(pattern)
        assert ch.shape == (2, 2) and np.issubdtype(ch.dtype, np.integer)
        assert ch.tolist() == expected
        assert pattern_sites(pattern) == tuple((r, c, expected[r][c]) for r in (0, 1) for c in (0, 1))
    assert set(PATTERNS) == set(EXPECTED_CHANNELS)


def test_channel_map_tiles_the_block_and_is_cached_read_only():
    cmap = channel_map("GRBG", 5, 7)
    assert cmap.shape == (5, 7) and cmap.dtype == np.uint8
    assert cmap[0, :4].tolist() == [1, 0, 1, 0] and cmap[1, :4].tolist() == [2, 1, 2, 1]
    assert cmap[4, 6] == 1 and cmap[3, 6] == 2          # odd sizes cut the last block
    assert channel_map("GRBG", 5, 7) is cmap            # cached
    with pytest.raises(ValueError):
        cmap[0, 0] = 2                                   # read-only
    with pytest.raises(ValueError, match="height"):
        channel_map("RGGB", 0, 4)
    with pytest.raises(ValueError, match="'rggb'"):
        channel_map("rggb", 4, 4)


@pytest.mark.parametrize("dtype", DTYPES + (np.float64,))
def test_mosaic_keeps_each_pixels_own_channel(dtype):
    rng = np.random.default_rng(1)
    rgb = quantise(rng.random((6, 9, 3)), np.float32 if dtype == np.float64 else dtype).astype(dtype)
    for pattern in PATTERNS:
        raw = mosaic(rgb, pattern)
        assert raw.shape == (6, 9) and raw.dtype == dtype
        cmap = channel_map(pattern, 6, 9).astype(np.intp)
        assert np.array_equal(raw, np.take_along_axis(rgb, cmap[..., None], axis=2)[..., 0])


def test_apply_crosstalk_mixes_channels_row_by_row():
    rng = np.random.default_rng(2)
    rgb = rng.random((7, 5, 3)).astype(np.float32)
    m = np.array([[0.90, 0.08, 0.02], [0.05, 0.90, 0.05], [0.01, 0.12, 0.87]])
    out = apply_crosstalk(rgb, m)
    assert out.shape == rgb.shape and out.dtype == np.float32
    # float32 arithmetic on values <= 1: 1e-6 absolute
    np.testing.assert_allclose(out, np.einsum("ij,hwj->hwi", m, rgb.astype(np.float64)), atol=1e-6)
    np.testing.assert_array_equal(apply_crosstalk(rgb, np.eye(3)), rgb)
    pure_green = np.zeros((2, 2, 3), np.float32)
    pure_green[..., 1] = 1.0
    np.testing.assert_allclose(apply_crosstalk(pure_green, m)[0, 0], m[:, 1], atol=1e-7)


def test_apply_crosstalk_rejects_bad_input():
    rgb = np.zeros((4, 4, 3), np.float32)
    with pytest.raises(ValueError, match="3x3"):
        apply_crosstalk(rgb, np.eye(2))
    with pytest.raises(ValueError, match="nan"):
        apply_crosstalk(rgb, [[1, 0, 0], [0, np.nan, 0], [0, 0, 1]])
    with pytest.raises(ValueError, match=r"\(4, 4\)"):
        apply_crosstalk(np.zeros((4, 4), np.float32), np.eye(3))
    with pytest.raises(ValueError, match="uint8"):
        apply_crosstalk(np.zeros((4, 4, 3), np.uint8), np.eye(3))


# ---------------------------------------------------------------------------- pattern mapping


def test_opencv_bayer_names_are_verified_against_flat_red():
    """OpenCV's Bayer name is its second row's 2nd and 3rd pixels: our RGGB is its BayerBG. Checked
    on cv2.demosaicing itself: a flat red scene must come back red (BGR channel 2), and the name
    read naively from the top-left block (RGGB -> BayerRG) must not."""
    for pattern in PATTERNS:
        rgb = np.zeros((16, 16, 3), np.uint8)
        rgb[..., 0] = 200
        raw = mosaic(rgb, pattern)
        bgr = cv2.demosaicing(raw, getattr(cv2, f"COLOR_Bayer{_CV_BAYER[pattern]}2BGR"))
        assert bgr[2:-2, 2:-2].reshape(-1, 3).tolist() == [[0, 0, 200]] * 144
        naive = cv2.demosaicing(raw, getattr(cv2, f"COLOR_Bayer{pattern[:2]}2BGR"))
        assert not np.array_equal(naive[2:-2, 2:-2], bgr[2:-2, 2:-2])


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("method", DEMOSAICS)
@pytest.mark.parametrize("pattern", PATTERNS)
def test_flat_primaries_come_back_as_themselves(pattern, method, dtype):
    """A flat pure red / green / blue scene, mosaicked and demosaicked, is that colour on the whole
    frame, border included (reflected border). Tolerance: integers exact; float32 1e-6 of full
    scale (the 16-bit route's float rounding)."""
    top = full_scale(dtype)
    for c in range(3):
        rgb = np.zeros((12, 16, 3), dtype)
        rgb[..., c] = dtype(top)
        out = demosaic(mosaic(rgb, pattern), pattern, method)
        assert out.shape == rgb.shape and out.dtype == dtype
        tol = 1e-6 * top if dtype == np.float32 else 0
        assert np.abs(out.astype(np.float64) - rgb).max() <= tol, (c, out[..., c].min())


# --------------------------------------------------------------------------- sample preservation


def random_raw(dtype, rng, shape=(18, 22)):
    if dtype == np.uint8:
        return rng.integers(0, 256, shape, dtype=np.uint8)
    if dtype == np.uint16:
        return rng.integers(0, 65536, shape, dtype=np.uint16)
    return (rng.standard_normal(shape) * 3.0 + 0.5).astype(np.float32)   # any range, negatives too


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("method", DEMOSAICS)
def test_round_trip_keeps_every_sample_exactly(method, dtype):
    """mosaic(demosaic(raw)) == raw bit for bit, border included, for every pattern; a 12-bit frame
    in a uint16 too (bit depths below 16)."""
    rng = np.random.default_rng(3)
    frames = [random_raw(dtype, rng), random_raw(dtype, rng, (4, 4))]
    if dtype == np.uint16:
        frames.append(rng.integers(0, 4096, (20, 16), dtype=np.uint16))
    for raw in frames:
        for pattern in PATTERNS:
            out = demosaic(raw, pattern, method)
            assert out.dtype == raw.dtype and out.shape == raw.shape + (3,)
            assert np.array_equal(mosaic(out, pattern), raw), (pattern, raw.shape)


def test_flat_and_constant_frames_stay_constant():
    for dtype in DTYPES:
        raw = np.full((8, 10), 7, dtype)
        for method in DEMOSAICS:
            assert np.all(demosaic(raw, "RGGB", method) == raw[0, 0])


def test_opencv_alone_overwrites_the_border_and_vng_is_displaced():
    """What the wrappers correct. Plain cv2.demosaicing (bilinear, EA) overwrites the samples of
    the outer row/column with copies; OpenCV 4.11's VNG output is moved up by two rows (samples of
    row y found in row y - 2). ``vng_displacement`` finds the displacement of the installed OpenCV;
    ``demosaic(.., "vng")`` on uint8 equals OpenCV's VNG moved back, at >= 4 px from the border
    (to 1 LSB near the right edge)."""
    rng = np.random.default_rng(4)
    raw = rng.integers(16, 240, (32, 40), dtype=np.uint8)
    for suffix in ("", "_EA"):
        own = mosaic(cv2.demosaicing(raw, getattr(cv2, f"COLOR_BayerBG2BGR{suffix}"))[..., ::-1], "RGGB")
        assert np.array_equal(own[1:-1, 1:-1], raw[1:-1, 1:-1])
        assert not np.array_equal(own[0], raw[0])
    dy, dx = vng_displacement()
    if cv2.__version__.startswith("4.11."):
        assert (dy, dx) == (-2, 0)
    cv_vng = cv2.demosaicing(raw, cv2.COLOR_BayerBG2BGR_VNG)[..., ::-1]
    moved_back = np.roll(cv_vng, (-dy, -dx), axis=(0, 1))
    ours = demosaic(raw, "RGGB", "vng").astype(np.int64)
    # exact, except up to 1 LSB in columns W-6, W-5 (measured: only there, only 1 LSB; presumably
    # OpenCV's row-tail code path, which the unpadded call reaches there and the padded one not)
    assert np.array_equal(ours[4:-4, 4:-8], moved_back[4:-4, 4:-8])
    assert np.abs(ours[4:-4, 4:-4] - moved_back[4:-4, 4:-4]).max() <= 1


def test_mhc_is_the_papers_formulas():
    """Malvar-He-Cutler written out per site (RGGB, interior pixels), against demosaic(.., "mhc")
    on float32: agreement to 1e-6 (float32 sums of values in [0, 1])."""
    raw = np.random.default_rng(6).random((12, 12)).astype(np.float32)
    out = demosaic(raw, "RGGB", "mhc")
    v = raw.astype(np.float64)

    def cross(y, x, d):   # sum of the 4 pixels at distance d along rows and columns
        return v[y - d, x] + v[y + d, x] + v[y, x - d] + v[y, x + d]

    def diag(y, x):
        return v[y - 1, x - 1] + v[y - 1, x + 1] + v[y + 1, x - 1] + v[y + 1, x + 1]

    def along(y, x, d, horizontal):
        return v[y, x - d] + v[y, x + d] if horizontal else v[y - d, x] + v[y + d, x]

    for y, x in ((4, 4), (6, 8)):         # red sites: G and B; (y+1, x+1) blue sites: G and R
        for yy, xx, other in ((y, x, 2), (y + 1, x + 1, 0)):
            green = (4 * v[yy, xx] - cross(yy, xx, 2) + 2 * cross(yy, xx, 1)) / 8
            opposite = (6 * v[yy, xx] - 1.5 * cross(yy, xx, 2) + 2 * diag(yy, xx)) / 8
            assert out[yy, xx, 1] == pytest.approx(green, abs=1e-6)
            assert out[yy, xx, other] == pytest.approx(opposite, abs=1e-6)
    for y, x, horizontal_colour, vertical_colour in ((4, 5, 0, 2), (5, 4, 2, 0)):   # green sites
        g = v[y, x]
        h = (5 * g - diag(y, x) - along(y, x, 2, True) + 0.5 * along(y, x, 2, False)
             + 4 * along(y, x, 1, True)) / 8
        vv = (5 * g - diag(y, x) - along(y, x, 2, False) + 0.5 * along(y, x, 2, True)
              + 4 * along(y, x, 1, False)) / 8
        assert out[y, x, horizontal_colour] == pytest.approx(h, abs=1e-6)
        assert out[y, x, vertical_colour] == pytest.approx(vv, abs=1e-6)


@pytest.mark.parametrize("dtype", (np.uint8, np.uint16))
def test_mhc_integers_are_the_float_result_rounded_and_clipped(dtype):
    """Integer MHC = float32 MHC of the same values, rounded half to even and clipped to the
    dtype's range (full-range noise overshoots both ends)."""
    rng = np.random.default_rng(7)
    raw = rng.integers(0, np.iinfo(dtype).max + 1, (16, 20), dtype=dtype)
    for pattern in PATTERNS:
        as_float = demosaic(raw.astype(np.float32), pattern, "mhc")
        assert as_float.min() < 0 and as_float.max() > np.iinfo(dtype).max
        expected = np.clip(np.rint(as_float), 0, np.iinfo(dtype).max).astype(dtype)
        assert np.array_equal(demosaic(raw, pattern, "mhc"), expected)


# --------------------------------------------------------------------------------- accuracy


def sinusoid_field(h=96, w=128, wavelength=40.0) -> np.ndarray:
    """Smooth colour field in [0.15, 0.85]: each channel a plane wave of its own direction and phase."""
    def fn(x, y):
        waves = [0.5 + 0.35 * np.sin(2 * np.pi * (x * np.cos(a) + y * np.sin(a)) / wavelength + ph)
                 for a, ph in ((0.3, 0.0), (1.2, 1.0), (2.2, 2.0))]
        return np.stack(waves, axis=-1)
    return supersampled(h, w, fn, sub=1)


def natural_ish(h=96, w=128) -> np.ndarray:
    """Grey ramp with a sharp slanted luminance edge and a bright disc, under a slowly varying
    warm tint (channels correlated, as in most scenes); anti-aliased."""
    def fn(x, y):
        lum = 0.15 + 0.7 * x / w
        lum = np.where(x - 0.5 * w > 0.3 * (y - 0.5 * h), 0.35 * lum, lum)
        lum = np.where((x - 0.3 * w) ** 2 + (y - 0.5 * h) ** 2 < 15 ** 2, 0.9, lum)
        tint = np.stack([np.ones_like(x), 0.85 + 0.1 * y / h, 0.6 + 0.2 * x / w], axis=-1)
        return lum[..., None] * tint
    return supersampled(h, w, fn)


def hue_edge(h=96, w=128) -> np.ndarray:
    """Grey ramp whose right part (past a slanted line) turns orange at the same luminance scale:
    a sharp colour edge without a green-channel step in proportion (channels decorrelated)."""
    def fn(x, y):
        g = 0.1 + 0.8 * x / w
        inside = x - 0.5 * w > 0.2 * (y - 0.5 * h)
        return np.stack([g, g * np.where(inside, 0.55, 1.0), g * np.where(inside, 0.25, 1.0)], axis=-1)
    return supersampled(h, w, fn)


def worst_rms(img01: np.ndarray, method: str, dtype) -> float:
    """Largest RMS error over the four patterns, whole frame, as a fraction of full scale."""
    src = quantise(img01, dtype)
    return max(rms(demosaic(mosaic(src, p), p, method), src) for p in PATTERNS) / full_scale(dtype)


# RMS error bounds, fraction of full scale, whole frame incl. border, worst pattern. Measured
# (float32 and uint16; uint8 within 0.0005 of them except vng): sinusoid 0.0036 bilinear, 0.0041
# edge_aware, 0.0107 vng (0.0078 on uint8: the square-root companding costs), 0.0056 mhc; hue edge
# 0.0071, 0.0068, 0.0055, 0.0073 (uint8 0.0072, 0.0069, 0.0051, 0.0074).
SMOOTH_RMS = {"bilinear": 0.006, "edge_aware": 0.0065, "vng": 0.016, "mhc": 0.009}
HUE_EDGE_RMS = 0.011


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("method", DEMOSAICS)
def test_smooth_colour_field_is_reproduced(method, dtype):
    assert worst_rms(sinusoid_field(), method, dtype) < SMOOTH_RMS[method]
    assert worst_rms(hue_edge(), method, dtype) < HUE_EDGE_RMS


@pytest.mark.parametrize("dtype", (np.float32, np.uint16))
def test_mhc_beats_bilinear_on_a_natural_ish_image(dtype):
    """Where the channels share their edges, MHC's correction from the pixel's own channel pays:
    mhc (and vng) RMS below 0.75 x bilinear's. Where they do not, it misleads: on the independent
    sinusoids MHC is worse than bilinear (on the hue edge they are about equal)."""
    # measured RMS: mhc 0.0083, bilinear 0.0144, vng 0.0050, edge_aware 0.0135; on the sinusoids
    # mhc 0.0056 vs bilinear 0.0037 (ratio 1.5), on the hue edge 0.0072 vs 0.0070
    img = natural_ish()
    bilinear, mhc = worst_rms(img, "bilinear", dtype), worst_rms(img, "mhc", dtype)
    assert mhc < 0.75 * bilinear, (mhc, bilinear)
    assert worst_rms(img, "vng", dtype) < 0.75 * bilinear
    field = sinusoid_field()
    assert worst_rms(field, "mhc", dtype) > 1.2 * worst_rms(field, "bilinear", dtype)


# ------------------------------------------------------------------------------ disc centroid

DISC_R, DISC_BG, DISC_SIZE = 10.0, np.array([0.04, 0.05, 0.06]), 64
# sub-pixel centres spread over a full 2-px period of the red lattice, for every pattern
DISC_CENTRES = [(31.0 + 2 * a, 31.0 + 2 * b) for a, b in
                np.random.default_rng(5).random((6, 2))] + [(31.5, 32.25)]


@lru_cache(maxsize=None)
def red_disc(cx: float, cy: float) -> np.ndarray:
    """Pure red disc of radius DISC_R centred on (cx, cy) over a dark grey background, linear,
    anti-aliased by 16x16 supersampling; (64, 64, 3) float64 in [0, 1] (cached: read only)."""
    def fn(x, y):
        cover = ((x - cx) ** 2 + (y - cy) ** 2 <= DISC_R ** 2).astype(np.float64)[..., None]
        return DISC_BG + cover * (np.array([1.0, 0.0, 0.0]) - DISC_BG)
    return supersampled(DISC_SIZE, DISC_SIZE, fn, sub=16)


def centroid(weights: np.ndarray) -> np.ndarray:
    yy, xx = np.mgrid[: weights.shape[0], : weights.shape[1]]
    return np.array([(weights * xx).sum(), (weights * yy).sum()]) / weights.sum()


# Tolerances, px. Measured over 40 centres x 4 patterns (float32, uint16, uint8): bilinear,
# edge_aware, mhc within 0.149 px of the true centre (mean 0.085), vng within 0.176 (mean 0.093).
# The error is the red lattice's sampling (2 px pitch), not the demosaicing: bilinear, edge_aware
# and mhc reproduce the centroid of the red samples alone within 0.0003 px (mhc on uint8: 0.0017,
# its rounding and clipping), vng within 0.056 px.
DISC_TRUE_TOL = 0.25
DISC_SAMPLES_TOL = {"bilinear": 0.005, "edge_aware": 0.005, "mhc": 0.005, "vng": 0.1}


@pytest.mark.parametrize("dtype", (np.float32, np.uint16, np.uint8))
@pytest.mark.parametrize("method", DEMOSAICS)
def test_red_disc_centroid_survives_mosaic_and_demosaic(method, dtype):
    for cx, cy in DISC_CENTRES:
        img = red_disc(cx, cy)
        assert np.hypot(*(centroid(img[..., 0] - DISC_BG[0]) - (cx, cy))) < 0.005   # the rendering itself
        src = quantise(img, dtype)
        bg = float(src[0, 0, 0])
        for pattern in PATTERNS:
            raw = mosaic(src, pattern)
            red = demosaic(raw, pattern, method)[..., 0].astype(np.float64) - bg
            found = centroid(red)
            is_red = channel_map(pattern, *raw.shape) == 0
            samples = centroid(np.where(is_red, raw.astype(np.float64) - bg, 0.0))
            assert np.hypot(*(found - (cx, cy))) < DISC_TRUE_TOL, (pattern, cx, cy, found)
            assert np.hypot(*(found - samples)) < DISC_SAMPLES_TOL[method], (pattern, cx, cy, found, samples)


# --------------------------------------------------------------------------------- bad input


def test_bad_input_is_a_value_error_naming_the_value():
    raw = np.zeros((8, 8), np.uint16)
    with pytest.raises(ValueError, match=r"cfa pattern must be one of RGGB, BGGR, GRBG, GBRG, got 'XYZ'"):
        demosaic(raw, "XYZ", "bilinear")
    with pytest.raises(ValueError, match="'XYZ'"):
        pattern_channels("XYZ")
    with pytest.raises(ValueError, match="'XYZ'"):
        mosaic(np.zeros((4, 4, 3)), "XYZ")
    with pytest.raises(ValueError, match=r"bilinear, edge_aware, vng, mhc, got 'ahd'"):
        demosaic(raw, "RGGB", "ahd")
    with pytest.raises(ValueError, match="got None"):
        demosaic(raw, "RGGB", None)
    with pytest.raises(ValueError, match="7x8"):
        demosaic(np.zeros((7, 8), np.uint8), "RGGB", "mhc")
    with pytest.raises(ValueError, match="8x9"):
        demosaic(np.zeros((8, 9), np.uint8), "RGGB", "bilinear")
    with pytest.raises(ValueError, match="2x8"):
        demosaic(np.zeros((2, 8), np.uint8), "RGGB", "vng")
    with pytest.raises(ValueError, match=r"3-D shape \(8, 8, 3\)"):
        demosaic(np.zeros((8, 8, 3), np.uint8), "RGGB", "bilinear")
    with pytest.raises(ValueError, match="1-D"):
        demosaic(np.zeros(16, np.uint8), "RGGB", "bilinear")
    with pytest.raises(ValueError, match="float64"):
        demosaic(np.zeros((8, 8)), "RGGB", "bilinear")
    with pytest.raises(ValueError, match="finite"):
        demosaic(np.full((8, 8), np.nan, np.float32), "RGGB", "mhc")
    with pytest.raises(ValueError, match=r"\(4, 4\)"):
        mosaic(np.zeros((4, 4)), "RGGB")
    with pytest.raises(ValueError, match=r"\(4, 4, 4\)"):
        mosaic(np.zeros((4, 4, 4)), "RGGB")
