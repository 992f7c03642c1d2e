"""``dockfactory design``: the shipped space answered end to end, bad spaces refused in one line,
the answer deterministic, and a design's config what its renders would use."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cli_run import run_cli
from dockfactory.core.config import load_config
from dockfactory.core.config_text import to_toml
from dockfactory.core.resources import resolve_config
from dockfactory.eval.design_predict import design_config
from dockfactory.eval.design_space import designs_of, load_design_space
from dockfactory.generator.sampler import frame_plan, sample_frame

SPACE = """\
[design]
scene = "quick"
test_frames = 30
seed = 0
marker_cost = 2.0

[[camera]]
name = "mono"
width = 1440
height = 1080
pixel_um = 3.45
cfa = "none"
cost = 400

[[camera]]
name = "colour"
width = 1440
height = 1080
pixel_um = 3.45
cfa = "rggb"
preset = "imx273"
cost = 300

[[lens]]
focal_mm = 6.0
cost = 100

[space]
distance_mm = [[1000, 1800]]
marker_diameter_mm = [16, 24]
markers_per_section = [6, 9]
"""


def _space(tmp_path, text=SPACE):
    (tmp_path / "space.toml").write_text(text)
    (tmp_path / "tight.toml").write_text('decision_rule = "guarded"\nconfidence = 0.95\n[localization]\n'
                                         'statistic = "rmse"\nx = 0.25\ny = 0.25\nalpha = 0.02\n')
    return tmp_path / "space.toml"


@pytest.mark.slow   # 216 designs: about 20 s
def test_the_shipped_space_is_answered_with_its_files(tmp_path, capsys):
    code, out, err = run_cli(["design", "docking_cell", "--out", tmp_path / "d"], capsys)
    assert code == 0, err
    res = json.loads((tmp_path / "d" / "design.json").read_text())
    ranked = [r for r in res["designs"] if r.get("rank") is not None]
    assert [r["rank"] for r in ranked] == list(range(1, len(ranked) + 1))
    assert {r["status"] for r in ranked} == {"passes", "undecided", "fails"}
    order = [r["status"] for r in ranked]
    assert order == sorted(order, key=["passes", "undecided", "fails"].index)
    assert all(r["status"] in ("infeasible", "not predicted") and r["reason"] for r in res["designs"][len(ranked):])
    passing = [r for r in ranked if r["status"] == "passes"]
    assert [r["cost"] for r in passing] == sorted(r["cost"] for r in passing)   # cheapest first
    assert all(r["p_accept"] >= 0.9 for r in passing) and any(r["pareto"] for r in passing)
    html = (tmp_path / "d" / "design.html").read_text()
    assert "data:image/png;base64," in html and passing[0]["design"] in html
    assert passing[0]["design"].replace("|", "\\|") in (tmp_path / "d" / "design.md").read_text()
    assert "designs predicted in" in out


def test_the_answer_is_deterministic_and_cheapest_passing_first(tmp_path, capsys):
    space = _space(tmp_path, SPACE.replace('scene = "quick"', 'scene = "quick"\nspec = "tight.toml"'))
    runs = []
    for k in (1, 2):
        assert run_cli(["design", space, "--out", tmp_path / f"o{k}"], capsys)[0] == 0
        res = json.loads((tmp_path / f"o{k}" / "design.json").read_text())
        res.pop("seconds")
        runs.append(res)
    assert runs[0] == runs[1]
    rows = runs[0]["designs"]
    passing = [r for r in rows if r["status"] == "passes"]
    assert passing and passing[0]["cost"] == min(r["cost"] for r in passing)
    # more markers and larger discs never predict a worse X for the same camera
    by = {(r["camera"], r["marker_diameter_mm"], r["markers_per_section"]): r["predicted_rmse"]["x"] for r in rows}
    for cam in ("mono", "colour"):
        assert by[(cam, 24.0, 9)] < by[(cam, 16.0, 6)]
        assert by[("colour", 24.0, 9)] > by[("mono", 24.0, 9)]


@pytest.mark.parametrize("edit,needle", [
    (("pixel_um = 3.45\ncfa = \"none\"", "pixel_um = 3.45\ncfa = \"rgb\""), "[[camera]] 1 cfa: expected one of none, rggb"),
    (("[[lens]]\nfocal_mm = 6.0", "[[lens]]\nfocal = 6.0"), "[[lens]] 1: unknown key 'focal'"),
    (("[[1000, 1800]]", "[[1800, 1000]]"), "[space] distance_mm: near 1800 mm is beyond far 1000 mm"),
    (("markers_per_section = [6, 9]", "markers_per_section = [4]"), "[space] markers_per_section: expected an integer in [6, 16]"),
    (("marker_diameter_mm = [16, 24]", "marker_diameter_mm = []"), "[space] marker_diameter_mm: expected a non-empty list"),
    (('scene = "quick"', 'scene = "nowhere.toml"'), "[design] scene: no file 'nowhere.toml' beside the space"),
    (("[space]", "[spaces]"), "unknown key 'spaces'"),
    (('preset = "imx273"\n', ""), "[[camera]] 2 preset: a colour (rggb) camera needs a sensor preset"),
    (("test_frames = 30", "test_frames = 1"), "[design] test_frames: expected an integer in [2, 100000]"),
])
def test_a_bad_space_is_one_line_and_exit_2(tmp_path, capsys, edit, needle):
    space = _space(tmp_path, SPACE.replace(*edit, 1))
    code, out, err = run_cli(["design", space, "--out", tmp_path / "o"], capsys)
    assert code == 2
    assert needle in err and str(space) in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "o").exists()


def test_an_out_that_is_a_file_is_one_line_and_exit_2_before_any_work(tmp_path, capsys):
    """--out naming an existing file (a typo, a script's variable) was a traceback after the table."""
    space, out = _space(tmp_path, SPACE), tmp_path / "taken"
    out.write_text("mine")
    code, stdout, err = run_cli(["design", space, "--out", out], capsys)
    assert code == 2 and "is a file, not a folder" in err and str(out) in err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err and "designs predicted" not in stdout
    assert out.read_text() == "mine"


def test_a_design_that_cannot_see_its_markers_is_infeasible_with_the_reason(tmp_path, capsys):
    space = _space(tmp_path, SPACE.replace("focal_mm = 6.0", "focal_mm = 25.0"))
    assert run_cli(["design", space, "--out", tmp_path / "o"], capsys)[0] == 0
    rows = json.loads((tmp_path / "o" / "design.json").read_text())["designs"]
    assert all(r["status"] == "infeasible" and "cannot fit its markers" in r["reason"] for r in rows)


def test_a_design_s_config_renders_its_camera_and_markers(tmp_path):
    space = load_design_space(_space(tmp_path), resolve_config)
    scene = load_config(space.scene)
    design = [d for d in designs_of(space, scene) if d.camera.cfa == "rggb" and d.markers_per_section == 9][0]
    cfg = design_config(scene, design, space, 6)
    (tmp_path / "d.toml").write_text(to_toml(cfg.resolved_dict()))
    again = load_config(tmp_path / "d.toml")
    assert again == cfg
    assert (cfg.image.width, cfg.image.height) == (1440, 1080) and cfg.sensor.cfa == ("RGGB",)
    assert len(cfg.markers.layout_a) == 9 and cfg.markers.diameter_mm == design.marker_diameter_mm
    distances = []
    for spec in [s for s in frame_plan(cfg) if s.split == "test"]:
        frame = sample_frame(cfg, spec)
        assert frame.camera.focal_px == pytest.approx(6.0 * 1000 / 3.45)
        distances.append(float(np.linalg.norm(frame.camera.cam_from_d_array()[:3, 3])))
    # camera to A's axis: the working distance to the seam plus up to the radius (300 mm) and jitter
    assert 1000.0 <= min(distances) and max(distances) <= 1800.0 + 300.0 + 50.0


def test_an_estimation_gate_without_captures_is_said(tmp_path, capsys):
    """The shipped spec gates repeatability: a space without repeatability captures says its
    P(accept) covers localization only; with captures every predicted design has the block."""
    space = _space(tmp_path)
    assert run_cli(["design", space, "--out", tmp_path / "o"], capsys)[0] == 0
    res = json.loads((tmp_path / "o" / "design.json").read_text())
    assert any("covers localization only" in n for n in res["notes"])
    assert all(r["estimation"] == {} for r in res["designs"] if "estimation" in r)
    with_caps = SPACE.replace("test_frames = 30", "test_frames = 30\nrepeatability_poses = 3\nrepeatability_captures = 5")
    space = _space(tmp_path, with_caps)
    assert run_cli(["design", space, "--out", tmp_path / "o2"], capsys)[0] == 0
    res = json.loads((tmp_path / "o2" / "design.json").read_text())
    assert not any("covers localization only" in n for n in res["notes"])
    assert all(set(r["estimation"]) == {"x", "y", "alpha"} for r in res["designs"] if "estimation" in r)


def test_the_answer_shows_predicted_beside_rendered_after_verify(tmp_path, capsys):
    """What --verify adds (its records: eval/design_verify) is in design.md and design.html: one
    row per verified design, predicted / rendered RMSE with their ratio and both verdicts. The
    records here are written by hand (a render takes minutes); bench/results/design/ has real ones."""
    from dockfactory.eval.design_report import write_design_outputs
    assert run_cli(["design", _space(tmp_path), "--out", tmp_path / "o"], capsys)[0] == 0
    result = json.loads((tmp_path / "o" / "design.json").read_text())
    top = result["designs"][0]
    result["verify"] = [{"id": top["id"], "design": top["design"], "frames": 24,
                         "predicted": {"rmse": top["predicted_rmse"], "status": top["status"]},
                         "rendered": {"rmse": {**{c: 2 * v for c, v in top["predicted_rmse"].items()}, "alpha": None},
                                      "verdict": "ACCEPTED", "blocks": {"localization": "pass"}, "solved": "24/24"}}]
    write_design_outputs(tmp_path / "o", result)
    md = (tmp_path / "o" / "design.md").read_text()
    assert "## Predicted against rendered (--verify)" in md
    row = [line for line in md.splitlines() if line.startswith(f"| {top['id']} |")]
    assert len(row) == 1 and "(0.50)" in row[0] and "ACCEPTED (localization pass, 24/24 solved)" in row[0]
    assert f"{top['predicted_rmse']['alpha']:.3g} / -" in row[0]
    assert "Predicted against rendered" in (tmp_path / "o" / "design.html").read_text()


def test_a_verified_run_that_left_no_metrics_is_one_line(tmp_path):
    """A design whose run did not finish (its render failed) stops --verify with a one-line
    error naming the run folder, never a traceback from a missing file."""
    from dockfactory.core.errors import DockfactoryError
    from dockfactory.design_verify import _rendered
    with pytest.raises(DockfactoryError, match="has no eval/metrics.json: the run of this design did not finish"):
        _rendered(tmp_path / "run")


def test_a_design_whose_later_test_frames_cannot_fit_their_markers_is_infeasible(tmp_path, capsys):
    """The wide scene at 1.7-2.4 m with a 6 mm lens: the 24 frames the prediction draws fit their
    markers, frame 2 of the 48 test frames does not (a verify render refused it after the design
    was answered "passes"): the design is infeasible with the whole plan's reason."""
    wide = Path(__file__).resolve().parents[2] / "bench" / "configs" / "design_scene_wide.toml"
    text = (SPACE.replace('scene = "quick"', f'scene = "{wide}"')
            .replace("test_frames = 30", "test_frames = 48\ngeometry_frames = 24"))
    text = text[:text.index("[space]")] + "[space]\ndistance_mm = [[1700, 2400]]\nmarker_diameter_mm = [30]\nmarkers_per_section = [7]\n"
    assert run_cli(["design", _space(tmp_path, text), "--out", tmp_path / "o"], capsys)[0] == 0
    rows = json.loads((tmp_path / "o" / "design.json").read_text())["designs"]
    assert rows and all(r["status"] == "infeasible" and "cannot fit all markers" in r["reason"] for r in rows)
    assert all(not r["reason"].startswith(str(tmp_path)) for r in rows)


def test_a_design_beyond_the_card_s_disc_sizes_says_so_in_every_output(tmp_path, capsys):
    """16 mm discs at 1.0-1.8 m through 6 mm are inside the card's scenes; 24 mm ones are larger
    (median b about 11.5 px against at most 10.7): their rows say "extrapolated" in the json and
    the md table, the others do not."""
    space = _space(tmp_path, SPACE.replace("markers_per_section = [6, 9]", "markers_per_section = [6]"))
    assert run_cli(["design", space, "--out", tmp_path / "o"], capsys)[0] == 0
    rows = json.loads((tmp_path / "o" / "design.json").read_text())["designs"]
    flagged = {r["marker_diameter_mm"]: bool(r["extrapolated"]) for r in rows}
    assert flagged == {16.0: False, 24.0: True}
    assert all(r["disc_minor_median_px"] > 10.7 for r in rows if r["marker_diameter_mm"] == 24.0)
    md = (tmp_path / "o" / "design.md").read_text()
    assert md.count("extrapolated: median disc b") == sum(flagged.values()) * 2   # both cameras


def test_a_card_that_simulates_refusals_says_so_and_counts_them_per_design(tmp_path, capsys):
    """The committed tail card (the shipped card with ``no_pose_simulation``): every Bayer design's row
    gives its simulated frames and refusals and the share they make, the monochrome PNG designs none
    simulated; the answer's notes say how frames without a pose were predicted."""
    space = _space(tmp_path, SPACE.replace("markers_per_section = [6, 9]", "markers_per_section = [6]")
                   .replace("test_frames = 30", "test_frames = 30\ngeometry_frames = 8"))
    card = Path(__file__).resolve().parents[2] / "bench" / "results" / "design" / "card_nopose_tail.json"
    assert run_cli(["design", space, "--card", card, "--out", tmp_path / "o"], capsys)[0] == 0
    doc = json.loads((tmp_path / "o" / "design.json").read_text())
    for r in doc["designs"]:
        nopose = r["no_pose"]
        assert nopose["card_key"] == "no_pose_simulation"
        assert nopose["simulated"] == (8 if r["cfa"] == "rggb" else 0)
        assert nopose["rate_per_frame"] == (nopose["refused"] / 8 if r["cfa"] == "rggb" else 0.0)
    assert any("its predicted centres" in n for n in doc["notes"])


def test_refusals_are_simulated_by_default_with_the_shipped_figures_and_not_with_no_refusals(tmp_path, capsys):
    """The answer adds the shipped refusal figures (models/design_refusals.json) to the shipped card
    by default: every Bayer design not already failing on its pose errors is simulated over its drawn
    frames and its notes say so; with ``--no-refusals`` nothing is simulated and the RMSE predicted
    is the same to the digit."""
    space = _space(tmp_path, SPACE.replace("markers_per_section = [6, 9]", "markers_per_section = [6]")
                   .replace("test_frames = 30", "test_frames = 30\ngeometry_frames = 8"))
    assert run_cli(["design", space, "--out", tmp_path / "r"], capsys)[0] == 0
    assert run_cli(["design", space, "--no-refusals", "--out", tmp_path / "p"], capsys)[0] == 0
    sim, plain = (json.loads((tmp_path / o / "design.json").read_text()) for o in ("r", "p"))
    bayer = [r for r in sim["designs"] if r["cfa"] == "rggb" and r["status"] != "fails"]
    assert bayer and all(r["no_pose"]["simulated"] == 8 for r in bayer)
    assert all("simulated" not in r["no_pose"] for r in plain["designs"])
    assert {r["id"]: r["predicted_rmse"] for r in sim["designs"]} == {r["id"]: r["predicted_rmse"] for r in plain["designs"]}
    assert any("its predicted centres" in n for n in sim["notes"])
    assert not any("its predicted centres" in n for n in plain["notes"])


def test_the_answer_is_the_same_to_the_digit_over_two_processes(tmp_path, capsys):
    """``--jobs 2`` (the command's own process, which forks its workers) answers exactly as one
    process does: the same rows in the same order, the simulated refusals included (each design's
    draws are seeded by its label, not by the worker that made them)."""
    space = _space(tmp_path, SPACE.replace("test_frames = 30", "test_frames = 30\ngeometry_frames = 6"))
    assert run_cli(["design", space, "--jobs", "1", "--out", tmp_path / "one"], capsys)[0] == 0
    done = subprocess.run([sys.executable, "-m", "dockfactory", "design", str(space), "--jobs", "2",
                           "--out", str(tmp_path / "two")], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    one, two = (json.loads((tmp_path / o / "design.json").read_text()) for o in ("one", "two"))
    one.pop("seconds"), two.pop("seconds")
    assert any(r["no_pose"].get("refused") for r in one["designs"]) or any(
        r["no_pose"].get("simulated") for r in one["designs"])
    assert one == two
