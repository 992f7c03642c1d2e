"""Numbers at the edge of what a float holds, and values of the wrong type, in the files and flags
a user gives: one line and exit 2, never OverflowError or TypeError (a centre-noise floor of
1e308 squared overflowed the covariances)."""
import json

import numpy as np
import pytest

from cli_run import one_line_error, run_cli

from dockfactory.generator.datasets.reader import Dataset


def _label_detections(ds: Dataset) -> dict:
    """Detections made from the labels (exact centres), as `dockfactory detect` writes them."""
    frames = {}
    for fid in ds.frames(("test",)):
        lab = ds.labels[fid]
        frames[fid] = [{"class_id": m["class_id"], "center_px": m["outline_centroid_px"], "score": 0.9,
                        "bbox_px": m["bbox_px"], "bbox_detector_px": m["bbox_px"], "refined": True,
                        "edge_px": None if k % 3 == 0 else 0.6}
                       for k, m in enumerate(lab["markers"]) if m.get("visibility") == 2]
    return {"dataset_version": ds.version_id, "frames": frames}


@pytest.mark.parametrize("value", ["1e308", "1e200", "101", "-1", "nan", "inf", "0"])
def test_sigma_floor_flag_out_of_range(painted_source, tmp_path, capsys, value):
    code, _, err = run_cli(["solve", painted_source, "--oracle-noise", "0.1", "--sigma-floor", value,
                         "--out", tmp_path / "p.json"], capsys)
    assert code == 2 and "--sigma-floor" in one_line_error(err)
    assert not (tmp_path / "p.json").exists()


@pytest.mark.parametrize("edit, key", [
    (lambda d: d.update(centre_noise_px=1e308), "centre_noise_px"),
    (lambda d: d.update(centre_noise_px="abc"), "centre_noise_px"),
    (lambda d: d.update(centre_noise_px=[1]), "centre_noise_px"),
    (lambda d: d.update(centre_noise_px=-0.1), "centre_noise_px"),
    (lambda d: d.update(centre_noise_core_px=-0.1), "centre_noise_core_px"),
    (lambda d: d.update(centre_noise_core_px="abc"), "centre_noise_core_px"),
    (lambda d: next(iter(d["frames"].values()))[0].update(bbox_detector_px="x"), "bbox_detector_px"),
    (lambda d: next(iter(d["frames"].values()))[0].update(bbox_detector_px=[1, 2, 3, float("nan")]),
     "bbox_detector_px"),
    (lambda d: next(iter(d["frames"].values()))[0].update(edge_px="wide"), "edge_px"),
    (lambda d: next(iter(d["frames"].values()))[0].update(edge_px=-0.5), "edge_px"),
    (lambda d: next(iter(d["frames"].values()))[0].update(edge_px=1e308), "edge_px"),
])
def test_detections_with_impossible_numbers(painted_source, tmp_path, capsys, edit, key):
    dets = _label_detections(Dataset.open(painted_source))
    edit(dets)
    path = tmp_path / "dets.json"
    path.write_text(json.dumps(dets))
    assert run_cli(["solve", painted_source, "--oracle-noise", "0.1", "--out", tmp_path / "p0.json"], capsys)[0] == 0
    for argv in (["solve", painted_source, "--detections", path, "--out", tmp_path / "p.json"],
                 ["evaluate", painted_source, "--poses", tmp_path / "p0.json", "--detections", path,
                  "--out", tmp_path / "eval"]):
        code, _, err = run_cli(argv, capsys)
        line = one_line_error(err)
        assert code == 2 and str(path) in line and key in line, line
    assert not (tmp_path / "p.json").exists()


def test_the_label_detections_themselves_solve(painted_source, tmp_path, capsys):
    """The fixture's detections are valid: the refusals above come from the edits alone."""
    dets = _label_detections(Dataset.open(painted_source))
    dets["centre_noise_px"] = 0.05
    path = tmp_path / "dets.json"
    path.write_text(json.dumps(dets))
    code, _, err = run_cli(["solve", painted_source, "--detections", path, "--out", tmp_path / "p.json"], capsys)
    poses = json.loads((tmp_path / "p.json").read_text())
    assert code == 0 and poses["sigma_floor_px"] == 0.05
    assert any(r["ok"] for r in poses["frames"].values()) and np.isfinite(
        [r["pose"]["x_mm"] for r in poses["frames"].values() if r["ok"]]).all()


def _solved(painted_source, tmp_path, capsys) -> dict:
    assert run_cli(["solve", painted_source, "--oracle-noise", "0.1", "--out", tmp_path / "p.json"], capsys)[0] == 0
    return json.loads((tmp_path / "p.json").read_text())


@pytest.mark.parametrize("field, value, key", [
    ("x_mm", 1e200, "pose.x_mm"), ("alpha_deg", 1e5, "pose.alpha_deg"), ("focal_px", 1e300, "focal_px"),
])
def test_poses_of_impossible_size_are_refused_before_any_statistic(painted_source, tmp_path, capsys, field,
                                                                    value, key):
    """A pose of 1e200 mm overflowed the report's histograms (IndexError deep in numpy)."""
    poses = _solved(painted_source, tmp_path, capsys)
    rec = next(r for r in poses["frames"].values() if r["ok"])
    (rec["pose"] if field in rec["pose"] else rec)[field] = value
    (tmp_path / "big.json").write_text(json.dumps(poses))
    code, out, err = run_cli(["evaluate", painted_source, "--poses", tmp_path / "big.json", "--out", tmp_path / "ev"],
                          capsys)
    line = one_line_error(err)
    assert code == 2 and key in line and "big.json" in line and "ACCEPTED" not in out, line


def _no_plots(monkeypatch):
    """The report without its plots (they are most of its time; tests/app/test_stages.py::test_report_stage
    draws and counts them): nothing these tests check is in a plot."""
    import dockfactory.eval.report.document as report
    monkeypatch.setattr(report, "plots", lambda rows, metrics, detections_pr=None: {})


def test_report_refuses_a_frames_table_cut_to_its_header(painted_source, tmp_path, capsys, monkeypatch):
    _no_plots(monkeypatch)
    _solved(painted_source, tmp_path, capsys)
    spec = tmp_path / "spec.toml"
    spec.write_text("[localization]\nx = 1000\n[estimation]\nx = 1000\n[failures]\nmax_rate = 1.0\n")
    code, out, _ = run_cli(["evaluate", painted_source, "--poses", tmp_path / "p.json", "--acceptance", spec,
                         "--out", tmp_path / "ev"], capsys)
    assert code == 0 and "ACCEPTED" in out
    assert run_cli(["report", tmp_path / "ev", "--out", tmp_path / "r.html"], capsys)[0] == 0
    table = tmp_path / "ev" / "frames.csv"
    table.write_text(table.read_text().splitlines()[0] + "\n")
    code, out, err = run_cli(["report", tmp_path / "ev", "--out", tmp_path / "r2.html"], capsys)
    line = one_line_error(err)
    assert code == 2 and "frames.csv" in line and "0 test frames" in line and "ACCEPTED" not in out, line
    assert not (tmp_path / "r2.html").exists()


def test_a_fifo_or_a_folder_given_as_a_file_is_refused_without_opening_it(painted_source, tmp_path, capsys):
    """Opening a fifo blocks until someone writes to it: `verify --manifest FIFO` hung."""
    import os
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    _solved(painted_source, tmp_path, capsys)
    for given in (fifo, tmp_path):
        kind = "fifo" if given == fifo else "folder"
        for argv in (["dataset", "verify", painted_source, "--manifest", given],
                     ["solve", painted_source, "--detections", given, "--out", tmp_path / "q.json"],
                     ["evaluate", painted_source, "--poses", given, "--out", tmp_path / "ev"],
                     ["evaluate", painted_source, "--poses", tmp_path / "p.json", "--acceptance", given,
                      "--out", tmp_path / "ev"],
                     ["check-config", given]):
            code, _, err = run_cli(argv, capsys)
            line = one_line_error(err)
            assert code == 2 and f"is a {kind}" in line and str(given) in line, (argv, line)


def test_the_report_carries_an_id_of_its_inputs_and_a_sign_off_block(painted_source, tmp_path, capsys, monkeypatch):
    _no_plots(monkeypatch)   # the id is of the evaluation's files (eval.report.document.sign_off), not of the plots
    _solved(painted_source, tmp_path, capsys)
    run_cli(["evaluate", painted_source, "--poses", tmp_path / "p.json", "--out", tmp_path / "ev"], capsys)
    assert run_cli(["report", tmp_path / "ev", "--out", tmp_path / "a.html", "--prepared-by", "A. Engineer"],
                   capsys)[0] == 0
    first = json.loads((tmp_path / "a.json").read_text())
    assert len(first["report_id"]) == 16 and first["prepared_by"] == "A. Engineer" and first["approved_by"] == ""
    assert "A. Engineer" in (tmp_path / "a.html").read_text() and "report id" in (tmp_path / "a.html").read_text()
    assert f"Report {first['report_id']}" in (tmp_path / "a.md").read_text()
    run_cli(["report", tmp_path / "ev", "--out", tmp_path / "b.html"], capsys)
    assert json.loads((tmp_path / "b.json").read_text())["report_id"] == first["report_id"]   # same inputs
    prov = tmp_path / "ev" / "provenance.json"
    prov.write_text(prov.read_text().replace('"commands": [', '"commands": ["edited", '))
    run_cli(["report", tmp_path / "ev", "--out", tmp_path / "c.html"], capsys)
    assert json.loads((tmp_path / "c.json").read_text())["report_id"] != first["report_id"]


def test_a_config_that_is_not_utf8_is_one_line(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_bytes(b'[dataset]\nname = "\xff\xfe"\n')
    for argv in (["check-config", bad], ["run", bad, "--out", tmp_path / "w"], ["render", bad, "--out", tmp_path / "d"]):
        code, _, err = run_cli(argv, capsys)
        line = one_line_error(err)
        assert code == 2 and "not UTF-8" in line and str(bad) in line, line
    assert not (tmp_path / "w").exists() and not (tmp_path / "d").exists()


@pytest.mark.parametrize("value", ["1e308", "-0.1", "nan", "a,b", "0.1,0.2,0.3", ""])
def test_section_shift_flag_out_of_range(painted_source, tmp_path, capsys, value):
    code, _, err = run_cli(["solve", painted_source, "--oracle-noise", "0.1", "--section-shift", value,
                            "--out", tmp_path / "p.json"], capsys)
    assert code == 2 and "--section-shift" in one_line_error(err)
    assert not (tmp_path / "p.json").exists()


def test_section_shift_flag_overrides_the_card_and_widens_y(painted_source, tmp_path, capsys):
    """``solve --section-shift`` replaces the detections' card value (one number: both axes) and the
    records carry what it added; the poses name it."""
    ds = Dataset.open(painted_source)
    dets = {**_label_detections(ds), "section_shift_px": [0.0, 0.01]}
    (tmp_path / "d.json").write_text(json.dumps(dets))
    stds = {}
    for flag in (None, "0.2"):
        out = tmp_path / f"p{flag}.json"
        argv = ["solve", painted_source, "--detections", tmp_path / "d.json", "--split", "test", "--out", out]
        code, _, _ = run_cli(argv + (["--section-shift", flag] if flag else []), capsys)
        poses = json.loads(out.read_text())
        assert code == 0 and poses["section_shift_px"] == ([0.0, 0.01] if flag is None else [0.2, 0.2])
        rec = next(r for r in poses["frames"].values() if r["ok"])
        stds[flag] = rec["covariance"][1][1]
        assert rec["section_shift_variance"][1] > 0
    assert stds["0.2"] > stds[None]
