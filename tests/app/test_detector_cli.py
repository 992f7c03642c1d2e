"""The detector subcommands: torch-free --help, train -> detect (+ eval) -> export-onnx on the painted
smoke dataset (a complete dockfactory dataset: the commands open datasets through the contract)."""
import json
import os
import subprocess
import sys

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import pytest


def test_help_is_torch_free(repo_root):
    code = ("import argparse, sys\nfrom dockfactory.cli_detector import add_subcommands\n"
            "p = argparse.ArgumentParser(); add_subcommands(p.add_subparsers(dest='c'))\n"
            "for c in ('train', 'detect', 'ablate', 'export-onnx'):\n"
            "    try:\n        p.parse_args([c, '--help'])\n    except SystemExit:\n        pass\n"
            "assert 'torch' not in sys.modules and 'kornia' not in sys.modules\n")
    proc = subprocess.run([sys.executable, "-c", code], cwd=repo_root, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert "--attention" in proc.stdout and "--weights" in proc.stdout


@pytest.mark.slow   # trains, detects, exports and checks ONNX: about 10 s
def test_train_detect_eval_export(painted_source, tmp_path, capsys):
    from dockfactory.cli import main
    data = painted_source
    run = tmp_path / "run"
    assert main(["train", str(data), "--out", str(run), "--epochs", "1", "--batch", "4", "--input-scale", "0.5",
                 "--crops-per-frame", "1", "--threads", "1", "--quiet"]) == 0
    assert (run / "last.pt").is_file() and (run / "weights.pt").is_file()
    assert main(["train", str(data), "--out", str(run), "--epochs", "2", "--batch", "4", "--input-scale", "0.5",
                 "--crops-per-frame", "1", "--threads", "1", "--quiet", "--resume"]) == 0
    assert json.loads((run / "history.json").read_text())["history"][-1]["epoch"] == 2
    dets = tmp_path / "dets.json"
    assert main(["detect", str(data), "--weights", str(run / "weights.pt"), "--out", str(dets), "--conf", "0.001",
                 "--threads", "1", "--quiet", "--eval"]) == 0
    doc = json.loads(dets.read_text())
    assert doc["dataset_version"] == json.loads((data / "dataset.json").read_text())["version_id"]
    test_ids = {json.loads(p.read_text())["frame_id"] for p in (data / "labels").glob("*.json")
                if json.loads(p.read_text())["spec"]["split"] == "test"}
    assert len(doc["weights_sha256"]) == 64 and set(doc["frames"]) == test_ids and test_ids
    for d in sum(doc["frames"].values(), []):
        assert {"class_id", "class_name", "score", "bbox_px", "center_px", "refine_quality"} <= set(d)
    assert "mAP50" in capsys.readouterr().out
    pytest.importorskip("onnxruntime")
    assert main(["export-onnx", "--weights", str(run / "weights.pt"), "--out", str(tmp_path / "m.onnx"),
                 "--height", "96", "--width", "128", "--threads", "1"]) == 0   # any size that is a multiple of 32
    assert "max |onnx - torch|" in capsys.readouterr().out


def test_bad_weights_exit_2(painted_source, tmp_path, capsys):
    from dockfactory.cli import main
    data = painted_source
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"PK\x03\x04 truncated")
    assert main(["detect", str(data), "--weights", str(bad), "--out", str(tmp_path / "d.json"), "--quiet"]) == 2
    assert "bad.pt" in capsys.readouterr().err


@pytest.mark.slow   # one tiny training run: about 5 s
def test_ablate_record_survives_the_loss_of_the_runs(painted_source, tmp_path, capsys, monkeypatch):
    import shutil

    from dockfactory import ablate
    from dockfactory.cli import main
    out, record = tmp_path / "runs", tmp_path / "record"
    argv = ["ablate", str(painted_source), "--attention", "none", "--seeds", "1", "--epochs", "1", "--batch", "4",
            "--crops-per-frame", "1", "--threads", "1", "--quiet", "--out", str(out), "--record", str(record)]
    assert main(argv) == 0
    rec = json.loads((record / "none_seed0.json").read_text())
    assert rec["dataset_version"] == json.loads((painted_source / "dataset.json").read_text())["version_id"]
    assert rec["config"]["epochs"] == 1 and 0 <= rec["mAP50"] <= 1
    assert 0 <= rec["yolov5"]["mAP50"] <= 0.995 and set(rec["yolov5"]["per_class"]) == set(rec["per_class"])
    net = rec["network_boxes"]                                  # the network's boxes, before refinement
    assert 0 <= net["mAP50_95"] <= net["mAP50"] <= 1 and set(net["per_class"]) == set(rec["per_class"])
    older = {k: v for k, v in rec.items() if k not in ("yolov5", "network_boxes")}   # a record made earlier ...
    (record / "none_seed0.json").write_text(json.dumps(older))
    assert main(argv + ["--no-train"]) == 0                     # ... gets them from the saved detections
    now = json.loads((record / "none_seed0.json").read_text())
    assert now["yolov5"] == rec["yolov5"] and now["network_boxes"] == net
    assert "network boxes mAP50:95" in capsys.readouterr().out
    table = (out / "ablation.md").read_text()
    other = [a if a != "1" or i != argv.index("--epochs") + 1 else "2" for i, a in enumerate(argv)]
    shutil.rmtree(record)
    assert main(other) == 2                # a finished run of another budget in OUT is not reused
    assert "none_seed0: a finished run of another dataset version or training config" in capsys.readouterr().err
    assert main(argv) == 0                 # the same budget takes it again (and records it)
    shutil.rmtree(out)                     # the runs are gone (out/ of a past session) ...

    def no_training(*a, **k):
        raise AssertionError("trained again")
    monkeypatch.setattr(ablate, "_train_and_evaluate", no_training)
    assert main(argv) == 0                 # ... the committed record still gives the table
    assert (out / "ablation.md").read_text().split("total training")[0] == table.split("total training")[0]
    with pytest.raises(AssertionError, match="trained again"):   # another budget is another run
        main(other)
    assert main(other + ["--no-train"]) == 2                     # ... which --no-train does not train
    assert "no run of the ablation is finished" in capsys.readouterr().err


def test_ablate_runs_seed_by_seed(painted_source, tmp_path, monkeypatch):
    """An ablation stopped part-way has the first seeds of every variant, not all seeds of the first."""
    from dockfactory.detector.train import TrainConfig
    from dockfactory import ablate
    from dockfactory.generator.datasets.reader import Dataset
    order = []

    def fake_run(dataset, out, att, seed, cfg, conf, progress, record_dir, train):
        order.append((att, seed))
        return {"attention": att, "seed": seed, "train_seconds": 1.0, "mAP50": 1.0, "mAP50_95": 0.9,
                "per_class": {"RedA": {"mAP50": 1.0, "mAP50_95": 0.9}}}
    monkeypatch.setattr(ablate, "_run_one", fake_run)
    ablate.run_ablation(Dataset.open(painted_source), tmp_path, ["none", "se"], [0, 1],
                        lambda att, seed: TrainConfig(), progress=False)
    assert order == [("none", 0), ("se", 0), ("none", 1), ("se", 1)]


@pytest.mark.slow   # the shipped detector twice over the painted test frames: about 8 s
def test_detect_writes_coco_results_that_cocoeval_takes(painted, tmp_path, capsys):
    """`detect --format coco-results`: the same detections as the native document, as rows with
    the ids of the dataset's COCO export, which COCOeval evaluates against that export."""
    import contextlib
    import io

    import numpy as np
    from pycocotools.coco import COCO
    from pycocotools.cocoeval import COCOeval

    from dockfactory.cli import main
    assert main(["dataset", "export", str(painted), "--format", "coco"]) == 0
    native, results = tmp_path / "dets.json", tmp_path / "results.json"
    for fmt, out in (("dockfactory", native), ("coco-results", results)):
        assert main(["detect", str(painted), "--out", str(out), "--format", fmt, "--threads", "1", "--quiet"]) == 0
    assert "(COCO results)" in capsys.readouterr().out
    doc, rows = json.loads(native.read_text()), json.loads(results.read_text())
    dets = [d for fid in sorted(doc["frames"]) for d in doc["frames"][fid]]
    assert isinstance(rows, list) and len(rows) == len(dets) > 0
    with contextlib.redirect_stdout(io.StringIO()):
        gt = COCO(str(painted / "exports" / "coco" / "annotations" / "person_keypoints_test.json"))
        frame_of = {img["id"]: img["frame_id"] for img in gt.dataset["images"]}
        assert {r["image_id"] for r in rows} <= set(frame_of)
        for r in rows:   # each row is one of the frame's detections: box + 0.5, centre as it is
            d = next(d for d in doc["frames"][frame_of[r["image_id"]]]
                     if np.allclose(np.add(d["bbox_px"][:2], 0.5), r["bbox"][:2], atol=1e-4))
            assert r["category_id"] == d["class_id"] + 1 and np.allclose(r["keypoints"][:2], d["center_px"], atol=1e-4)
        for iou_type in ("bbox", "keypoints"):
            ev = COCOeval(gt, gt.loadRes(rows), iouType=iou_type)
            ev.params.kpt_oks_sigmas = np.array(gt.dataset["info"]["kpt_oks_sigmas"])
            ev.evaluate()
            ev.accumulate()
            ev.summarize()
            assert 0.0 < ev.stats[0] <= 1.0, iou_type   # the shipped detector finds the painted markers


def test_detect_refuses_an_unknown_format(painted, tmp_path, capsys):
    from cli_run import run_cli
    code, _, err = run_cli(["detect", painted, "--out", tmp_path / "d.json", "--format", "yolo"], capsys)
    assert code == 2 and "--format" in err and "coco-results" in err and not (tmp_path / "d.json").exists()
