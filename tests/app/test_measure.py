"""dockfactory measure: real-image entry point. On a painted 1280 x 960 dataset (tests/pipeline_data.py,
no Blender) it gives the same poses as detect + solve on the same images; bad images are reported
per image, never dropped; bad input is a one-line error (exit 2)."""
import csv
import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from pipeline_data import painted_config, painted_from_text

from dockfactory.core.names import POSE_NAMES
from dockfactory.core.resources import shipped_weights
from dockfactory.detector.noise_card import centre_noise_px
from dockfactory.detector.onnx_runtime import onnxruntime_available
from dockfactory.cli import main

CONFIG = painted_config("measure-test", 11, 4, 0.5)
# the same scene as one docking run: every frame through one camera (--self-calibrate sequence's premise)
RUN_CONFIG = CONFIG + "\n[runs]\nframes_per_run = 4\n"


@pytest.fixture(scope="module")
def big(tmp_path_factory):
    return painted_from_text(tmp_path_factory, "measure", CONFIG)


def test_bad_input_is_one_line_exit_2(big, tmp_path, capsys):
    empty = tmp_path / "empty"
    empty.mkdir()
    (tmp_path / "junk.pt").write_bytes(b"not a checkpoint")
    cases = [([str(empty), "--layout", str(big / "layout.json")], "no PNG, JPEG, TIFF or BMP images"),
             ([str(big / "images"), "--layout", str(tmp_path / "nope.json")], "layout file not found"),
             ([str(big / "images"), "--layout", str(big / "layout.json"), "--camera-model", "fisheye"], "fisheye"),
             ([str(big / "images"), "--layout", str(big / "layout.json"), "--weights", str(tmp_path / "w.pt")],
              "no such file"),
             ([str(big / "images"), "--layout", str(big / "layout.json"), "--weights", str(tmp_path / "junk.pt")],
              "not a torch weights file"),
             ([str(big / "images"), "--layout", str(big / "layout.json"), "--overlay-size", "3"], "overlay size"),
             ([str(big / "images"), "--layout", str(big / "layout.json"), "--workers", "40"], "workers")]
    for argv, words in cases:
        assert main(["measure", *argv, "--out", str(tmp_path / "out"), "--quiet"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("dockfactory: error:") and words in err[0], err
    assert not (tmp_path / "out" / "measurements.json").exists()


def _poses(doc):
    return {r["image"].rsplit("/", 1)[-1][:-4]: r for r in doc["images"]}


@pytest.mark.slow   # detector on 6 images of 1280 x 960, three times (measure twice, detect)
def test_measure_gives_the_poses_of_detect_and_solve(big, tmp_path, capsys):
    """With detect's own network runtime (torch) in one process: the same poses to 1e-9; with the
    defaults (ONNX Runtime, two worker processes) the same to 1e-4 mm / deg (the runtimes' outputs
    differ by about 1e-5, the centres by under 1e-3 px)."""
    out, fast = tmp_path / "m", tmp_path / "fast"
    assert main(["measure", str(big / "images"), "--layout", str(big / "layout.json"), "--out", str(out),
                 "--threads", "1", "--backend", "torch", "--workers", "1", "--overlay-size", "1", "--quiet"]) == 0
    assert main(["measure", str(big / "images"), "--layout", str(big / "layout.json"), "--out", str(fast),
                 "--quiet"]) == 0
    doc = json.loads((out / "measurements.json").read_text())
    fast_doc = json.loads((fast / "measurements.json").read_text())
    assert (doc["backend"], doc["workers"], fast_doc["workers"], fast_doc["overlay_size"]) == ("torch", 1, 2, 0.5)
    assert fast_doc["backend"] == ("onnx" if onnxruntime_available() else "torch")
    for fid, rec in _poses(doc).items():
        other = _poses(fast_doc)[fid]
        assert other["marker_ids"] == rec["marker_ids"]
        assert max(abs(other["pose"][k] - v) for k, v in rec["pose"].items()) < 1e-4, fid
    assert [json.dumps(r["image"]) for r in doc["images"]] == [json.dumps(r["image"]) for r in fast_doc["images"]]
    full = cv2.imread(str(next((out / "overlays").glob("*.png"))))
    half = cv2.imread(str(next((fast / "overlays").glob("*.png"))))
    assert full.shape == (960, 1280, 3) and half.shape == (480, 640, 3)
    assert doc["images_total"] == doc["images_with_pose"] == 6
    dets, poses = tmp_path / "d.json", tmp_path / "p.json"
    assert main(["detect", str(big), "--split", "all", "--out", str(dets), "--threads", "1", "--quiet"]) == 0
    assert main(["solve", str(big), "--detections", str(dets), "--split", "train,val,test,repeat",
                 "--out", str(poses)]) == 0
    solved_doc = json.loads(poses.read_text())
    # the shipped weights' noise card floors the covariance in detect + solve and in measure alike
    card = centre_noise_px(shipped_weights())
    assert card is not None and 0.0 < card < 0.5
    assert solved_doc["sigma_floor_px"] == doc["sigma_floor_px"] == card
    assert json.loads(dets.read_text())["centre_noise_px"] == card
    solved = solved_doc["frames"]
    measured = _poses(doc)
    assert set(measured) == set(solved)
    for fid, rec in solved.items():
        m = measured[fid]
        assert m["ok"] and rec["ok"] and m["marker_ids"] == rec["marker_ids"]
        for k, v in rec["pose"].items():
            assert abs(m["pose"][k] - v) < 1e-9, (fid, k)
        assert abs(m["focal_px"] - rec["focal_px"]) < 1e-6
    rows = list(csv.DictReader((out / "measurements.csv").open()))
    assert len(rows) == 6 and all(r["ok"] == "True" for r in rows)
    # the CSV at a sensible precision (it wrote 17 digits): 0.1 um, 0.01 mdeg, the JSON keeps every bit
    by_name = {Path(r["image"]).stem: r for r in rows}
    for fid, m in measured.items():
        r = by_name[fid]
        assert r["x_mm"] == f"{m['pose']['x_mm']:.4f}" and r["alpha_deg"] == f"{m['pose']['alpha_deg']:.5f}"
        assert len(r["std_x_mm"].split(".")[1]) == 4 and len(r["focal_px"].split(".")[1]) == 3
    assert len(list((out / "overlays").glob("*.png"))) == 6


@pytest.mark.slow
def test_frames_of_different_cameras_are_not_solved_as_one_run(big, tmp_path, capsys):
    """The frames of ``big`` each have their own camera (focal 1200-3000 px): solved as one docking
    run with shared intrinsics, the run's fit cannot explain them (before the run gate: every one
    ok, with one focal length for all)."""
    images = sorted(str(p) for p in (big / "images").glob("*.png"))
    out = tmp_path / "m"
    rc = main(["measure", *images, "--layout", str(big / "layout.json"), "--self-calibrate", "sequence",
               "--out", str(out), "--threads", "1", "--quiet"])
    doc = json.loads((out / "measurements.json").read_text())
    recs = [r for r in doc["images"]]
    assert rc == 1 and sum(r["ok"] for r in recs) <= 1
    assert all("with the run's shared intrinsics" in r["reason"] for r in recs if not r["ok"])


@pytest.fixture(scope="module")
def one_camera(tmp_path_factory):
    return painted_from_text(tmp_path_factory, "measure-run", RUN_CONFIG)


@pytest.mark.slow
def test_bad_images_are_reported_not_dropped_and_self_calibration_runs(one_camera, tmp_path, capsys):
    big = one_camera
    broken = tmp_path / "broken.png"
    broken.write_bytes(b"not a png")
    images = sorted(str(p) for p in (big / "images").glob("*.png"))
    out = tmp_path / "m"
    rc = main(["measure", *images, str(broken), str(tmp_path / "missing.jpg"), "--layout", str(big / "layout.json"),
               "--self-calibrate", "sequence", "--out", str(out), "--threads", "1", "--quiet"])
    assert rc == 1   # two images have no pose
    doc = json.loads((out / "measurements.json").read_text())
    assert doc["images_total"] == 8 and doc["images_with_pose"] == 6
    assert doc["failures"] == {"unreadable image": 2}
    assert doc["sequence"]["ok"] and doc["sequence"]["frames"] == 6
    recs = _poses(doc)
    assert recs["broken"]["reason"].endswith("not a PNG, JPEG, TIFF or BMP file (its first bytes are b'not a pn')")
    assert all(r.get("self_calibrated") == "sequence" for r in doc["images"] if r["ok"])
    assert len(list((out / "overlays").glob("*.png"))) == 6


def _raw_mosaic(png, black: int = 64, white: int = 4095):
    """A camera's raw frame of an 8-bit sRGB image: linear, RGGB mosaic, 12-bit DN above ``black``."""
    from dockfactory.core.camera_chain.cfa import mosaic
    x = cv2.cvtColor(cv2.imread(str(png)), cv2.COLOR_BGR2RGB) / 255.0
    lin = np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)
    return np.rint(black + mosaic(lin, "RGGB") * (white - black)).astype(np.uint16)


@pytest.mark.slow   # the detector on 3 images, three times
def test_raw_frames_are_developed_and_measured(big, tmp_path, capsys):
    """One-channel 16-bit PNGs are raw mosaics: with --cfa they are developed (black level, grey
    world, demosaic, sRGB) and measured, the centres fitted on the sensor's own samples; their
    poses agree with the 8-bit images' within 4 of their reported standard deviations (the mosaic
    keeps a quarter of each colour's samples). Without --cfa each raw frame is
    reported (unreadable, with the reason), never dropped; so is one without --raw-white (a PNG does
    not say its ADC depth)."""
    raw_dir = tmp_path / "raw"
    raw_dir.mkdir()
    images = sorted((big / "images").glob("*.png"))[:3]
    for p in images:
        cv2.imwrite(str(raw_dir / p.name), _raw_mosaic(p))
    ref, out, bare = tmp_path / "ref", tmp_path / "out", tmp_path / "bare"
    common = ["--layout", str(big / "layout.json"), "--workers", "1", "--threads", "1", "--overlay-size", "0",
              "--quiet"]
    assert main(["measure", *map(str, images), "--out", str(ref), *common]) == 0
    assert main(["measure", str(raw_dir), "--cfa", "RGGB", "--raw-black", "64", "--raw-white", "4095", "--out",
                 str(out), *common]) == 0
    doc, ref_doc = json.loads((out / "measurements.json").read_text()), json.loads((ref / "measurements.json").read_text())
    assert doc["camera"]["cfa"] == "RGGB" and doc["camera"]["raw_black_dn"] == 64
    for fid, rec in _poses(ref_doc).items():
        got = _poses(doc)[fid]
        # the same markers identified; the goodness-of-fit gate may leave one or two out of either
        # (the painted frames' centre noise is near the shipped card's limit)
        ids = [set(r["marker_ids"]) | set(r.get("left_out") or ()) for r in (got, rec)]
        assert got["ok"] and ids[0] == ids[1]
        assert got["camera_class"] == "bayer" and rec["camera_class"] == "three-chip"   # the gate's second test
        for k in ("x_mm", "y_mm", "alpha_deg"):
            i = POSE_NAMES.index(k)
            std = np.hypot(*(np.sqrt(np.asarray(r["covariance"])[i, i]) for r in (got, rec)))
            assert abs(got["pose"][k] - rec["pose"][k]) < 4 * std, (fid, k, got["pose"][k], rec["pose"][k], std)
    assert main(["measure", str(raw_dir), "--out", str(bare), *common]) == 1
    recs = json.loads((bare / "measurements.json").read_text())["images"]
    assert len(recs) == 3 and all("give its Bayer pattern with --cfa" in r["reason"] for r in recs)
    assert main(["measure", str(raw_dir), "--cfa", "RGGB", "--out", str(bare), *common]) == 1
    recs = json.loads((bare / "measurements.json").read_text())["images"]
    assert len(recs) == 3 and all("white level with --raw-white" in r["reason"] for r in recs)
