"""The coverage correction of label-aware sampling (generator.marker_coverage) on a marker rendered
by Monte Carlo in numpy: a red disc in a dark ring on grey paint with a slope, 16 samples a pixel
(box filter, each sample's light noisy), against the same marker at 4,096 stratified samples."""
import numpy as np
import pytest

from dockfactory.generator.marker_coverage import coverage_corrected, marker_weight, smoothed_on_marker

H = W = 40
CENTRE = (20.3, 19.6)      # x, y px
DISC_R, RING_R = 8.0, 11.0
DISC, RING = np.array([0.6, 0.02, 0.02]), np.array([0.02, 0.02, 0.02])
LIGHT_NOISE = 0.05         # per sample


def _paint(x, y):
    return np.stack([0.25 + 0.004 * x, 0.3 + 0.0 * y, 0.28 + 0.003 * y], axis=-1)


def _shade(xs, ys):
    """(classes (..., 3) one-hot disc / ring / paint, colour (..., 3)) at canvas points."""
    r = np.hypot(xs - CENTRE[0], ys - CENTRE[1])
    cls = np.stack([r < DISC_R, (r >= DISC_R) & (r < RING_R), r >= RING_R], axis=-1).astype(float)
    colour = cls[..., :1] * DISC + cls[..., 1:2] * RING + cls[..., 2:] * _paint(xs, ys)
    return cls, colour


def _render(offsets, rng=None):
    """(rgb, disc and ring coverage) of every pixel from its sample ``offsets`` (H, W, n, 2)."""
    ys, xs = np.mgrid[0:H, 0:W]
    px, py = xs[..., None] + offsets[..., 0], ys[..., None] + offsets[..., 1]
    cls, colour = _shade(px, py)
    if rng is not None:
        colour = colour + rng.normal(0.0, LIGHT_NOISE, colour.shape)
    return colour.mean(axis=2), cls.mean(axis=2)[..., :2]


@pytest.fixture(scope="module")
def exact():
    g = (np.arange(64) + 0.5) / 64
    grid = np.stack(np.meshgrid(g, g), axis=-1).reshape(-1, 2)
    return _render(np.broadcast_to(grid, (H, W, len(grid), 2)))


def _noisy(seed):
    rng = np.random.default_rng(seed)
    return _render(rng.random((H, W, 16, 2)), rng)


def _edge(cov):
    return ((cov > 0.02) & (cov < 0.98)).any(axis=-1)


def test_edge_noise_falls_to_the_light_noise(exact):
    """Squared error on the edge pixels (any mixed coverage) under 0.2x the uncorrected one's
    (measured 0.13x: the coverage draw was most of it); pure pixels are untouched (but for the
    clip at 0)."""
    ref, cov = exact
    edge = _edge(cov)
    raw_err = corr_err = 0.0
    for seed in range(8):
        rgb, sampled = _noisy(seed)
        out = coverage_corrected(rgb, sampled, cov)
        raw_err += np.sum((rgb - ref)[edge] ** 2)
        corr_err += np.sum((out - ref)[edge] ** 2)
        pure = (sampled == cov).all(axis=-1) & ~edge
        assert np.allclose(out[pure], np.maximum(rgb[pure], 0.0), atol=1e-6)   # never below 0
    assert corr_err < 0.2 * raw_err, (corr_err, raw_err)


def test_the_correction_adds_no_bias(exact):
    """Averaged over 48 renders the corrected edge pixels sit on the converged ones: the mean
    error per pixel under 0.1x one render's RMS error there (the coverage of the samples is
    unbiased for the exact coverage, whatever the colours the correction estimates)."""
    ref, cov = exact
    edge = _edge(cov)
    outs, raws = [], []
    for seed in range(100, 148):
        rgb, sampled = _noisy(seed)
        outs.append(coverage_corrected(rgb, sampled, cov)[edge] - ref[edge])
        raws.append(rgb[edge] - ref[edge])
    rms = np.sqrt(np.mean(np.square(raws)))
    assert np.max(np.abs(np.mean(outs, axis=0))) < 0.1 * rms + 3 * LIGHT_NOISE / 4 / np.sqrt(48)


def test_no_change_where_the_samples_saw_the_exact_coverage(exact):
    ref, cov = exact
    assert np.allclose(coverage_corrected(ref, cov, cov), ref, atol=1e-6)


def test_a_coverage_of_another_shape_is_refused(exact):
    ref, cov = exact
    with pytest.raises(ValueError, match="coverage of shape"):
        coverage_corrected(ref, cov[:-1], cov[:-1])


def _write_exr(path, channels):
    import OpenEXR
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with OpenEXR.File(header, {k: np.ascontiguousarray(v, np.float16) for k, v in channels.items()}) as f:
        f.write(str(path))


def test_the_coverage_pass_is_read_from_a_render_and_its_absence_named(tmp_path):
    """Blender's channel names (view layer, AOV, R/G/B): the disc and ring shares come back as
    written; a file without the pass is an ExrError naming the file and the pass."""
    from dockfactory.core.names import MARKER_CLASS_AOV
    from dockfactory.generator.exr import ExrError, read_class_coverage
    rng = np.random.default_rng(3)
    disc, ring = rng.random((5, 7)), rng.random((5, 7))
    rgb = {f"ViewLayer.Combined.{c}": rng.random((5, 7)) for c in "RGB"}
    aov = {f"ViewLayer.{MARKER_CLASS_AOV}.R": disc, f"ViewLayer.{MARKER_CLASS_AOV}.G": ring,
           f"ViewLayer.{MARKER_CLASS_AOV}.B": np.zeros((5, 7))}
    _write_exr(tmp_path / "crop.exr", {**rgb, **aov})
    got = read_class_coverage(tmp_path / "crop.exr")
    assert got.shape == (5, 7, 2)
    assert np.allclose(got[..., 0], disc, atol=1e-3) and np.allclose(got[..., 1], ring, atol=1e-3)
    _write_exr(tmp_path / "plain.exr", rgb)
    with pytest.raises(ExrError, match=f"plain.exr: no coverage pass '{MARKER_CLASS_AOV}'"):
        read_class_coverage(tmp_path / "plain.exr")


def test_with_a_denoiser_the_marker_is_corrected_and_the_paint_beyond_it_denoised(exact):
    """``corrected_region`` with the colour before the denoiser: on every pixel a disc or ring
    touches it is the corrected noisy colour, 3 px or more beyond them the denoised colour as
    rendered, and in between a blend of the two."""
    from dockfactory.generator.marker_coverage import corrected_region, marker_weight
    ref, cov = exact
    noisy, sampled = _noisy(7)
    denoised = ref + 0.001          # stands in for the denoiser's output
    out = corrected_region(denoised, noisy, sampled, cov)
    w = marker_weight(cov)
    touched = cov.sum(axis=-1) > 1e-3
    assert np.all(w[touched] == 1.0) and w.min() == 0.0
    assert np.allclose(out[touched], coverage_corrected(noisy, sampled, cov)[touched], atol=1e-6)
    r = np.hypot(*(np.mgrid[0:H, 0:W][::-1] - np.array(CENTRE)[:, None, None]))
    far = r > RING_R + 4.5
    assert far.any() and np.allclose(out[far], denoised[far], atol=1e-6)
    assert corrected_region(denoised, None, sampled, cov).tolist() == coverage_corrected(denoised, sampled, cov).tolist()


def test_the_light_smoothing_takes_the_edge_noise_down_without_a_bias(exact):
    """At 1 px the edge pixels' squared error falls under 0.25x the correction's alone (measured
    0.11x: the light noise each edge pixel's 16 samples left is shared with its neighbours'); over
    48 renders the mean error per edge pixel stays within the unsmoothed correction's bound (the
    exact-coverage edge is kept: only the zero-mean residual is averaged)."""
    ref, cov = exact
    edge = _edge(cov)
    plain = smooth = 0.0
    outs, raws = [], []
    for seed in range(200, 248):
        rgb, sampled = _noisy(seed)
        out = coverage_corrected(rgb, sampled, cov, smoothing_px=1.0)
        plain += np.sum((coverage_corrected(rgb, sampled, cov) - ref)[edge] ** 2)
        smooth += np.sum((out - ref)[edge] ** 2)
        outs.append(out[edge] - ref[edge])
        raws.append(rgb[edge] - ref[edge])
    assert smooth < 0.25 * plain, (smooth, plain)
    rms = np.sqrt(np.mean(np.square(raws)))
    assert np.max(np.abs(np.mean(outs, axis=0))) < 0.1 * rms + 3 * LIGHT_NOISE / 4 / np.sqrt(48)


def test_the_smoothing_averages_marker_pixels_only(exact):
    """A constant residual on the marker is kept as it is (the weights sum to 1); the paint beyond
    the marker is never changed and never enters it: a residual that is 1 off the marker and 0 on
    it comes back 1 off and 0 on."""
    _, cov = exact
    on = marker_weight(cov) >= 1.0
    const = np.full((H, W, 3), 0.3)
    assert np.allclose(smoothed_on_marker(const, cov, 1.5), const)
    outside = np.where(on[..., None], 0.0, 1.0) * np.ones((H, W, 3))
    got = smoothed_on_marker(outside, cov, 1.5)
    assert np.array_equal(got[~on], outside[~on]) and np.allclose(got[on], 0.0)


def test_a_miss_of_the_class_colours_is_not_spread(exact):
    """A marker's residual of light noise (sigma 0.01) with a 3 x 3 patch 0.2 off (the classes'
    colours missing next to an occluder): the patch and its neighbours keep their own residual, and
    no pixel two or more away from it moves by more than the noise (the miss is not shared)."""
    _, cov = exact
    on = marker_weight(cov) >= 1.0
    rng = np.random.default_rng(5)
    res = rng.normal(0.0, 0.01, (H, W, 3))
    ys, xs = np.nonzero(on)
    y0, x0 = ys[len(ys) // 2], xs[len(xs) // 2]
    res[y0 - 1:y0 + 2, x0 - 1:x0 + 2] += 0.2
    got = smoothed_on_marker(res, cov, 1.5)
    assert np.array_equal(got[y0 - 2:y0 + 3, x0 - 2:x0 + 3], res[y0 - 2:y0 + 3, x0 - 2:x0 + 3])
    ring = np.zeros((H, W), bool)
    ring[y0 - 5:y0 + 6, x0 - 5:x0 + 6] = True
    ring[y0 - 2:y0 + 3, x0 - 2:x0 + 3] = False
    assert np.abs(got[ring & on]).max() < 0.03
    plain = rng.normal(0.0, 0.01, (H, W, 3))
    assert np.std(smoothed_on_marker(plain, cov, 1.5)[on]) < 0.5 * np.std(plain[on])


def test_a_bright_disc_s_own_noise_is_not_taken_for_a_miss(exact):
    """Light noise scales with the light: a bright disc's residual 10x a dark ring's (sigma 0.05
    against 0.005, the paint 0.02). The guard judges each class by its own sigma, so it leaves out
    almost none of the marker's pixels (under 2 %; one sigma pooled over the classes flagged the
    disc's tails and their neighbours, a third of an ordinary rendered marker's pixels) and the
    smoothing takes the disc's noise down; a miss of 20 disc sigmas is still kept out."""
    from dockfactory.generator.marker_coverage import _misfit
    _, cov = exact
    on = marker_weight(cov) >= 1.0
    share = np.concatenate([cov, np.clip(1.0 - cov.sum(axis=-1, keepdims=True), 0.0, 1.0)], axis=-1)
    sigma = share @ np.array([0.05, 0.005, 0.02])
    rng = np.random.default_rng(11)
    res = rng.standard_t(6, (H, W, 3)) * sigma[..., None]
    assert _misfit(res, on, cov)[on].mean() < 0.02
    disc = on & (cov[..., 0] > 0.99)
    assert np.std(smoothed_on_marker(res, cov, 1.5)[disc]) < 0.5 * np.std(res[disc])
    ys, xs = np.nonzero(disc)
    y0, x0 = ys[len(ys) // 2], xs[len(xs) // 2]
    res[y0, x0] += 1.0
    assert _misfit(res, on, cov)[y0, x0]
