"""core.emva and core.sensor_presets: the EMVA 1288 sensor model, measured back by the standard's
own photon transfer method, and the presets' validation.

Tolerances are stated beside each check; the statistical ones are many standard errors wide
(256 x 256 px: the relative standard error of a variance is sqrt(2 / 65536) = 0.55 %)."""
import math
from dataclasses import replace

import numpy as np
import pytest

from dockfactory.core.camera_chain import emva
from dockfactory.core.camera_chain.emva import EmvaSensor, expose, fixed_patterns, photon_transfer, with_adc_bits
from dockfactory.core.sensor_presets import PRESETS, preset, with_overrides

SIZE = 256
EXPOSURE_S = 0.01          # 10 ms: the presets' dark current adds at most 0.1 e- here
UNIT_SEED = 1288
# dark, then up to 70 % of the full well: 10 levels, as the brief's flat-field series
PTC_LEVELS = (0.0, 0.01, 0.02, 0.05, 0.1, 0.2, 0.3, 0.4, 0.5, 0.7)


def _flat(electrons: float, size: int = SIZE) -> np.ndarray:
    return np.full((size, size), electrons, np.float32)


def _pair_var(a, b) -> float:
    return 0.5 * float(np.var(a.astype(np.float64) - b.astype(np.float64)))


def _ptc_pairs(sensor: EmvaSensor, seed: int, levels=PTC_LEVELS):
    patterns = fixed_patterns(sensor, UNIT_SEED, SIZE, SIZE)
    rng = np.random.default_rng(seed)
    shot = [(_flat(f * sensor.saturation_e), _flat(0.0)) for f in levels]
    return [tuple(expose(e, sensor, EXPOSURE_S, rng, patterns) for e in (lit, lit, dark, dark))
            for lit, dark in shot]


# ------------------------------------------------------------------ photon transfer (EMVA 1288)
@pytest.mark.parametrize("name", sorted(PRESETS))
def test_photon_transfer_recovers_gain_and_dark_noise_within_5_percent(name):
    """DSNU and PRNU are on (the presets' own); the frame differences cancel them."""
    sensor = preset(name)
    assert sensor.dsnu_dn > 0 and sensor.prnu_pct > 0
    ptc = photon_transfer(_ptc_pairs(sensor, seed=1))
    assert ptc["in_fit"].sum() >= 5 and ptc["dark_noise_resolved"]
    assert ptc["K"] == pytest.approx(sensor.gain_dn_per_e, rel=0.05)
    # the measured dark noise includes the dark current's shot noise over the exposure
    expected_dark = math.hypot(sensor.dark_noise_e, math.sqrt(sensor.dark_current_e_per_s * EXPOSURE_S))
    assert ptc["dark_noise_e"] == pytest.approx(expected_dark, rel=0.05)
    assert ptc["dark_noise_e"] == pytest.approx(sensor.dark_noise_e, rel=0.05)


@pytest.mark.parametrize("bits", [10, 14])
def test_photon_transfer_at_another_adc_depth(bits):
    """The same sensor at 10 and 14 bits: K scales by 2**(bits - 12) (within 5 %). At 14 bits the
    dark noise (3.4 DN) is recovered within 5 %; at 10 bits it is 0.21 DN, below the standard's
    0.5 DN floor where rounding hides it, and the result says so."""
    base = preset("imx174")
    sensor = with_adc_bits(base, bits)
    ptc = photon_transfer(_ptc_pairs(sensor, seed=2))
    assert ptc["K"] == pytest.approx(base.gain_dn_per_e * 2.0 ** (bits - 12), rel=0.05)
    assert ptc["dark_noise_resolved"] is (bits == 14)
    if bits == 14:
        assert ptc["dark_noise_e"] == pytest.approx(sensor.dark_noise_e, rel=0.05)


def test_photon_transfer_points_and_errors():
    sensor = preset("imx250")
    pairs = _ptc_pairs(sensor, seed=3, levels=(0.1, 0.3))
    ptc = photon_transfer(pairs, saturation_mean_dn=sensor.max_code)
    assert ptc["mean_dn"].shape == ptc["var_dn2"].shape == ptc["in_fit"].shape == (2,)
    # mean above dark is K * electrons within 0.5 %
    np.testing.assert_allclose(ptc["mean_dn"], np.array([0.1, 0.3]) * sensor.saturation_e
                               * sensor.gain_dn_per_e, rtol=0.005)
    with pytest.raises(ValueError, match="at least 2 levels"):
        photon_transfer(pairs[:1])
    with pytest.raises(ValueError, match="fewer than 2 levels"):
        photon_transfer(pairs, saturation_mean_dn=sensor.black_level_dn + 10.0)
    a = pairs[0][0]
    with pytest.raises(ValueError, match="equal"):
        photon_transfer([(a, a[:-1], a, a), pairs[1]])


# ------------------------------------------------------------------------------ fixed patterns
def test_fixed_patterns_are_the_units_and_not_the_frames():
    """Same seed: bit-for-bit equal patterns (after the cache is cleared, and whatever frame rngs
    ran in between); with the temporal noise off, dark frames drawn with different rngs are
    bit-for-bit equal: round(black level + DSNU)."""
    sensor = with_overrides(preset("imx250"), {"dark_noise_e": 0.0, "dark_current_e_per_s": 0.0,
                                               "dsnu_dn": 3.0})
    first = [p.copy() for p in fixed_patterns(sensor, 11, 64, 80)]
    frames = [expose(_flat(0.0, 64)[:, :1].repeat(80, 1), sensor, 0.02, np.random.default_rng(s),
                     fixed_patterns(sensor, 11, 64, 80)) for s in (1, 2, 3)]
    emva._unit_patterns.cache_clear()
    emva._scaled_patterns.cache_clear()
    again = fixed_patterns(sensor, 11, 64, 80)
    for p, q in zip(first, again):
        assert p.dtype == np.float32 and p.shape == (64, 80)
        assert np.array_equal(p, q)
    assert np.array_equal(frames[0], frames[1]) and np.array_equal(frames[1], frames[2])
    expected = np.rint(sensor.black_level_dn + first[0].astype(np.float64)).astype(np.uint16)
    assert np.array_equal(frames[0], expected)


def test_fixed_patterns_differ_between_units_and_match_their_figures():
    sensor = with_overrides(preset("imx174"), {"dsnu_dn": 1.5, "prnu_pct": 1.2})
    dsnu, prnu = fixed_patterns(sensor, 5, 512, 512)
    other_dsnu, other_prnu = fixed_patterns(sensor, 6, 512, 512)
    assert not np.array_equal(dsnu, other_dsnu) and not np.array_equal(prnu, other_prnu)
    # independent units: correlation within 0.02 (its standard error is 1/512 = 0.002)
    assert abs(np.corrcoef(dsnu.ravel(), other_dsnu.ravel())[0, 1]) < 0.02
    assert abs(np.corrcoef(prnu.ravel(), other_prnu.ravel())[0, 1]) < 0.02
    assert abs(np.corrcoef(dsnu.ravel(), prnu.ravel())[0, 1]) < 0.02    # DSNU, PRNU independent
    # spreads within 2 % of the configured figures (standard error of a std: 1/sqrt(2N) = 0.14 %)
    assert float(np.std(dsnu)) == pytest.approx(1.5, rel=0.02)
    assert 100 * float(np.std(prnu)) == pytest.approx(1.2, rel=0.02)
    assert abs(float(np.mean(dsnu))) < 0.02 and abs(float(np.mean(prnu)) - 1) < 1e-3
    with pytest.raises(ValueError):
        dsnu[0, 0] = 1.0                      # shared and read-only


def test_fixed_patterns_follow_the_unit_across_adc_depths():
    """A unit keeps its pattern: at 16 bits the DSNU field is the 12-bit one times 16."""
    sensor = preset("imx273")
    dsnu12, prnu12 = fixed_patterns(sensor, 9, 32, 48)
    dsnu16, prnu16 = fixed_patterns(with_adc_bits(sensor, 16), 9, 32, 48)
    np.testing.assert_allclose(dsnu16, 16 * dsnu12, rtol=1e-6)
    assert np.array_equal(prnu12, prnu16)


@pytest.mark.parametrize("args, word", [((-1, 8, 8), "seed"), ((1.5, 8, 8), "seed"),
                                        ((True, 8, 8), "seed"), ((1, 0, 8), "height"),
                                        ((1, 8, 2.0), "width")])
def test_fixed_patterns_refuse_bad_arguments(args, word):
    with pytest.raises(ValueError, match=word):
        fixed_patterns(preset("imx174"), *args)


# ---------------------------------------------------------------------- saturation, linearity
@pytest.mark.parametrize("name", sorted(PRESETS))
def test_bright_flat_field_clips_at_the_full_well(name):
    """3x the full well: every pixel reads K * saturation + black level + DSNU + dark noise; the
    mean within 0.5 DN of K * saturation + black level, the spread that of the dark noise and
    DSNU only (no shot noise: within 10 %)."""
    sensor = preset(name)
    assert sensor.gain_dn_per_e * sensor.saturation_e + sensor.black_level_dn < sensor.max_code
    frame = expose(_flat(3 * sensor.saturation_e), sensor, EXPOSURE_S, np.random.default_rng(4),
                   fixed_patterns(sensor, UNIT_SEED, SIZE, SIZE))
    top = sensor.gain_dn_per_e * sensor.saturation_e + sensor.black_level_dn
    assert float(frame.mean()) == pytest.approx(top, abs=0.5)
    spread = math.sqrt((sensor.gain_dn_per_e * sensor.dark_noise_e) ** 2 + sensor.dsnu_dn ** 2 + 1 / 12)
    assert float(frame.std()) == pytest.approx(spread, rel=0.10)
    assert frame.max() <= sensor.max_code


def test_the_adc_clips_when_the_full_well_is_beyond_it():
    """K * saturation 4 % over the 12-bit range (accepted): a bright field is all top code; at
    8 bits the same sensor tops out at 255."""
    base = preset("imx174")
    gain = (1.04 * base.max_code - base.black_level_dn) / base.saturation_e
    sensor = with_overrides(base, {"gain_dn_per_e": gain})
    bright = _flat(2 * sensor.saturation_e, 64)
    frame = expose(bright, sensor, EXPOSURE_S, np.random.default_rng(5), fixed_patterns(sensor, 1, 64, 64))
    assert frame.dtype == np.uint16 and np.all(frame == 4095)
    eight = with_adc_bits(sensor, 8)
    frame8 = expose(bright, eight, EXPOSURE_S, np.random.default_rng(5), fixed_patterns(eight, 1, 64, 64))
    assert np.all(frame8 == 255)


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_mean_response_is_linear_below_saturation(name):
    """From 2 % to 85 % of the full well, mean signal above dark = K * electrons within 0.5 %."""
    sensor = preset(name)
    patterns = fixed_patterns(sensor, UNIT_SEED, SIZE, SIZE)
    rng = np.random.default_rng(6)
    dark = float(expose(_flat(0.0), sensor, EXPOSURE_S, rng, patterns).mean())
    for fraction in (0.02, 0.1, 0.25, 0.5, 0.7, 0.85):
        electrons = fraction * sensor.saturation_e
        signal = float(expose(_flat(electrons), sensor, EXPOSURE_S, rng, patterns).mean()) - dark
        assert signal == pytest.approx(sensor.gain_dn_per_e * electrons, rel=0.005), fraction


def test_dark_current_grows_with_exposure_time():
    """100 e-/s: the mean dark signal grows by K * 100 * t (within 2 %) and its temporal variance
    by K^2 * 100 * t (the dark current's shot noise, within 5 %)."""
    sensor = with_overrides(preset("imx174"), {"dark_current_e_per_s": 100.0})
    patterns = fixed_patterns(sensor, UNIT_SEED, SIZE, SIZE)
    rng = np.random.default_rng(7)
    zero = _flat(0.0)
    frames = {t: (expose(zero, sensor, t, rng, patterns), expose(zero, sensor, t, rng, patterns))
              for t in (0.0, 0.5, 1.0, 2.0)}
    mean0, var0 = float(frames[0.0][0].mean()), _pair_var(*frames[0.0])
    k = sensor.gain_dn_per_e
    for t in (0.5, 1.0, 2.0):
        assert float(frames[t][0].mean()) - mean0 == pytest.approx(k * 100 * t, rel=0.02), t
        assert _pair_var(*frames[t]) - var0 == pytest.approx(k * k * 100 * t, rel=0.05), t


# ------------------------------------------------------------------------------- determinism
def test_same_rng_seed_same_frame_and_no_global_random_state():
    sensor = preset("imx250")
    patterns = fixed_patterns(sensor, UNIT_SEED, 48, 64)
    scene = np.random.default_rng(0).uniform(0, sensor.saturation_e, (48, 64)).astype(np.float32)
    state = np.random.get_state()
    a = expose(scene, sensor, 0.02, np.random.default_rng(42), patterns)
    b = expose(scene, sensor, 0.02, np.random.default_rng(42), patterns)
    c = expose(scene, sensor, 0.02, np.random.default_rng(43), patterns)
    assert a.dtype == np.uint16 and a.shape == (48, 64)
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    after = np.random.get_state()
    assert after[0] == state[0] and np.array_equal(after[1], state[1]) and after[2:] == state[2:]


def test_expose_does_not_modify_its_input():
    sensor = preset("imx273")
    scene = _flat(1000.0, 16)
    expose(scene, sensor, 0.01, np.random.default_rng(1), fixed_patterns(sensor, 1, 16, 16))
    assert np.all(scene == 1000.0)


# ------------------------------------------------------------------- validation and overrides
def test_presets_are_valid_and_named_in_lower_case():
    assert {"imx174", "imx250", "imx273"} <= set(PRESETS)
    for name, sensor in PRESETS.items():
        assert name == name.lower() and sensor.validate(name) is sensor and sensor.adc_bits == 12
        assert all(0 < q <= 1 for q in sensor.quantum_efficiency)
        assert preset(name) is sensor


def test_validation_message_is_one_line_naming_field_and_value():
    bad = replace(preset("imx174"), dark_noise_e=-1)
    with pytest.raises(ValueError) as info:
        bad.validate("sensor preset 'x'")
    assert str(info.value) == "sensor preset 'x': dark_noise_e must be >= 0, got -1"


def test_unknown_preset_names_it_and_lists_the_known_ones():
    with pytest.raises(ValueError) as info:
        preset("imx999")
    message = str(info.value)
    assert "'imx999'" in message and all(name in message for name in PRESETS) and "\n" not in message


@pytest.mark.parametrize("overrides, words", [
    ({"dark_noise_e": -1.0}, ("dark_noise_e", "-1.0")),
    ({"saturation_e": float("nan")}, ("saturation_e", "nan")),
    ({"dark_current_e_per_s": float("inf")}, ("dark_current_e_per_s", "inf")),
    ({"saturation_e": 0.0}, ("saturation_e", "0.0")),
    ({"gain_dn_per_e": -0.1}, ("gain_dn_per_e", "-0.1")),
    ({"dsnu_dn": -2.0}, ("dsnu_dn", "-2.0")),
    ({"prnu_pct": 50.0}, ("prnu_pct", "50.0")),
    ({"quantum_efficiency": (0.5, 1.2, 0.5)}, ("quantum_efficiency[G]", "1.2")),
    ({"quantum_efficiency": [0.5, 0.6, 0.0]}, ("quantum_efficiency[B]", "0.0")),
    ({"quantum_efficiency": (0.5, 0.6)}, ("quantum_efficiency", "(0.5, 0.6)")),
    ({"adc_bits": 7}, ("adc_bits", "7")),
    ({"adc_bits": 17}, ("adc_bits", "17")),
    ({"adc_bits": 12.0}, ("adc_bits", "12.0")),
    ({"adc_bits": True}, ("adc_bits", "True")),
    ({"black_level_dn": -5.0}, ("black_level_dn", "-5.0")),
    ({"gain_dn_per_e": 1.0}, ("gain_dn_per_e", "1.0")),       # K * saturation far past 4095
    ({"read_noise_e": 2.0}, ("read_noise_e",)),               # unknown field
])
def test_bad_overrides_name_the_key_and_value(overrides, words):
    with pytest.raises(ValueError) as info:
        with_overrides(preset("imx174"), overrides, where="camera config [sensor]")
    message = str(info.value)
    assert message.startswith("camera config [sensor]: ") and "\n" not in message
    for word in words:
        assert word in message, (word, message)


def test_overrides_replace_only_the_named_fields():
    base = preset("imx250")
    changed = with_overrides(base, {"prnu_pct": 1.0, "quantum_efficiency": [0.4, 0.5, 0.45]})
    assert changed.prnu_pct == 1.0 and changed.quantum_efficiency == (0.4, 0.5, 0.45)
    assert replace(changed, prnu_pct=base.prnu_pct, quantum_efficiency=base.quantum_efficiency) == base
    assert with_overrides(base, {}) == base
    with pytest.raises(ValueError, match="dict"):
        with_overrides(base, [("prnu_pct", 1.0)])


def test_with_adc_bits_scales_the_dn_figures():
    base = preset("imx174")
    eight = with_adc_bits(base, 8)
    assert eight.adc_bits == 8 and eight.max_code == 255
    assert eight.gain_dn_per_e == pytest.approx(base.gain_dn_per_e / 16)
    assert eight.dsnu_dn == pytest.approx(base.dsnu_dn / 16)
    assert eight.black_level_dn == pytest.approx(base.black_level_dn / 16)
    assert (eight.saturation_e, eight.dark_noise_e, eight.prnu_pct) == \
        (base.saturation_e, base.dark_noise_e, base.prnu_pct)
    assert with_adc_bits(eight, 12) == base
    for bits in (7, 17, 10.0, True):
        with pytest.raises(ValueError, match="adc bits"):
            with_adc_bits(base, bits)


@pytest.mark.parametrize("change, word", [
    (lambda e, p: (-e, p, np.random.default_rng(0)), "electrons_mean"),
    (lambda e, p: (np.where(e > 0, np.nan, e), p, np.random.default_rng(0)), "electrons_mean"),
    (lambda e, p: (e[None], p, np.random.default_rng(0)), "electrons_mean"),
    (lambda e, p: (e, (p[0], p[1][:-1]), np.random.default_rng(0)), "patterns"),
    (lambda e, p: (e, p, np.random.RandomState(0)), "rng"),
    (lambda e, p: (e, p, None), "rng"),
])
def test_expose_refuses_bad_input(change, word):
    sensor = preset("imx174")
    electrons, patterns, rng = change(_flat(100.0, 8), fixed_patterns(sensor, 1, 8, 8))
    with pytest.raises(ValueError, match=word):
        expose(electrons, sensor, 0.01, rng, patterns)
    with pytest.raises(ValueError, match="exposure_s"):
        expose(_flat(1.0, 8), sensor, -0.01, np.random.default_rng(0), fixed_patterns(sensor, 1, 8, 8))
    with pytest.raises(ValueError, match="EmvaSensor"):
        expose(_flat(1.0, 8), "imx174", 0.01, np.random.default_rng(0), fixed_patterns(sensor, 1, 8, 8))


@pytest.mark.parametrize("share", [0.001, 0.3, 0.9, 0.9995])
def test_temporal_variance_is_shot_plus_dark_noise_up_to_the_full_well(share):
    """One Gaussian draw stands for shot + dark noise away from the full well, two exact steps
    near it: the pair variance of a flat field is K^2 (mu + dark^2) + 1/12 within 4 % below the
    clip, and at 0.9995 of the full well (every pixel on the exact path) the mean sits below the
    unclipped value by the clip's share."""
    sensor = preset("imx273")
    mu = share * sensor.saturation_e
    pats = fixed_patterns(sensor, UNIT_SEED, SIZE, SIZE)
    a, b = (expose(_flat(mu), sensor, EXPOSURE_S, np.random.default_rng(k), pats).astype(float) for k in (11, 12))
    var = np.var(a - b) / 2
    expected = sensor.gain_dn_per_e ** 2 * (mu + sensor.dark_current_e_per_s * EXPOSURE_S + sensor.dark_noise_e ** 2) + 1 / 12
    near = mu + emva.NEAR_FULL_WELL_SIGMAS * math.sqrt(mu) >= sensor.saturation_e
    if share < 0.99:
        assert not near and var == pytest.approx(expected, rel=0.04)
    else:
        assert near   # clipped: less spread and a lower mean than without the full well
        assert var < expected and a.mean() < sensor.black_level_dn + sensor.gain_dn_per_e * mu
