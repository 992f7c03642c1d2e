"""The detector's noise card (issue 12): measured on a labelled split, written next to the weights,
named by their sha256, carried by detect into its detections and used by solve as the floor of the
covariance. On a painted 1280 x 960 dataset (tests/pipeline_data.py, no Blender)."""
import json
import shutil

import pytest
from pipeline_data import painted_config, painted_from_text

from dockfactory.core.resources import shipped_weights
from dockfactory.detector.noise_card import centre_noise_px, noise_card_path, section_shift_px, write_noise_card
from dockfactory.cli import main

CONFIG = painted_config("noise-card-test", 5, 6, 0.7, 0.5)


@pytest.fixture(scope="module")
def painted(tmp_path_factory):
    return painted_from_text(tmp_path_factory, "noise", CONFIG)


@pytest.mark.slow   # the detector on the val frames, detect and solve on the test frames
def test_noise_card_is_measured_written_and_used(painted, tmp_path, capsys):
    w = tmp_path / "w.pt"
    shutil.copy(shipped_weights(), w)
    assert main(["noise-card", str(painted), "--weights", str(w), "--quiet", "--threads", "1"]) == 0
    card = json.loads(noise_card_path(w).read_text())
    assert card["measured_on"]["split"] == "val" and card["measured_on"]["frames"] >= 2
    assert card["n"] >= 10 and 0.0 < card["centre_noise_px"] < 1.0
    assert centre_noise_px(w) == card["centre_noise_px"]
    assert list(card["camera_classes"]) == ["three-chip"] and card["camera_classes"]["three-chip"] >= 2
    assert len(card["section_shift_px"]) == 2 and all(0.0 <= v < 1.0 for v in card["section_shift_px"])
    assert section_shift_px(w) == tuple(card["section_shift_px"])
    other = dict(card, refinement_sha256="0" * 64)      # measured with another centre refinement
    noise_card_path(w).write_text(json.dumps(other))
    assert centre_noise_px(w) is None
    noise_card_path(w).write_text(json.dumps(card))
    assert "px per axis" in capsys.readouterr().out
    dets, poses = tmp_path / "d.json", tmp_path / "p.json"
    assert main(["detect", str(painted), "--weights", str(w), "--out", str(dets), "--quiet", "--threads", "1"]) == 0
    assert json.loads(dets.read_text())["centre_noise_px"] == card["centre_noise_px"]
    assert json.loads(dets.read_text())["section_shift_px"] == card["section_shift_px"]
    assert main(["solve", str(painted), "--detections", str(dets), "--split", "test", "--out", str(poses)]) == 0
    doc = json.loads(poses.read_text())
    assert doc["sigma_floor_px"] == card["centre_noise_px"]
    assert doc["section_shift_px"] == card["section_shift_px"]
    # a dataset without docking runs has no frames that share a camera: a joint solve is refused
    # (tests/eval/test_camera_models_eval.py checks the floor of a docking run's joint solve)
    assert main(["solve", str(painted), "--detections", str(dets), "--split", "test", "--self-calibrate",
                 "sequence", "--camera-model", "pinhole", "--out", str(tmp_path / "seq.json")]) == 2
    assert "no docking runs" in capsys.readouterr().err


def test_noise_card_needs_frames_in_its_split(tmp_path):
    from dockfactory.core.errors import DockfactoryError
    from dockfactory.eval.noise_calibration import calibrate_noise_card

    class NoVal:
        root = tmp_path

        @staticmethod
        def frames(splits):
            return []
    with pytest.raises(DockfactoryError, match="no frames in the val split"):
        calibrate_noise_card(NoVal(), shipped_weights())
    assert not noise_card_path(tmp_path / "w.pt").exists()


@pytest.mark.parametrize("value,want", [([0.0, 0.07], (0.0, 0.07)), (None, None), ([0.1], None),
                                        ([0.1, -0.1], None), ([0.1, "nan"], None), ("ab", None)])
def test_section_shift_is_read_from_a_valid_card_only(tmp_path, value, want):
    """The card's ``section_shift_px`` (two finite px >= 0) or None: absent (a card measured before
    it existed) or not two such numbers."""
    w = tmp_path / "w.pt"
    w.write_bytes(b"weights")
    write_noise_card(w, 0.08, {} if value is None else {"section_shift_px": value})
    assert section_shift_px(w) == want
    assert centre_noise_px(w) == 0.08


def test_a_frames_camera_class_sets_its_centre_noise():
    """The class of a frame (its Bayer pattern told, a JPEG) scales the card's three-chip figure by
    the class's measured factor; no card, no noise."""
    from dockfactory.detector.noise_card import CAMERA_CLASS_FACTORS, camera_class, class_noise_px
    assert [camera_class(c, j) for c, j in ((None, False), ("RGGB", False), (None, True), ("BGGR", True))] == \
        ["three-chip", "bayer", "jpeg", "bayer-jpeg"]
    assert CAMERA_CLASS_FACTORS["three-chip"] == 1.0
    assert all(CAMERA_CLASS_FACTORS["three-chip"] < f for c, f in CAMERA_CLASS_FACTORS.items() if c != "three-chip")
    assert CAMERA_CLASS_FACTORS["bayer-jpeg"] > max(CAMERA_CLASS_FACTORS["bayer"], CAMERA_CLASS_FACTORS["jpeg"])
    assert class_noise_px(0.02, "RGGB", True) == pytest.approx(0.02 * CAMERA_CLASS_FACTORS["bayer-jpeg"])
    assert class_noise_px(0.02, None, False) == 0.02 and class_noise_px(None, "RGGB", True) is None


@pytest.mark.parametrize("classes,factor", [(None, 1.0), ({"three-chip": 40}, 1.0), ({"bayer": 40}, "bayer"),
                                            ({"three-chip": 20, "bayer-jpeg": 20}, "mix"), ({"webcam": 3}, 1.0),
                                            ({"bayer": "x"}, 1.0)])
def test_a_card_measured_on_other_cameras_is_taken_to_the_three_chip_figure(tmp_path, classes, factor):
    """A card names the camera classes of the frames it was measured on; its centre noise is read
    back as the three-chip camera's (divided by the RMS of their factors), so that a frame's class
    is not counted twice. A card that names none (or nothing known) is a three-chip card."""
    from dockfactory.detector.noise_card import CAMERA_CLASS_FACTORS as F
    w = tmp_path / "w.pt"
    w.write_bytes(b"weights")
    write_noise_card(w, 0.08, {} if classes is None else {"camera_classes": classes})
    want = {"bayer": F["bayer"], "mix": ((F["three-chip"] ** 2 + F["bayer-jpeg"] ** 2) / 2) ** 0.5}.get(factor, factor)
    assert centre_noise_px(w) == pytest.approx(0.08 / want)


def test_solve_takes_each_frames_floor_to_its_camera_class():
    """Detections that name each frame's camera class (detect told the camera) solve each frame with
    the card's floor times its class's factor; a frame without a class, or no floor, as given."""
    from dockfactory.detector.noise_card import CAMERA_CLASS_FACTORS
    from dockfactory.eval.solve_frames import class_options, docking_options
    opts = docking_options(0.02)
    dets = {"camera_classes": {"f1": "bayer", "f2": "three-chip"}}
    assert class_options(opts, dets, "f1").refine.sigma_floor_px == pytest.approx(0.02 * CAMERA_CLASS_FACTORS["bayer"])
    assert class_options(opts, dets, "f2") == opts and class_options(opts, dets, "f3") is opts
    assert class_options(opts, None, "f1") is opts and class_options(docking_options(None), dets, "f1").refine.sigma_floor_px is None
