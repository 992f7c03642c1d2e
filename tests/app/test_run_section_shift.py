"""``dockfactory run``'s solve stage and the section offset (eval.section_shift): measured on the
dataset's own val split when the detections cover it. On a painted 1280 x 960 dataset (no
Blender) with detections made from its labels."""
import json

import numpy as np
import pytest
from pipeline_data import SHIFT_SPLIT_CONFIG, offset_detections, painted_from_text

from dockfactory.core.io import write_json_atomic
from dockfactory.generator.datasets.reader import Dataset
from dockfactory.pipeline import Stages, _solve_stage

# painting 24 frames at 1280 x 960 and solving them: the full suite runs it, the fast lane leaves it out
pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def painted(tmp_path_factory):
    return painted_from_text(tmp_path_factory, "runshift", SHIFT_SPLIT_CONFIG)


def test_the_judges_solve_stage_takes_the_offset_of_the_val_split(painted, tmp_path, capsys):
    """``run``'s solve stage measures the offset on the val frames of the detections it made and
    solves the test frames with it (each record carries what it added), naming the source."""
    ds = Dataset.open(painted)
    dets = offset_detections(ds, ds.frames(("val", "test")), 0.1, np.random.default_rng(5))
    write_json_atomic(tmp_path / "dets.json", dets)
    _solve_stage(ds, ds.version_id, tmp_path / "dets.json", None, tmp_path / "poses.json", Stages(tmp_path))
    poses = json.loads((tmp_path / "poses.json").read_text())
    assert poses["section_shift"]["splits"] == ["val"]
    assert poses["section_shift_px"] == poses["section_shift"]["shift_axis_px"]
    assert "section offset" in capsys.readouterr().err
    solved = [r for f, r in poses["frames"].items() if f in ds.frames(("test",)) and r["ok"]]
    assert solved and all(r["section_shift_variance"][1] > 0 for r in solved)


def test_without_val_detections_the_cards_offset_is_used(painted, tmp_path):
    ds = Dataset.open(painted)
    dets = offset_detections(ds, ds.frames(("test",)), 0.1, np.random.default_rng(6))
    dets["section_shift_px"] = [0.0, 0.05]
    write_json_atomic(tmp_path / "dets.json", dets)
    _solve_stage(ds, ds.version_id, tmp_path / "dets.json", None, tmp_path / "poses.json", Stages(tmp_path))
    poses = json.loads((tmp_path / "poses.json").read_text())
    assert poses["section_shift"] == {"source": "the weights' noise card"} and poses["section_shift_px"] == [0.0, 0.05]
