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
