"""The sensor's temporal noise in the design predictor (eval.design_sensor, the card's
``sensor_noise``): the relative variance against the factory's own sensors, the factor a design
gets, the card's key and its errors, and the share's fit (bench/design/sensor_share.py)."""
from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest

from bench.design.sensor_share import fit_share
from dockfactory.core.camera_chain.colour_sensor import configured_sensor
from dockfactory.core.camera_chain.emva import expose
from dockfactory.core.camera_chain.plain_sensor import plain_dn
from dockfactory.core.config import SensorConfig
from dockfactory.core.errors import DockfactoryError
from dockfactory.core.resources import shipped_design_card
from dockfactory.core.scene import SensorParams
from dockfactory.eval.design_card import load_design_card
from dockfactory.eval.design_sensor import SIGNAL, camera_variance, preset_variance, relative_variance, sensor_factor
from dockfactory.eval.design_space import Camera, Design, Lens

SHAPE = (256, 256)


def _temporal(frame_a: np.ndarray, frame_b: np.ndarray, black: float = 0.0) -> float:
    """Temporal variance over the squared mean signal of two frames of one flat field (their
    difference removes every fixed pattern)."""
    a, b = frame_a.astype(np.float64), frame_b.astype(np.float64)
    return float(np.var(a - b) / 2.0 / (0.5 * (a.mean() + b.mean()) - black) ** 2)


@pytest.mark.parametrize("full, read", [(8000.0, 4.0), (20000.0, 2.0), (2000.0, 6.0)])
def test_the_relative_variance_is_the_plain_sensor_s_own(full, read):
    """A flat field at SIGNAL through the factory's plain sensor: the measured temporal variance
    over the squared signal within 4 % of relative_variance (quantisation included at 12 bits)."""
    p = SensorParams(False, 0.0, 0.0, full, read, 12, 0.0, 0.0, 0)
    rng = np.random.default_rng(1)
    frames = [plain_dn(np.full((*SHAPE, 3), SIGNAL, np.float32), p, rng) for _ in range(2)]
    expected = relative_variance(full, read, 4095.0 / full)
    assert _temporal(*frames) == pytest.approx(expected, rel=0.04)


@pytest.mark.parametrize("name", ["imx273", "imx174"])
def test_a_preset_s_relative_variance_is_its_emva_sensor_s_own(name):
    """The EMVA chain's exposure of a flat field at SIGNAL of the full well (fixed patterns removed by
    the difference of two frames): within 4 % of preset_variance."""
    s = configured_sensor(name, (), 12)
    patterns = (np.zeros(SHAPE, np.float32), np.ones(SHAPE, np.float32))
    rng = np.random.default_rng(2)
    mean_e = np.full(SHAPE, SIGNAL * s.saturation_e, np.float32)
    frames = [expose(mean_e, s, 0.0, rng, patterns) for _ in range(2)]
    assert _temporal(*frames, black=s.black_level_dn) == pytest.approx(preset_variance(name), rel=0.04)


def test_a_deeper_well_has_less_noise_and_the_dark_noise_adds():
    assert relative_variance(2 * 10000.0, 0.0) == pytest.approx(relative_variance(10000.0, 0.0) / 2)
    assert relative_variance(10000.0, 30.0) - relative_variance(10000.0, 0.0) == pytest.approx(900.0 / (SIGNAL * 1e4) ** 2)
    assert preset_variance("imx174") < 0.5 * preset_variance("imx273")   # 32.7 ke- against 10.5 ke- wells


def test_the_camera_variance_takes_the_preset_with_the_scene_s_overrides_else_its_plain_sensor():
    plain = SensorConfig(full_well_e=(8000.0, 20000.0), read_noise_e=(2.0, 6.0))
    assert camera_variance("", plain) == pytest.approx(relative_variance(14000.0, 4.0))
    deeper = replace(plain, overrides=(("saturation_e", 40000.0), ("gain_dn_per_e", 0.095)))
    assert camera_variance("imx273", plain) == pytest.approx(preset_variance("imx273"))
    assert camera_variance("imx273", deeper) < 0.5 * camera_variance("imx273", plain)


def _card(tmp_path, sensor_noise) -> object:
    data = json.loads(shipped_design_card().read_text())
    data.pop("sensor_noise", None)
    if sensor_noise is not None:
        data["sensor_noise"] = sensor_noise
    path = tmp_path / "card.json"
    path.write_text(json.dumps(data))
    return path


def _design(cfa: str, preset: str) -> Design:
    return Design(Camera("cam", 1920, 1200, 5.86, cfa, preset), Lens(12.0), (2000.0, 2800.0), 30.0, "dark", 7, "png")


@pytest.mark.parametrize("cfa", ["none", "rggb"])
def test_a_design_s_centre_noise_scales_by_its_sensor_s_factor(tmp_path, cfa):
    """The card's scale for an IMX174 design over the same card without sensor_noise is
    sqrt(1 - s + s v174 / v273); the reference sensor's own design keeps the card's scale."""
    share = {"none": 0.3, "rggb": 0.2}
    with_term = load_design_card(_card(tmp_path, {"reference": "imx273", "share": share}))
    without = load_design_card(_card(tmp_path / "..", None))
    v174, v273 = preset_variance("imx174"), preset_variance("imx273")
    d = _design(cfa, "imx174")
    got = with_term.noise_of(d, v174)[0].scale_px / without.noise_of(d, v174)[0].scale_px
    assert got == pytest.approx(math.sqrt(1 - share[cfa] + share[cfa] * v174 / v273), rel=1e-12)
    assert got < 0.95
    assert with_term.noise_of(_design(cfa, "imx273"), v273)[0].scale_px == pytest.approx(without.noise_of(d)[0].scale_px)
    assert with_term.noise_of(d)[0].scale_px == without.noise_of(d)[0].scale_px   # no variance: the reference


@pytest.mark.parametrize("cfa, fmt", [("none", "jpeg90"), ("rggb", "jpeg95")])
def test_a_jpeg_design_s_encoding_noise_does_not_follow_the_sensor(tmp_path, cfa, fmt):
    """A JPEG design's variance is the reference sensor's J^2 - 1 for the encoding plus its own
    sensor's PNG part: for an IMX174 camera the scale over the same card without sensor_noise is
    sqrt(J^2 - 1 + f^2) / J (f the PNG factor, below 0.95), within 1 % of 1 for the card's J."""
    share = {"none": 0.3, "rggb": 0.2}
    with_term = load_design_card(_card(tmp_path, {"reference": "imx273", "share": share}))
    without = load_design_card(_card(tmp_path / "..", None))
    v174, v273 = preset_variance("imx174"), preset_variance("imx273")
    d = replace(_design(cfa, "imx174"), image_format=fmt)
    jpeg = with_term.jpeg_of(int(fmt[4:]))[0]["dark"][cfa]
    f = math.sqrt(1 - share[cfa] + share[cfa] * v174 / v273)
    got = with_term.noise_of(d, v174)[0].scale_px / without.noise_of(d, v174)[0].scale_px
    assert got == pytest.approx(math.sqrt(jpeg ** 2 - 1 + f ** 2) / jpeg, rel=1e-12)
    assert f < 0.95 and 0.99 < got < 1.0
    assert with_term.sensor_factor_of(d, v174) == pytest.approx(got, rel=1e-12)   # what the answer reports
    ref = replace(_design(cfa, "imx273"), image_format=fmt)
    assert with_term.noise_of(ref, v273)[0].scale_px == pytest.approx(without.noise_of(ref)[0].scale_px, rel=1e-12)


def test_the_shipped_card_has_a_sensor_term():
    card = load_design_card(shipped_design_card())
    assert card.sensor_reference == "imx273"
    assert all(0.0 < v < 1.0 for v in card.sensor_share.values())


@pytest.mark.parametrize("table, needle", [
    ({"reference": "imx999", "share": {"none": 0.3, "rggb": 0.3}}, "sensor_noise.reference: unknown sensor preset"),
    ({"reference": "imx273", "share": {"none": 1.5, "rggb": 0.3}}, "sensor_noise.share.none: expected a share in [0, 1]"),
    ({"reference": "imx273", "share": {"none": 0.3}}, "sensor_noise.share: expected a table of none, rggb"),
    ({"share": {"none": 0.3, "rggb": 0.3}}, "sensor_noise: expected a table of reference, share"),
])
def test_a_bad_sensor_noise_table_is_one_line(tmp_path, table, needle):
    with pytest.raises(DockfactoryError) as exc:
        load_design_card(_card(tmp_path, table))
    assert needle in str(exc.value) and "\n" not in str(exc.value)


def test_the_share_fit_recovers_a_known_share_and_stays_in_0_1():
    v = [0.25, 0.01, 0.32, 0.25, 0.01, 0.32]
    noise = [0.01, -0.02, 0.015, -0.01, 0.02, -0.015]
    pts = [{"v_ratio": r, "centre_var_ratio": 1 - 0.3 * (1 - r) + e} for r, e in zip(v, noise)]
    assert fit_share(pts) == pytest.approx(0.3, abs=0.02)
    assert fit_share([{"v_ratio": 0.1, "centre_var_ratio": 1.3}]) == 0.0
    assert fit_share([{"v_ratio": 0.1, "centre_var_ratio": -1.0}]) == 1.0
    assert fit_share([]) == 0.0
    assert sensor_factor(0.0, 0.1) == 1.0 and sensor_factor(1.0, 0.25) == pytest.approx(0.5)


def test_a_design_outside_the_card_s_disc_sizes_is_flagged_and_one_inside_is_not(tmp_path):
    """The card's fitted_on.disc_minor_median_px bounds the designs it predicts without a flag."""
    card = load_design_card(shipped_design_card())
    low, high = card.disc_range_px
    assert 0 < low < high
    assert card.outside_range(0.5 * (low + high)) == ""
    line = card.outside_range(high * 1.5)
    assert line.startswith("extrapolated") and f"{high * 1.5:.1f} px" in line and "\n" not in line
    assert card.outside_range(low / 2) != "" and card.outside_range(None) == ""
    data = json.loads(shipped_design_card().read_text())
    data["fitted_on"].pop("disc_minor_median_px")
    path = tmp_path / "old.json"
    path.write_text(json.dumps(data))
    assert load_design_card(path).outside_range(1000.0) == ""   # a card that does not say: no flag
