"""Frames without a pose simulated per design (eval.design_refusals): the design's drawn test frames
through the real solve and gate. A camera class the gate tests at the card's noise is not
simulated; centres far noisier than the gate allows are refused, centres at the card's noise are
not; the same space draws the same frames; the card's section is checked in one line; a design
row folds the simulated share into P(accept)."""
from __future__ import annotations


import pytest

from dockfactory.core.config import load_config
from dockfactory.core.errors import DockfactoryError
from design_cards import card_with
from dockfactory.core.resources import resolve_config
from dockfactory.eval.acceptance import load_acceptance
from dockfactory.eval.design_predict import NoiseClass, design_config
from dockfactory.eval.design_rank import all_posed_probability, design_row
from dockfactory.eval.design_refusals import GateFigures, design_camera_class, simulated_no_pose
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
