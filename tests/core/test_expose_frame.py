"""The camera chain between the lens and the encoding (core.camera_chain.expose_frame) of a camera
without [sensor] presets: auto exposure, exposure offset, vignetting and veiling glare (light), the
plain sensor's noise and ADC, its ISP (digital gain, sRGB); an ideal camera."""
import numpy as np
import pytest

from dockfactory.core.camera_chain import expose_frame
from dockfactory.core.camera_chain.isp import _srgb_lut
from dockfactory.core.camera_chain.light import TARGET_GREY, auto_exposure_scale
from dockfactory.core.scene import SensorParams


def params(**kw):
    base = dict(ideal=False, exposure_ev=0.0, gain_ev=0.0, full_well_e=10000.0, read_noise_e=4.0,
                adc_bits=12, vignetting=0.0, bloom=0.0, noise_seed=1)
    base.update(kw)
    return SensorParams(**base)


def apply_sensor(linear, p):
    """(8-bit image, derived values) of ``expose_frame``."""
    image, _, derived = expose_frame(linear, p)
    return image, derived


def flat(value, h=200, w=300):
    return np.full((h, w, 3), value, np.float32)


def test_auto_exposure_brings_mean_to_grey():
    img = flat(0.05)
    assert auto_exposure_scale(img) == pytest.approx(TARGET_GREY / 0.05, rel=1e-5)


def test_ideal_is_noise_free_srgb():
    out, derived = apply_sensor(flat(0.3), params(ideal=True))
    assert out.dtype == np.uint8 and out.shape == (200, 300, 3)
    assert np.ptp(out) == 0
    srgb = 1.055 * TARGET_GREY ** (1 / 2.4) - 0.055
    assert abs(int(out[0, 0, 0]) - srgb * 255) <= 1
    assert derived["auto_exposure_scale"] == pytest.approx(0.6, rel=1e-5)


def test_noise_statistics_match_shot_and_read_noise():
    # work in DN before sRGB: with a linear LUT-free check via the electron model
    p = params(full_well_e=1000.0, read_noise_e=5.0, adc_bits=16)
    out, _ = apply_sensor(flat(0.5, 400, 400), p)
    # invert the sRGB LUT to linear and compare the spread to sqrt(e + r^2) / full_well
    lut = _srgb_lut(2 ** 16).astype(np.float64)
    inv = np.interp(np.arange(256), lut, np.arange(2 ** 16) / (2 ** 16 - 1))
    lin = inv[out[..., 1].astype(int)]
    e = TARGET_GREY * 1000.0
    expected_sigma = np.sqrt(e + 25.0) / 1000.0
    assert lin.mean() == pytest.approx(TARGET_GREY, rel=0.03)
    assert lin.std() == pytest.approx(expected_sigma, rel=0.15)  # 8-bit output quantisation adds a bit


def test_low_light_is_darker_and_noisier_and_seeded():
    img = np.random.default_rng(0).uniform(0.05, 0.5, (240, 320, 3)).astype(np.float32)
    img[:] = img.mean()
    normal, _ = apply_sensor(img, params())
    dark, _ = apply_sensor(img, params(exposure_ev=-4.0, gain_ev=2.0))
    assert dark.mean() < normal.mean() - 20
    rel = lambda a: a.std() / a.mean()  # noqa: E731
    assert rel(dark.astype(float)) > 2 * rel(normal.astype(float))
    again, _ = apply_sensor(img, params(exposure_ev=-4.0, gain_ev=2.0))
    assert np.array_equal(dark, again)
    other, _ = apply_sensor(img, params(exposure_ev=-4.0, gain_ev=2.0, noise_seed=2))
    assert not np.array_equal(dark, other)


def test_vignetting_darkens_corners_and_bloom_spreads_light():
    out, _ = apply_sensor(flat(0.2), params(vignetting=0.4, read_noise_e=0.0, full_well_e=1e6))
    assert out[100, 150].mean() > out[0, 0].mean() + 10
    img = flat(0.05, 240, 320)
    img[100:110, 150:160] = 500.0  # a lamp
    no_bloom, _ = apply_sensor(img, params(read_noise_e=0.0, full_well_e=1e6))
    bloom, _ = apply_sensor(img, params(read_noise_e=0.0, full_well_e=1e6, bloom=0.08))
    near = bloom[105, 140].astype(int).mean() - no_bloom[105, 140].astype(int).mean()
    far = bloom[10, 10].astype(int).mean() - no_bloom[10, 10].astype(int).mean()
    assert near > 10            # a halo around the lamp
    assert 0 <= far < near / 3  # the veil fades with distance: the frame is not washed out
    assert np.median(bloom) < np.median(no_bloom) + 10


def test_nan_in_render_does_not_propagate():
    img = flat(0.2)
    img[5, 5] = np.nan
    out, _ = apply_sensor(img, params())
    assert out.dtype == np.uint8


def test_shape_is_checked():
    with pytest.raises(ValueError, match="linear image"):
        apply_sensor(np.zeros((10, 10)), params())
