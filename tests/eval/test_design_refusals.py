"""Frames without a pose simulated per design (eval.design_refusals): the design's drawn test frames
through the real solve and gate. A camera class the gate tests at the card's noise is not
simulated; centres far noisier than the gate allows are refused, centres at the card's noise are
not; the same space draws the same frames; the card's section is checked in one line; a design
row folds the simulated share into P(accept)."""
from __future__ import annotations


import json
from pathlib import Path

import numpy as np
import pytest

from bench.design.centre_tails import card_tail, mixture_fit
from dockfactory.core.config import load_config
from dockfactory.core.errors import DockfactoryError
from design_cards import card_with
from dockfactory.core.resources import resolve_config
from dockfactory.eval.acceptance import load_acceptance
from dockfactory.eval.design_predict import NoiseClass, design_config
from dockfactory.eval.design_card import with_refusals
from dockfactory.eval.design_rank import all_posed_probability, design_row
from dockfactory.eval.design_report import _no_pose_note
from dockfactory.eval.design_refusals import GateFigures, design_camera_class, simulated_no_pose, tail_scales
from dockfactory.eval.design_space import Camera, Design, DesignSpace, Lens

CARD_NOISE = 0.0125
GATE = GateFigures(CARD_NOISE, 0.0062, (0.0013, 0.0), 1.0)
SIM = {"noise_factor": 1.0, "centre_noise_px": CARD_NOISE, "core_px": 0.0062, "section_shift_px": [0.0013, 0.0]}
FRAMES = 8


def _design(cfa: str, fmt: str) -> Design:
    return Design(Camera("cam", 1440, 1080, 3.45, cfa, "imx273"), Lens(8.0), (1300.0, 2000.0), 20.0, "dark", 7, fmt)


def _space() -> DesignSpace:
    return DesignSpace("space.toml", resolve_config("quick"), None, FRAMES, (0, 0), FRAMES, 0, 0.0, (), (), {})


def _cfg(design: Design):
    return design_config(load_config(resolve_config("quick")), design, _space(), FRAMES)


def _noise(scale_px: float) -> NoiseClass:
    return NoiseClass(scale_px, (0.0, 0.0))


def test_the_camera_class_of_a_design_follows_its_cfa_and_format():
    assert [design_camera_class(_design(c, f)) for c, f in (("none", "png"), ("rggb", "png"), ("none", "jpeg90"),
                                                            ("rggb", "jpeg95"))] == ["three-chip", "bayer", "jpeg", "bayer-jpeg"]


def test_a_class_the_gate_tests_at_the_card_s_noise_is_not_simulated():
    d = _design("none", "png")
    got = simulated_no_pose(_cfg(d), d, _noise(1.0), GATE, FRAMES, 0)
    assert got == {"camera_class": "three-chip", "simulated": 0, "refused": 0, "rate": 0.0, "reasons": {}}


def test_centres_at_the_card_s_noise_are_posed_and_far_noisier_ones_refused():
    """A JPEG design (class factor 4.5, the gate's test at 3x the card's noise): centres at the card's
    noise pass every frame; at 40x it (beyond 4.5 x 3 with room to spare) most frames are refused,
    each with a reason, the share their count over the frames drawn."""
    d = _design("none", "jpeg90")
    cfg = _cfg(d)
    calm = simulated_no_pose(cfg, d, _noise(CARD_NOISE), GATE, FRAMES, 0)
    assert (calm["simulated"], calm["refused"], calm["rate"]) == (FRAMES, 0, 0.0)
    wild = simulated_no_pose(cfg, d, _noise(40 * CARD_NOISE), GATE, FRAMES, 0)
    assert wild["refused"] >= FRAMES - 2 and wild["rate"] == wild["refused"] / FRAMES
    assert sum(wild["reasons"].values()) == wild["refused"]


def test_the_noise_factor_scales_the_drawn_noise():
    d = _design("none", "jpeg90")
    cfg = _cfg(d)
    wild = simulated_no_pose(cfg, d, _noise(CARD_NOISE), GateFigures(CARD_NOISE, 0.0062, None, 40.0), FRAMES, 0)
    assert wild["refused"] >= FRAMES - 2


def test_the_same_space_draws_the_same_frames():
    d = _design("rggb", "jpeg90")
    cfg = _cfg(d)
    first, again = (simulated_no_pose(cfg, d, _noise(12 * CARD_NOISE), GATE, FRAMES, 0) for _ in range(2))
    assert first == again


def _card(tmp_path, sim):
    return card_with(tmp_path, "no_pose_simulation", sim)


@pytest.mark.parametrize("sim, needle", [
    ({**SIM, "noise_factor": 0}, "no_pose_simulation.noise_factor: expected a positive number"),
    ({**SIM, "centre_noise_px": "x"}, "no_pose_simulation.centre_noise_px: expected a positive number"),
    ({**SIM, "section_shift_px": [0.1]}, "no_pose_simulation.section_shift_px: expected [x, y] px or null"),
    ({**SIM, "core_px": -1}, "no_pose_simulation.core_px: expected a positive number"),
    ([1], "no_pose_simulation: expected a table"),
])
def test_a_bad_simulation_section_is_one_line(tmp_path, sim, needle):
    with pytest.raises(DockfactoryError) as exc:
        _card(tmp_path, sim)
    assert needle in str(exc.value) and "\n" not in str(exc.value)


def test_a_design_row_folds_the_simulated_share_into_its_chances(tmp_path):
    """The same colour JPEG design under the shipped card without and with the simulation: the RMSE
    predicted is the same; at three times its predicted noise some frames are refused, and P(accept) falls by (1 - rate)^frames of the simulated rate, which the row
    reports with its counts."""
    spec = load_acceptance(resolve_config("acceptance"))
    scene = load_config(resolve_config("quick"))
    d = _design("rggb", "jpeg90")
    plain = design_row(d, _space(), scene, spec, _card(tmp_path, None))
    sim = design_row(d, _space(), scene, spec, _card(tmp_path, {**SIM, "noise_factor": 3.0}))
    nopose = sim["no_pose"]
    assert sim["predicted_rmse"] == plain["predicted_rmse"]
    assert nopose["card_key"] == "no_pose_simulation" and nopose["simulated"] == FRAMES
    assert nopose["refused"] > 0 and nopose["rate_per_frame"] == nopose["refused"] / FRAMES
    q = all_posed_probability(nopose["rate_per_frame"], FRAMES)
    assert sim["p_accept"] == pytest.approx(plain["p_accept"] * q, rel=1e-12)


def test_a_design_its_pose_errors_already_fail_is_not_simulated(tmp_path):
    """Frames without a pose can only add to a failing design's failure, so the answer skips their
    simulation (seconds a design) where the predicted pose errors alone reach ``fails_at``: the colour
    JPEG q90 design (P(reject) 0.58 on 8 frames of the cell spec) is not simulated at 0.5 and keeps
    the plain card's P(accept) and P(reject); the monochrome JPEG q95 design (P(reject) 2e-7) is."""
    spec = load_acceptance(Path(__file__).resolve().parents[2] / "configs" / "designs" / "cell_acceptance.toml")
    scene = load_config(resolve_config("quick"))
    card = _card(tmp_path, {**SIM, "noise_factor": 3.0})
    plain_card = _card(tmp_path, None)
    failing, plain = (design_row(_design("rggb", "jpeg90"), _space(), scene, spec, c, 0.5) for c in (card, plain_card))
    assert plain["p_reject"] >= 0.5
    assert failing["no_pose"]["card_key"].startswith("not simulated") and "simulated" not in failing["no_pose"]
    assert failing["no_pose"]["skipped"] is True and "skipped" not in plain["no_pose"]
    assert (failing["p_accept"], failing["p_reject"]) == (plain["p_accept"], plain["p_reject"])
    assert "not simulated: it fails on its pose errors alone" in _no_pose_note(failing["no_pose"])
    open_ = design_row(_design("none", "jpeg95"), _space(), scene, spec, card, 0.5)
    assert open_["no_pose"]["card_key"] == "no_pose_simulation" and open_["no_pose"]["simulated"] == FRAMES


def test_a_tail_keeps_the_noise_rms_and_puts_eps_of_it_m_times_out():
    rng = np.random.default_rng(1)
    s = tail_scales(200_000, (0.2, 5.0), rng)
    assert np.sqrt(np.mean(s ** 2)) == pytest.approx(1.0, rel=0.01)
    assert np.mean(s > 1.0) == pytest.approx(0.2, abs=0.005)
    assert set(np.round(np.unique(s) * np.sqrt(0.8 + 0.2 * 25), 9)) == {1.0, 5.0}
    assert np.all(tail_scales(5, None, rng) == 1.0)


def test_at_the_same_rms_a_tailed_draw_is_refused_less_than_a_gaussian_one():
    """The same JPEG design at 30x the card's noise RMS: Gaussian centres are refused on most frames;
    with three in ten centres 40 times the rest's noise (the same RMS: a core 22 times smaller) the
    solver sets the outliers aside and the core passes: the gate sees the tail's core, not its RMS,
    so the tail's shape, not only its RMS, decides a design's refusals."""
    d = _design("none", "jpeg90")
    cfg = _cfg(d)
    gauss = simulated_no_pose(cfg, d, _noise(30 * CARD_NOISE), GATE, FRAMES, 0)
    tailed = simulated_no_pose(cfg, d, _noise(30 * CARD_NOISE), GATE, FRAMES, 0, (0.3, 40.0))
    assert gauss["refused"] >= FRAMES - 2 and tailed["refused"] <= gauss["refused"] - 3


@pytest.mark.parametrize("tail, needle", [
    ({"jpeg90": {"none": [1.0, 3.0]}}, "no_pose_simulation.tail.jpeg90.none: expected [eps in [0, 1), m >= 1]"),
    ({"jpeg90": {"none": [0.1, 0.5]}}, "no_pose_simulation.tail.jpeg90.none: expected [eps in [0, 1), m >= 1]"),
    ({"tiff": {"none": [0.1, 3.0]}}, "no_pose_simulation.tail.tiff: expected 'png' or 'jpegQ'"),
    ({"png": {"mono": [0.1, 3.0]}}, "no_pose_simulation.tail.png: expected a table of none / rggb"),
    ([0.1], "no_pose_simulation.tail: expected a table of png / jpegQ"),
])
def test_a_bad_tail_table_is_one_line(tmp_path, tail, needle):
    with pytest.raises(DockfactoryError) as exc:
        _card(tmp_path, {**SIM, "tail": tail})
    assert needle in str(exc.value) and "\n" not in str(exc.value)


@pytest.mark.parametrize("cfa, fmt, tail", [("none", "png", None), ("rggb", "png", (0.13, 9.2)),
                                            ("none", "jpeg93", (0.23, 5.8)), ("rggb", "jpeg100", (0.28, 3.7))])
def test_the_card_gives_the_tail_of_the_highest_quality_at_or_below_the_design_s(tmp_path, cfa, fmt, tail):
    table = {"png": {"rggb": [0.13, 9.2]}, "jpeg90": {"none": [0.23, 5.8], "rggb": [0.28, 3.3]},
             "jpeg95": {"none": [0.23, 6.5], "rggb": [0.28, 3.7]}}
    assert _card(tmp_path, {**SIM, "tail": table}).tail_of(_design(cfa, fmt)) == tail
    assert _card(tmp_path, SIM).tail_of(_design(cfa, fmt)) is None


def test_the_tail_fit_recovers_a_contaminated_normal_and_finds_none_in_a_gaussian():
    rng = np.random.default_rng(3)
    n = 4_000
    z = rng.normal(size=n) * np.where(rng.random(n) < 0.15, 6.0, 1.0)
    z = (z - np.median(z)) / (1.4826 * np.median(np.abs(z - np.median(z))))
    fit = mixture_fit(z)
    assert fit["eps"] == pytest.approx(0.15, rel=0.25) and fit["m"] == pytest.approx(6.0, rel=0.2)
    plain = mixture_fit(rng.normal(size=n))
    assert plain["eps"] <= 0.01 and plain["nll_gain"] < 10
    assert card_tail({"bayer-jpeg95": fit, "three-chip": plain}) == {"jpeg95": {"rggb": [fit["eps"], fit["m"]]},
                                                                      "png": {"none": [plain["eps"], plain["m"]]}}


def _refusals_file(tmp_path, data) -> Path:
    path = tmp_path / "refusals.json"
    path.write_text(json.dumps(data))
    return path


def test_the_shipped_refusal_figures_load_onto_a_card_without_its_own(tmp_path):
    """The shipped figures give the shipped card a gate at the shipped noise card's figures and a tail
    per class and format; a card with its own section keeps it (the file does not override it)."""
    from dockfactory.core.resources import shipped_design_refusals
    shipped = json.loads(shipped_design_refusals().read_text())["no_pose_simulation"]
    card = with_refusals(_card(tmp_path, None), shipped_design_refusals())
    assert card.no_pose_gate == GateFigures(shipped["centre_noise_px"], shipped["core_px"],
                                            tuple(shipped["section_shift_px"]), shipped["noise_factor"])
    assert card.no_pose_tail["jpeg90"]["rggb"] == tuple(shipped["tail"]["jpeg90"]["rggb"])
    own = _card(tmp_path, SIM)
    assert with_refusals(own, shipped_design_refusals()) is own


@pytest.mark.parametrize("data, needle", [
    ({"format": "dockfactory.design_predictor/5", "no_pose_simulation": SIM}, "format: expected 'dockfactory.design_refusals/1'"),
    ({"format": "dockfactory.design_refusals/1"}, "no_pose_simulation: missing"),
    ({"format": "dockfactory.design_refusals/1", "no_pose_simulation": {**SIM, "core_px": 0}},
     "no_pose_simulation.core_px: expected a positive number"),
    ([1, 2], "format: expected 'dockfactory.design_refusals/1'"),
])
def test_a_bad_refusals_file_is_one_line_naming_it(tmp_path, data, needle):
    path = _refusals_file(tmp_path, data)
    with pytest.raises(DockfactoryError) as exc:
        with_refusals(_card(tmp_path, None), path)
    assert str(exc.value).startswith(str(path)) and needle in str(exc.value) and "\n" not in str(exc.value)
