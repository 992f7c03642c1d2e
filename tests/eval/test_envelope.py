"""The tolerance envelope (eval.envelope): the sweep reproduces the labels' geometry exactly at the
ideal camera, its statistics grow with the camera's defects, its pass map follows the thresholds,
and evaluate/report carry it."""
import json

import numpy as np
import pytest

from dockfactory.eval.acceptance import AcceptanceSpec, Gate
from dockfactory.eval.envelope import EnvelopeGrid, camera_envelope
from dockfactory.generator.datasets.reader import Dataset


@pytest.fixture(scope="module")
def ds(painted_source):
    return Dataset.open(painted_source)


def test_the_ideal_camera_without_noise_gives_the_true_poses(ds):
    env = camera_envelope(ds, AcceptanceSpec(), 0.0, EnvelopeGrid(pp_offsets_px=(0.0,), k1=(0.0,)))
    assert env["frames"] >= 3
    for c, v in env["values"].items():
        assert v[0][0] < 1e-6, (c, v)   # mm / deg: the projection is the labels' own geometry


def test_errors_grow_with_the_principal_point_offset_and_distortion(ds):
    grid = EnvelopeGrid(pp_offsets_px=(0.0, 5.0, 15.0), k1=(-0.1, 0.0), directions=4)
    env = camera_envelope(ds, AcceptanceSpec(), 0.0, grid)
    alpha = np.array(env["values"]["alpha"], dtype=float)
    assert alpha[0, 1] < 1e-6 < alpha[1, 1] < alpha[2, 1]          # pp offset, k1 = 0
    assert alpha[0, 0] > 1e-4 and env["values"]["x"][0][0] > 1e-3   # k1 alone moves the pose too


def test_the_pass_map_follows_the_thresholds(ds):
    grid = EnvelopeGrid(pp_offsets_px=(0.0, 15.0), k1=(0.0, -0.1), directions=2)
    loose = camera_envelope(ds, AcceptanceSpec(localization=Gate(x=1e3, y=1e3, alpha=1e3)), 0.0, grid)
    assert np.all(loose["passes"]) and "4 of 4 grid cells pass" in loose["verdict"]
    tight = camera_envelope(ds, AcceptanceSpec(localization=Gate(x=1e-9, y=1e-9, alpha=1e-9)), 0.05, grid)
    assert not np.any(tight["passes"]) and tight["verdict"].startswith("no camera of the grid passes")
    mid = camera_envelope(ds, AcceptanceSpec(localization=Gate(alpha=1e-4)), 0.0, grid)
    assert mid["passes"][0][0] and not mid["passes"][1][0] and list(mid["thresholds"]) == ["alpha"]


@pytest.mark.slow   # evaluate with the envelope, then the report with its plot
def test_evaluate_and_report_carry_the_envelope(painted_source, tmp_path, capsys):
    from dockfactory.cli import main
    poses = tmp_path / "p.json"
    assert main(["solve", str(painted_source), "--oracle-noise", "0.05", "--out", str(poses)]) == 0
    spec = tmp_path / "spec.toml"
    spec.write_text("[localization]\nx = 5.0\ny = 5.0\nalpha = 0.1\n")
    assert main(["evaluate", str(painted_source), "--poses", str(poses), "--acceptance", str(spec),
                 "--envelope", "--out", str(tmp_path / "eval")]) in (0, 1, 3)
    env = json.loads((tmp_path / "eval" / "metrics.json").read_text())["camera_envelope"]
    assert env["sigma_px"] == pytest.approx(0.05) and len(env["passes"]) == len(EnvelopeGrid().pp_offsets_px)
    assert main(["report", str(tmp_path / "eval"), "--out", str(tmp_path / "r.html")]) == 0
    text = (tmp_path / "r.html").read_text()
    assert "Which cameras pass without calibration" in text and env["verdict"] in text
