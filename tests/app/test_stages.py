"""The solve, evaluate, report and run stages on a small dataset, without rendering.

The dataset is the shipped ``smoke`` config (8 frames at 320 x 240, 4 of them test; one pose
captured twice for repeatability) made by tests/pipeline_data.py: the factory's real sampling,
labels, sensor model and manifest, with the Blender render replaced by painted passes. Every
front-facing marker (7 of A, 7 of B) is fully visible and its label's image centroid is exact,
so the noise-free oracle must give the true pose.

Tolerances (noise-free oracle): measured on this dataset the largest pose errors are 8e-5 mm and
2e-5 deg, the focal error 1.2e-3 px (the solver fits a 256-point polygon outline of each disc, not
the analytic conic); the tests allow 1e-3 mm, 1e-3 deg and 0.01 px.
"""
import json
import shutil

import numpy as np
import pytest
from pipeline_data import painted_copy

from dockfactory.core.errors import DockfactoryError
from dockfactory.core.resources import default_acceptance, shipped_config
from dockfactory.eval.acceptance import AcceptanceSpec, load_acceptance
from dockfactory.eval.evaluate import evaluate, write_outputs
from dockfactory.pipeline import run_pipeline
from dockfactory.eval.pose_metrics import pose_error
from dockfactory.eval.report import build_report
from dockfactory.eval.solve_frames import solve_dataset, write_poses
from dockfactory.generator.datasets.reader import Dataset

TOL_MM, TOL_DEG, TOL_FOCAL_PX = 1e-3, 1e-3, 0.01
COMPS = ("x", "y", "z", "alpha", "beta", "gamma")


def _strict_json(path):
    def no_nan(token):
        raise AssertionError(f"{path}: {token} in JSON")
    return json.loads(path.read_text(), parse_constant=no_nan)


@pytest.fixture(scope="module")
def painted_root(tmp_path_factory):
    return painted_copy(tmp_path_factory, tmp_path_factory.mktemp("painted") / "dataset",
                        shipped_config("smoke").read_text())


@pytest.fixture(scope="module")
def ds(painted_root):
    return Dataset.open(painted_root)


@pytest.fixture(scope="module")
def exact_poses(ds):
    return solve_dataset(ds, oracle_sigma_px=0.0)


def _assert_exact(ds, poses):
    for fid, rec in poses["frames"].items():
        assert rec["ok"], (fid, rec)
        err = pose_error(rec["pose"], ds.labels[fid]["pose_b_in_d"])
        for c in COMPS:
            assert abs(err[c]) < (TOL_MM if c in "xyz" else TOL_DEG), (fid, c, err[c])
        assert abs(rec["focal_px"] - ds.labels[fid]["camera"]["focal_px"]) < TOL_FOCAL_PX


def test_the_painted_dataset_is_a_complete_dataset_of_the_config(ds, painted_root):
    manifest = json.loads((painted_root / "manifest.json").read_text())
    assert manifest["version_id"] == ds.version_id and manifest["counts"]["frames"] == 10
    assert sorted(ds.frames(("test",))) == ["000001", "000004", "000006", "000007"]
    assert sorted(ds.frames(("repeat",))) == ["rep000_00", "rep000_01"]
    for lab in ds.labels.values():
        visible = [m for m in lab["markers"] if m["visibility"] == 2 and m["legible"]]
        assert len(visible) == 14


def test_solve_stage_oracle_without_noise_gives_the_true_pose(ds, exact_poses, tmp_path):
    poses = exact_poses
    assert poses["dataset_version"] == ds.version_id and poses["source"] == "oracle"
    assert sorted(poses["frames"]) == sorted(ds.frames(("test", "repeat")))
    _assert_exact(ds, poses)
    for rec in poses["frames"].values():
        assert rec["n_markers"] == {"A": 7, "B": 7} and rec["rejected_ids"] == []
        assert max(rec["rmse_px"].values()) < 1e-3
        cov = np.array(rec["covariance"])
        assert cov.shape == (6, 6) and np.all(np.isfinite(cov))
        assert np.allclose(cov, cov.T) and np.linalg.eigvalsh(cov).min() > 0
    path = tmp_path / "poses.json"
    write_poses(path, poses)
    assert _strict_json(path)["frames"].keys() == poses["frames"].keys()


def test_solve_stage_from_detections_matches_the_oracle(ds, exact_poses):
    """Detections at the exact centroids solve to the oracle's poses; a low score is dropped; a
    frame without detections is kept as a failure, never dropped."""
    frames = {}
    for fid in ds.frames(("test", "repeat")):
        dets = [{"class_id": m["class_id"], "center_px": m["outline_centroid_px"], "score": 0.9}
                for m in ds.labels[fid]["markers"] if m["visibility"] == 2]
        dets.append({"class_id": 0, "center_px": [5.0, 5.0], "score": 0.01})   # below MIN_SCORE
        frames[fid] = dets
    missing = ds.frames(("test",))[0]
    del frames[missing]
    poses = solve_dataset(ds, detections={"frames": frames})
    assert poses["source"] == "detections"
    assert poses["frames"][missing] == {"ok": False, "reason": "no detections for this frame",
                                        "category": "no detections", "camera_class": "three-chip"}
    for fid, rec in poses["frames"].items():
        if fid != missing:
            assert rec["n_detections"] == 14
            assert np.allclose(rec["d_from_b"], exact_poses["frames"][fid]["d_from_b"], atol=1e-9)


def test_solve_stage_rejects_two_sources_and_seeds_its_noise(ds):
    with pytest.raises(ValueError, match="not both"):
        solve_dataset(ds, detections={"frames": {}}, oracle_sigma_px=0.1)
    with pytest.raises(ValueError):
        solve_dataset(ds)
    a = solve_dataset(ds, splits=("repeat",), oracle_sigma_px=0.3)
    b = solve_dataset(ds, splits=("repeat",), oracle_sigma_px=0.3)
    assert a == b                              # noise drawn from (dataset seed, frame index)
    x_err = [pose_error(r["pose"], ds.labels[f]["pose_b_in_d"])["x"] for f, r in a["frames"].items()]
    assert all(r["ok"] for r in a["frames"].values())
    assert 0 < max(abs(e) for e in x_err) < 10.0   # mm: noisy, not absurd


def _evaluate(ds, poses, out, spec=AcceptanceSpec(), oracle=False):
    """Write ``poses``, evaluate them (``oracle``: also re-solve the test split from exact
    centroids with the measured noise, as ``dockfactory evaluate`` does) and write the outputs."""
    path = out / "poses.json"
    write_poses(path, poses)
    metrics, rows = evaluate(ds, path, spec, oracle=oracle, oracle_sigma_px=0.0)
    write_outputs(out / "eval", metrics, rows)
    return metrics, rows


@pytest.fixture(scope="module")
def evaluated(ds, exact_poses, tmp_path_factory):
    """(folder holding poses.json and eval/, metrics, rows) of the noise-free oracle poses."""
    out = tmp_path_factory.mktemp("evaluated")
    metrics, rows = _evaluate(ds, exact_poses, out, oracle=True)
    return out, metrics, rows


def test_evaluate_stage_metrics_and_verdict(ds, evaluated):
    out, metrics, rows = evaluated
    loc, est = metrics["localization"], metrics["estimation"]
    assert loc["n_frames"] == 4 and loc["n_solved"] == 4
    for c in COMPS:
        assert loc["overall"][c]["n"] == 4
        assert loc["overall"][c]["rmse"] < (TOL_MM if c in "xyz" else TOL_DEG)
        assert est["pooled"][c]["rmse"] < 1e-9    # two captures of one pose share its geometry
    assert est["n_frames"] == 2 and est["n_solved"] == 2
    assert sorted(loc["by_condition"]) == ["glare", "low_light", "normal", "occlusion"]
    assert metrics["failures_test"]["count"] == 0 and metrics["failures_repeat"]["count"] == 0
    # no detections: the centre noise is the one the oracle poses were made with (0 px, not a default)
    assert metrics["centre_noise_px"] == 0.0
    assert metrics["oracle"]["sigma_px"] == 0.0 and metrics["oracle"]["localization"]["n_solved"] == 4
    acc = metrics["acceptance"]
    assert acc["accepted"] and len(acc["criteria"]) == 7 and all(c["pass"] for c in acc["criteria"])
    assert len(rows) == 6 and all(r["ok"] for r in rows)
    csv_lines = (out / "eval" / "frames.csv").read_text().splitlines()
    assert csv_lines[0].startswith("frame_id,split,condition") and len(csv_lines) == 7
    on_disk = _strict_json(out / "eval" / "metrics.json")
    assert on_disk["acceptance"]["accepted"] is True and on_disk["dataset"]["version_id"] == ds.version_id


def test_evaluate_stage_with_the_shipped_spec_gates_detection(ds, exact_poses, tmp_path):
    """The shipped acceptance spec gates mAP, which an oracle run has none of: rejected on exactly
    those two criteria, every pose criterion passes."""
    metrics, _ = _evaluate(ds, exact_poses, tmp_path, load_acceptance(default_acceptance()))
    acc = metrics["acceptance"]
    assert not acc["accepted"]
    assert sorted(c["name"] for c in acc["criteria"] if not c["pass"]) == ["detection: map50",
                                                                           "detection: map50_95"]


def test_evaluate_stage_refuses_foreign_poses_and_counts_missing_frames(ds, exact_poses, tmp_path):
    foreign = dict(exact_poses, dataset_version="0123456789abcdef")
    with pytest.raises(DockfactoryError, match="refusing to mix"):
        _evaluate(ds, foreign, tmp_path)
    gone = ds.frames(("test",))[0]
    partial = dict(exact_poses, frames={f: r for f, r in exact_poses["frames"].items() if f != gone})
    metrics, rows = _evaluate(ds, partial, tmp_path)
    assert metrics["localization"]["n_solved"] == 3
    assert metrics["failures_test"]["by_category"] == {"missing": 1}
    assert [r["frame_id"] for r in rows if not r["ok"]] == [gone]


def test_report_stage(ds, evaluated, tmp_path):
    folder, metrics, _ = evaluated
    out = tmp_path / "report.html"
    summary = build_report(folder / "eval", out, ["dockfactory run smoke"])
    assert summary["verdict"] == "ACCEPTED" and summary["accepted"] is True
    for c in COMPS:
        assert summary["localization_rmse"][c] == pytest.approx(metrics["localization"]["overall"][c]["rmse"])
    text = out.read_text()
    assert text.startswith("<!DOCTYPE html>") and text.rstrip().endswith("</html>")
    assert "ACCEPTED" in text and "dockfactory run smoke" in text and ds.version_id in text
    assert "Oracle (exact centres" in text
    assert text.count("<img") == 5 + 1 + 4   # five plots, the QQ plot of z; the four test frames in the gallery
    assert "ACCEPTED" in out.with_suffix(".md").read_text()
    assert _strict_json(out.with_suffix(".json"))["verdict"] == "ACCEPTED"


def _no_render(*args, **kwargs):
    raise AssertionError("the run stage rendered although the dataset is complete")


def test_run_stage_on_a_complete_dataset(painted_root, tmp_path, monkeypatch, capsys):
    """``run_pipeline`` in oracle mode: the render stage finds every frame done (nothing is
    rendered), then solve, evaluate and report write their outputs and the verdict is the exit
    status (1: the shipped spec gates mAP, which an oracle run has none of; 0 with a spec that
    gates poses only). The second run skips the render and the solve (current) but evaluates
    again (the acceptance spec changed). The report's plots (two thirds of this test's time) are
    left out here: test_report_stage draws them."""
    import dockfactory.eval.report.document as report
    import dockfactory.generator.render_job as render_job
    monkeypatch.setattr(render_job, "_render", _no_render)
    monkeypatch.setattr(report, "plots", lambda rows, metrics, detections_pr=None: {})
    work = tmp_path / "run"
    shutil.copytree(painted_root, work / "dataset")
    config = shipped_config("smoke")

    assert run_pipeline(config, work, default_acceptance(), oracle_noise_px=0.0) == 1
    out = capsys.readouterr()
    assert "verdict: REJECTED" in out.out and "render: dataset" in out.err
    for name in ("poses.json", "eval/metrics.json", "eval/frames.csv", "eval/provenance.json",
                 "report.html", "report.md", "report.json", "stages.json"):
        assert (work / name).is_file(), name
    ds = Dataset.open(work / "dataset")
    _assert_exact(ds, _strict_json(work / "poses.json"))
    metrics = _strict_json(work / "eval" / "metrics.json")
    assert metrics["localization"]["n_solved"] == 4 and not metrics["acceptance"]["accepted"]
    assert set(_strict_json(work / "stages.json")) == {"render", "solve", "evaluate"}
    commands = _strict_json(work / "eval" / "provenance.json")["commands"]
    assert commands[0] == f"dockfactory run {config} --out {work}"
    assert "REJECTED" in (work / "report.md").read_text()

    spec = tmp_path / "poses_only.toml"
    spec.write_text("[localization]\nx = 0.01\ny = 0.01\nalpha = 0.001\n"
                    "[estimation]\nx = 0.01\ny = 0.01\nalpha = 0.001\n")
    assert run_pipeline(config, work, spec, oracle_noise_px=0.0) == 0
    out = capsys.readouterr()
    assert "verdict: ACCEPTED" in out.out and "complete, skipped" in out.err
    assert "solve: poses current, skipped" in out.err and "evaluate: metrics current" not in out.err
    assert _strict_json(work / "eval" / "metrics.json")["acceptance"]["accepted"] is True
    assert "ACCEPTED" in (work / "report.md").read_text()
