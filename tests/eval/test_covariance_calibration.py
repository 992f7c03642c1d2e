"""Is the solver's covariance honest? z = error / reported std (eval.uncertainty, issue 12).

- The std of each component comes from the pose record's covariance in POSE_NAMES order (X, Y,
  Z mm; alpha, beta, gamma deg), the units of the error; a covariance of another shape is bad
  input.
- Monte-Carlo (seeded, 300 docking-like frames, Gaussian noise the solver is told): a correct
  covariance read the way evaluate reads it gives RMS z within 0.88-1.12 (3.5 standard errors of
  an RMS over 300 normal draws: 1 / sqrt(600) = 0.041) and 92-98.5 % within 2 sigma (expected
  95.45 %, standard error 1.2 %). A std taken as the variance, or in radians, fails it.
- evaluate reports z per frame (frames.csv), RMS z and the fraction within 2 sigma overall and per
  condition; the report prints the table, a QQ plot and the sigma it used, and still reads a
  metrics.json of an older evaluate.
"""
import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest

from dockfactory.core.geometry import pose_components
from dockfactory.eval.acceptance import AcceptanceSpec
from dockfactory.eval.evaluate import evaluate, write_outputs
from dockfactory.eval.pose_metrics import pose_error
from dockfactory.eval.report import build_report, read_rows
from dockfactory.generator.datasets.folder import DatasetError
from dockfactory.eval.solve_frames import pose_record, solve_dataset, write_poses
from dockfactory.eval.uncertainty import EXPECTED, calibration_block, reported_std, standard_scores, z_stats
from dockfactory.generator.datasets.reader import Dataset
from dockfactory.solver import FocalNotObservable, solve_docking
from dockfactory.solver.synthetic import default_layout, docking_scene

VAR = [0.25, 0.04, 1.0, 1e-4, 4e-3, 9e-4]     # distinct variances over X, Y, Z, alpha, beta, gamma
INDEX = {"x": 0, "y": 1, "z": 2, "alpha": 3, "beta": 4, "gamma": 5}   # POSE_NAMES, spelled out


def _cov():
    cov = np.diag(VAR)
    cov[0, 3] = cov[3, 0] = 0.002               # off-diagonal terms must not matter
    return cov


def test_reported_std_follows_the_pose_key_order_and_units():
    std = reported_std(_cov().tolist())
    assert std == pytest.approx({c: math.sqrt(VAR[k]) for c, k in INDEX.items()}, rel=1e-12)
    err = {"x": -1.0, "y": 0.1, "z": 0.0, "alpha": 0.03, "beta": 0.0, "gamma": -0.06}
    z = standard_scores(err, std)
    assert z["x"] == pytest.approx(-2.0) and z["y"] == pytest.approx(0.5) and z["alpha"] == pytest.approx(3.0)
    assert z["gamma"] == pytest.approx(-2.0)
    bad = _cov()
    bad[1, 1], bad[3, 3] = 0.0, float("nan")
    std = reported_std(bad)
    assert std["y"] is None and std["alpha"] is None and standard_scores(err, std)["y"] is None
    for shape in (np.eye(5), np.eye(6)[:, :5], "no matrix"):
        with pytest.raises(DatasetError, match="frames.f1.covariance"):
            reported_std(shape, "frames.f1.covariance")


def test_z_stats_and_the_normal_reference():
    s = z_stats([1.0, -1.0, 3.0, None])
    assert s["n"] == 3 and s["rms_z"] == pytest.approx(math.sqrt(11 / 3)) and s["within_2sigma"] == pytest.approx(2 / 3)
    assert s["max_abs_z"] == 3.0 and s["mean_z"] == pytest.approx(1.0) and s["robust_z"] == pytest.approx(1.4826)
    assert z_stats([None])["rms_z"] is None
    assert EXPECTED["within_2sigma"] == pytest.approx(0.9545, abs=1e-4)


def _monte_carlo_rows(n=300, sigma=0.3, seed=44):
    layout = default_layout()
    ids = [m.id for m in layout]
    rng = np.random.default_rng(seed)
    rows = []
    for _ in range(n):
        sc = docking_scene(rng)
        uv = np.vstack([sc.uv_a, sc.uv_b]) + rng.normal(0.0, sigma, (len(ids), 2))
        try:
            res = solve_docking(layout, sc.principal_point, correspondences=(ids, uv), sigma_px=sigma)
        except FocalNotObservable:
            continue
        rec = json.loads(json.dumps(pose_record(res, len(ids))))     # as the poses file holds it
        err = pose_error(rec["pose"], pose_components(sc.d_from_b))
        z = standard_scores(err, reported_std(rec["covariance"]))
        rows.append({"ok": True, "condition": "normal", **{f"z_{c}": v for c, v in z.items()}})
    return rows


def test_a_correct_covariance_gives_standard_normal_z():
    rows = _monte_carlo_rows()
    assert len(rows) >= 297
    cal = calibration_block(rows)
    for c in ("x", "y", "alpha"):
        s = cal["overall"][c]
        assert 0.88 <= s["rms_z"] <= 1.12, (c, s)
        assert 0.92 <= s["within_2sigma"] <= 0.985, (c, s)
    assert cal["by_condition"]["normal"]["x"] == cal["overall"]["x"] and cal["without_std"] == 0


@pytest.fixture(scope="module")
def evaluated(painted_source, tmp_path_factory):
    """Detections at the centroids + 0.05 px; the solved poses with a known covariance."""
    ds = Dataset.open(painted_source)
    out = tmp_path_factory.mktemp("calibration")
    rng = np.random.default_rng(5)
    frames = {fid: [{"class_id": m["class_id"], "bbox_px": m["bbox_px"], "score": 0.9, "refined": True,
                     "center_px": (np.array(m["outline_centroid_px"]) + rng.normal(0, 0.05, 2)).tolist()}
                    for m in ds.labels[fid]["markers"] if m["visibility"] == 2]
              for fid in ds.frames(("test", "repeat"))}
    (out / "dets.json").write_text(json.dumps({"dataset_version": ds.version_id, "frames": frames}))
    poses = solve_dataset(ds, detections={"frames": frames})
    for rec in poses["frames"].values():
        rec["covariance"] = _cov().tolist()
    write_poses(out / "poses.json", poses)
    metrics, rows = evaluate(ds, out / "poses.json", AcceptanceSpec(), out / "dets.json")
    write_outputs(out / "eval", metrics, rows)
    (out / "eval" / "provenance.json").write_text(json.dumps({"detections": str(out / "dets.json")}))
    return ds, poses, metrics, out


def test_evaluate_reports_z_from_the_poses_file_covariance(evaluated):
    ds, poses, metrics, out = evaluated
    expect = {c: [] for c in INDEX}
    by_cond = {}
    for fid in ds.frames(("test",)):
        est, true = poses["frames"][fid]["pose"], ds.labels[fid]["pose_b_in_d"]
        for c, k in INDEX.items():
            key = f"{c}_mm" if k < 3 else f"{c}_deg"
            expect[c].append((est[key] - true[key]) / math.sqrt(VAR[k]))
        by_cond[ds.labels[fid]["spec"]["condition"]] = {c: expect[c][-1] for c in INDEX}
    cal = metrics["localization"]["calibration"]
    for c in INDEX:
        z = np.array(expect[c])
        assert cal["overall"][c]["n"] == 4
        assert cal["overall"][c]["rms_z"] == pytest.approx(math.sqrt(np.mean(z ** 2)), rel=1e-9)
        assert cal["overall"][c]["within_2sigma"] == pytest.approx(np.mean(np.abs(z) <= 2.0))
        for cond, zc in by_cond.items():
            assert cal["by_condition"][cond][c]["rms_z"] == pytest.approx(abs(zc[c]), rel=1e-9)
    rows = {r["frame_id"]: r for r in read_rows(out / "eval")}     # frames.csv carries std and z
    for k, fid in enumerate(ds.frames(("test",))):
        assert rows[fid]["std_alpha"] == pytest.approx(math.sqrt(VAR[3]))
        assert rows[fid]["z_x"] == pytest.approx(expect["x"][k], rel=1e-9)
    # the oracle's covariance is the solver's at the noise it is told: its z is computed too
    assert metrics["oracle"]["localization"]["calibration"]["overall"]["x"]["n"] == 4


def test_report_prints_the_sigma_the_table_and_a_qq_plot(evaluated, tmp_path):
    _, _, metrics, out = evaluated
    summary = build_report(out / "eval", tmp_path / "report.html")
    html = (tmp_path / "report.html").read_text()
    md = (tmp_path / "report.md").read_text()
    used = metrics["centre_noise"]["used"]
    cal = metrics["localization"]["calibration"]["overall"]
    assert "Is the reported covariance honest?" in html and 'alt="QQ plot of z = error / reported std"' in html
    assert f"rms_px = {used['value']:.3g} px per axis over {used['n']} detections" in html
    assert f"rms_px = {used['value']:.3g} px per axis over {used['n']} detections" in md
    assert f"| all | x | 4 | {cal['x']['rms_z']:.3g} | {cal['x']['within_2sigma']:.1%} |" in md
    assert summary["centre_noise_used"]["value"] == used["value"]
    assert summary["covariance_calibration"]["alpha"]["rms_z"] == cal["alpha"]["rms_z"]
    # the GUM budget of a single pose over the solved test frames, per gated component
    budget = metrics["uncertainty_budget"]
    assert budget["n"] == metrics["localization"]["n_solved"] and budget["components"]["x_mm"]["combined"] > 0
    assert "Uncertainty budget of a single pose (GUM, JCGM 100)" in html and "U (k = 2)" in html


def test_report_still_reads_an_older_metrics_file(evaluated, tmp_path):
    _, _, metrics, out = evaluated
    old = out / "eval_older"             # beside the evaluation: its inputs are where it names them
    shutil.rmtree(old, ignore_errors=True)
    shutil.copytree(out / "eval", old)
    legacy = json.loads((old / "metrics.json").read_text())
    del legacy["centre_noise"]
    for block in (legacy["localization"], legacy["oracle"]["localization"]):
        del block["calibration"]
    (old / "metrics.json").write_text(json.dumps(legacy))
    build_report(old, tmp_path / "report.html")
    html = (tmp_path / "report.html").read_text()
    assert "older metrics file" in html and "Is the reported covariance honest?" not in html


@pytest.mark.slow  # several seconds of solves or pages; the full suite runs it
def test_the_report_is_the_same_from_any_folder_or_one_line_without_its_inputs(evaluated, tmp_path, monkeypatch):
    """The evaluation records its inputs relative to its folder: report from inside the tree and
    from elsewhere gives the same bytes (the date pinned by SOURCE_DATE_EPOCH); the evaluation
    folder copied away from its inputs is a one-line error naming the missing input, not a report
    without its pictures and exit 0."""
    _, _, _, out = evaluated
    metrics = json.loads((out / "eval" / "metrics.json").read_text())
    assert not Path(metrics["poses"]["path"]).is_absolute() and not Path(metrics["dataset"]["root"]).is_absolute()
    monkeypatch.setenv("SOURCE_DATE_EPOCH", "1764720000")
    monkeypatch.chdir(out)
    build_report(Path("eval"), tmp_path / "a.html")
    monkeypatch.chdir(tmp_path)
    build_report(out / "eval", tmp_path / "b.html")
    assert (tmp_path / "a.html").read_bytes() == (tmp_path / "b.html").read_bytes()
    assert "2025-12-03T00:00:00+00:00" in (tmp_path / "a.html").read_text()
    shutil.copytree(out / "eval", tmp_path / "alone")
    with pytest.raises(DatasetError, match=r"metrics\.json: (dataset\.root|poses\.path): .* not found .*: the report reads it"):
        build_report(tmp_path / "alone", tmp_path / "c.html")
    assert not (tmp_path / "c.html").exists()
