"""bench/paper/paper_results.py: render figures of an interrupted render, Table 1 and the ranking check."""
import json

import pytest

from bench.paper.paper_results import main, ranking_check, render_figures, table1

from dockfactory.core.io import sha256_file  # noqa: E402


def _rows(starts_and_counts, step=5.0, total=4.5):
    rows = []
    for start, count in starts_and_counts:
        rows += [{"finished_at": start + i * step, "total": total, "cycles": 4.0, "rss_mb": 600.0 + i}
                 for i in range(count)]
    return rows


def test_render_figures_leave_the_pauses_out():
    one = render_figures(_rows([(1000.0, 10)]))
    assert one["frames"] == 10 and one["segments"] == 1
    assert one["active_wall_s"] == pytest.approx(4.5 + 9 * 5.0)
    two = render_figures(_rows([(1000.0, 10), (90000.0, 10)]))   # resumed a day later
    assert two["segments"] == 2
    assert two["active_wall_s"] == pytest.approx(2 * (4.5 + 9 * 5.0))
    assert two["frames_per_hour"] == pytest.approx(3600 * 20 / two["active_wall_s"], rel=1e-3)
    assert two["peak_worker_rss_mb"] == 609.0


def test_a_frame_rendered_again_counts_once_by_its_last_render():
    first = [{**r, "frame_id": f"{i:06d}"} for i, r in enumerate(_rows([(1000.0, 5)]))]     # then deleted
    again = [{**r, "frame_id": f"{i:06d}"} for i, r in enumerate(_rows([(1030.0, 10)]))]
    fig = render_figures(first + again)
    assert fig["frames"] == 10 and fig["segments"] == 1
    assert fig["active_wall_s"] == pytest.approx(4.5 + 9 * 5.0)      # the first five renders left out


def _rec(att, seed, m50, m5095, v5=None, net=None):
    rec = {"attention": att, "seed": seed, "mAP50": m50, "mAP50_95": m5095}
    if v5 is not None:
        rec["yolov5"] = {"mAP50": v5[0], "mAP50_95": v5[1]}
    if net is not None:     # the network's own boxes, on both scales
        rec["network_boxes"] = {"mAP50": net[0], "mAP50_95": net[1],
                                "yolov5": {"mAP50": net[0] - 0.001, "mAP50_95": net[1] + 0.002}}
    return rec


def test_table1_means_stds_and_the_ranking_in_sigmas():
    recs = [_rec("se", s, 0.99, v) for s, v in enumerate((0.84, 0.85, 0.86))]
    recs += [_rec("eca", s, 0.99, v) for s, v in enumerate((0.82, 0.83, 0.84))]
    recs += [_rec("none", 0, 0.98, 0.80)]
    t1 = table1(recs)
    assert t1["se"]["mAP50_95"]["mean"] == pytest.approx(0.85)
    assert t1["se"]["mAP50_95"]["std"] == pytest.approx(0.01)
    assert t1["none"]["mAP50_95"]["std"] is None             # one seed: no spread to quote
    pairs = ranking_check(t1)
    assert pairs[0]["pair"] == "se > eca" and pairs[0]["holds"]
    assert pairs[0]["sigmas"] == pytest.approx(2.0)          # 0.02 apart, pooled std 0.01
    assert [p["pair"] for p in pairs] == ["se > eca"]        # a2 has no runs: the pair is left out


def test_main_writes_what_it_has_and_marks_the_rest(tmp_path, capsys):
    ds = tmp_path / "ds"
    (ds / "logs").mkdir(parents=True)
    (ds / "logs" / "timings.jsonl").write_text("\n".join(json.dumps(r) for r in _rows([(0.0, 3)])) + "\n")
    rec = tmp_path / "t1"
    rec.mkdir()
    (rec / "se_seed0.json").write_text(json.dumps(_rec("se", 0, 0.99, 0.85)))
    assert main(["--dataset", str(ds), "--out", str(tmp_path / "out"), "--table1", str(rec)]) == 0
    doc = json.loads((tmp_path / "out" / "metrics.json").read_text())
    assert doc["dataset"]["complete"] is False and doc["render"]["frames"] == 3
    table = (tmp_path / "out" / "report.md").read_text()
    assert "| YOLOv5s + SE: mAP50:95 | 0.834 | refined 0.850 ± — COCO (1 seed) |" in table
    assert "| YOLOv5s + ECA: mAP50 | 0.995 | not run yet |" in table
    assert "localization alpha" in capsys.readouterr().out


def test_a_rerender_keeps_the_published_render_figures(tmp_path):
    ds = tmp_path / "ds"
    (ds / "logs").mkdir(parents=True)
    (ds / "logs" / "timings.jsonl").write_text("\n".join(json.dumps(r) for r in _rows([(0.0, 3)])) + "\n")
    (ds / "manifest.json").write_text(json.dumps({"version_id": "v1", "other": "bits"}))
    out = tmp_path / "out"
    out.mkdir()
    published = out / "manifest.json"
    published.write_text(json.dumps({"version_id": "v1"}))
    first = {"dataset": {"manifest_sha256": sha256_file(published)}, "render": render_figures(_rows([(0.0, 5)]))}
    (out / "metrics.json").write_text(json.dumps(first))
    assert main(["--dataset", str(ds), "--out", str(out), "--published", str(published)]) == 0
    doc = json.loads((out / "metrics.json").read_text())
    assert doc["dataset"]["rerender_of"] == sha256_file(published) != doc["dataset"]["manifest_sha256"]
    assert doc["render"] == first["render"] and doc["rerender"]["frames"] == 3
    assert "re-render of the published dataset" in (out / "report.md").read_text()
    assert main(["--dataset", str(ds), "--out", str(out), "--published", str(published)]) == 0
    assert json.loads((out / "metrics.json").read_text())["render"] == first["render"]   # kept again
    first["dataset"]["manifest_sha256"] = "0" * 64                              # made on another dataset
    (out / "metrics.json").write_text(json.dumps(first))
    assert main(["--dataset", str(ds), "--out", str(out), "--published", str(published)]) == 0
    assert json.loads((out / "metrics.json").read_text())["render"] == {}
    (ds / "manifest.json").write_bytes(published.read_bytes())                  # the published dataset itself
    assert main(["--dataset", str(ds), "--out", str(out), "--published", str(published)]) == 0
    doc = json.loads((out / "metrics.json").read_text())
    assert doc["render"]["frames"] == 3 and "rerender" not in doc and "rerender_of" not in doc["dataset"]


def _eval_metrics(accepted=False):
    axis = {"n": 10, "mse": 0.25, "rmse": 0.5}
    return {"localization": {"n_frames": 10, "n_solved": 10, "overall": {a: axis for a in ("x", "y", "alpha")},
                             "crb": {a: {"bound_rms": 0.4} for a in ("x", "y", "alpha")}},
            "estimation": {"n_frames": 20, "pooled": {a: axis for a in ("x", "y", "alpha")}},
            "acceptance": {"accepted": accepted, "criteria": [
                {"name": "localization precision: x", "value": 0.5, "threshold": 0.3, "unit": "mm", "pass": False,
                 "paper": 0.794}]}}


def test_report_lists_each_detector_its_weights_figures_and_verdict(tmp_path):
    ds = tmp_path / "ds"
    ds.mkdir()
    (ds / "dataset.json").write_text(json.dumps({"version_id": "abcd1234abcd1234"}))
    det = tmp_path / "s_se"
    det.mkdir()
    (det / "metrics.json").write_text(json.dumps(_eval_metrics()))
    acc = {"frames": 600, "mAP50": 0.99, "mAP50_95": 0.91, "yolov5": {"mAP50": 0.994, "mAP50_95": 0.92},
           "centre_error_by_condition": {"glare": {"median_px": 0.123}, "normal": {"median_px": 0.081}}}
    (det / "detector.json").write_text(json.dumps({"accuracy": acc, "inference": {"ms_per_image_median": 210.4}}))
    net = {"mAP50": 0.985, "mAP50_95": 0.832, "yolov5": {"mAP50": 0.99, "mAP50_95": 0.851}}
    (det / "detector_repeat.json").write_text(json.dumps({"accuracy": {**acc, "frames": 200, "network_boxes": net}}))
    (det / "w.pt").write_bytes(b"0" * 2_000_000)
    spec = f"s_se={det}:{det / 'detector.json'}:{det / 'w.pt'}"
    missing = f"n_se={tmp_path / 'n'}:{tmp_path / 'n' / 'detector.json'}:{tmp_path / 'n' / 'w.pt'}"
    assert main(["--dataset", str(ds), "--out", str(tmp_path / "out"), "--detector", spec, "--detector", missing]) == 0
    report = (tmp_path / "out" / "report.md").read_text()
    assert "version id: `abcd1234abcd1234` (no manifest yet" in report       # from dataset.json
    assert "2.00 MB" in report and "210.4 ms per 1280 x 960 image" in report
    assert "test split (600 frames): mAP50 0.990, mAP50:95 0.910 (COCO; YOLOv5's 0.994, 0.920); median " \
           "centre error (px) glare 0.123, normal 0.081" in report
    assert "repeat split (200 frames): mAP50 0.985, mAP50:95 0.832 (COCO; YOLOv5's 0.990, 0.851) on the " \
           "network's own boxes; refined boxes: mAP50 0.990, mAP50:95 0.910 (COCO; YOLOv5's 0.994, 0.920); " \
           "median centre error (px) glare 0.123, normal 0.081" in report
    assert "Acceptance: **REJECTED**" in report
    assert f"- weights `{tmp_path / 'n' / 'w.pt'}`: not trained yet" in report
    assert "| localization precision: x | 0.5000 mm | 0.3000 | no |" in report
    assert "| localization x (paper's \"MSE\", an RMS) | 0.794 mm | RMSE 0.500 mm (bound 0.400); " \
           "MSE 0.2500 mm² |" in report


def test_report_states_the_ranking_in_sigmas(tmp_path):
    rec = tmp_path / "t1"
    rec.mkdir()
    for att, vals in (("se", (0.84, 0.85, 0.86)), ("eca", (0.82, 0.83, 0.84))):
        for s, v in enumerate(vals):
            (rec / f"{att}_seed{s}.json").write_text(json.dumps(_rec(att, s, 0.99, v, (0.995, v + 0.01))))
    (tmp_path / "ds").mkdir()
    assert main(["--dataset", str(tmp_path / "ds"), "--out", str(tmp_path / "out"), "--table1", str(rec)]) == 0
    report = (tmp_path / "out" / "report.md").read_text()
    assert "| se > eca | +0.0200 | 0.0100 | +2.0 | +2.4 | yes |" in report     # t: 0.02 / (0.01 sqrt(2/3))
    assert "| YOLOv5s + SE: mAP50:95 | 0.834 | refined 0.850 ± 0.010 COCO, 0.860 ± 0.010 YOLOv5's (3 seeds) |" in report
    assert "network boxes" not in report                     # records without them: nothing invented


def test_table1_and_the_ranking_on_the_network_boxes(tmp_path):
    rec = tmp_path / "t1"
    rec.mkdir()
    for att, vals in (("se", (0.84, 0.85, 0.86)), ("eca", (0.82, 0.83, 0.84))):
        for s, v in enumerate(vals):
            net = (0.99, v - 0.03 if att == "se" else v)   # the networks' own boxes rank the other way
            (rec / f"{att}_seed{s}.json").write_text(json.dumps(_rec(att, s, 0.99, v, (0.995, v + 0.01), net)))
    (tmp_path / "ds").mkdir()
    assert main(["--dataset", str(tmp_path / "ds"), "--out", str(tmp_path / "out"), "--table1", str(rec)]) == 0
    report = (tmp_path / "out" / "report.md").read_text()
    assert ("| YOLOv5s + SE: mAP50:95 | 0.834 | network boxes 0.820 ± 0.010 COCO, 0.822 ± 0.010 YOLOv5's; "
            "refined 0.850 ± 0.010 COCO, 0.860 ± 0.010 YOLOv5's (3 seeds) |") in report
    net = report.split("network's boxes, the paper's measure)")[1].split("##")[0]
    assert "| se > eca | -0.0100 | 0.0100 | -1.0 | -1.2 | no |" in net      # 0.820 against 0.830
    refined = report.split("the refined boxes our pipeline outputs)")[1]
    assert "| se > eca | +0.0200 | 0.0100 | +2.0 | +2.4 | yes |" in refined
