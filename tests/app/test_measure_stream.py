"""measure on a stream (--video, --camera) and the docking-run video export it reads.

A painted docking run (tests/pipeline_data.py: 4 frames of 1280 x 960, one camera unit, no
Blender) is exported as video (`dataset export --format video,video_lossless`) and measured back:
the lossless video (FFV1) gives measure's own poses on the PNGs to 1e-9 (the decoded pixels are the
PNGs'), the MP4 (mp4v, 4:2:0 chroma) poses within 3 mm / 0.1 deg of the labels. The camera path is
tested with a file-backed device: ``measure_stream.camera_source`` maps the index to the PNGs'
image-sequence pattern, which VideoCapture opens like a device."""
import json

import cv2
import numpy as np
import pytest

from cli_run import one_line_error, run_cli
from dockfactory.measure import stream as measure_stream
from dockfactory.measure.kalman import PoseKalman

CONFIG = """
[dataset]
name = "stream-test"
seed = 5
frames = 4
train_fraction = 0.0

[conditions]
normal = 1

[repeatability]
poses = 1
captures = 1

[image]
width = 1280
height = 960

[runs]
frames_per_run = 4

[render]
keep_exr = false
"""


@pytest.fixture(scope="module")
def run_ds(tmp_path_factory):
    from pipeline_data import painted_from_text
    return painted_from_text(tmp_path_factory, "stream", CONFIG)


@pytest.fixture(scope="module")
def videos(run_ds):
    from dockfactory.cli import main
    assert main(["dataset", "export", str(run_ds), "--format", "video,video_lossless"]) == 0
    return run_ds / "exports"


def _lines(path):
    return [json.loads(ln) for ln in path.read_text().splitlines()]


def _stream(args, capsys, tmp_path, name="s.jsonl"):
    out = tmp_path / name
    code, _, err = run_cli(["measure", *args, "--jsonl", out, "--threads", "1", "--backend", "torch"], capsys)
    return code, (_lines(out) if out.exists() else None), err


def test_video_export_writes_each_run_with_its_labels(run_ds, videos):
    index = json.loads((videos / "video" / "videos.json").read_text())
    assert (index["codec"], index["lossy"], len(index["runs"])) == ("mp4v", True, 1)
    run = index["runs"][0]
    labels = _lines(videos / "video" / run["labels"])
    assert [ln["frame"] for ln in labels] == [0, 1, 2, 3] == [ln["run_frame"] for ln in labels]
    assert [ln["frame_id"] for ln in labels] == ["000000", "000001", "000002", "000003"]
    truth = json.loads((run_ds / "labels" / "000002.json").read_text())
    assert labels[2]["pose"] == truth["pose_b_in_d"] and labels[2]["timestamp_ms"] == 200.0
    for fmt, suffix in (("video", ".mp4"), ("video_lossless", ".mkv")):
        cap = cv2.VideoCapture(str(videos / fmt / f"unit0_run00{suffix}"))
        frames = []
        while (got := cap.read())[0]:
            frames.append(got[1])
        assert len(frames) == 4 and frames[0].shape == (960, 1280, 3)
        png = cv2.imread(str(run_ds / "images" / "000001.png"))
        diff = np.abs(frames[1].astype(int) - png)
        assert (diff.max() == 0) if fmt == "video_lossless" else (diff.mean() < 8), (fmt, diff.mean())


def test_a_dataset_without_runs_has_no_video(painted, capsys):
    code, _, err = run_cli(["dataset", "export", painted, "--format", "video"], capsys)
    assert code == 2 and "no docking runs" in one_line_error(err)
    assert not (painted / "exports" / "video").exists()


@pytest.mark.slow   # the detector on 4 frames of 1280 x 960, four times
def test_video_measured_back_against_labels_and_measure(run_ds, videos, tmp_path, capsys):
    layout = run_ds / "layout.json"
    code, lossless, _ = _stream(["--video", videos / "video_lossless" / "unit0_run00.mkv", "--layout", layout],
                                capsys, tmp_path, "lossless.jsonl")
    assert code == 0
    code, mp4, err = _stream(["--video", videos / "video" / "unit0_run00.mp4", "--layout", layout,
                              "--filter", "kalman"], capsys, tmp_path, "mp4.jsonl")
    assert code == 0 and "4 of 4 frames with a pose" in err
    code, windowed, _ = _stream(["--video", videos / "video_lossless" / "unit0_run00.mkv", "--layout", layout,
                                 "--roi", "3"], capsys, tmp_path, "roi.jsonl")
    assert code == 0 and windowed[0]["roi"] is None and windowed[1]["roi"] is not None
    for k in range(4):   # the window changes the network's input, not what it finds: within 1 mm / 0.05 deg
        assert abs(windowed[k]["pose"]["x_mm"] - lossless[k]["pose"]["x_mm"]) < 1.0
        assert abs(windowed[k]["pose"]["alpha_deg"] - lossless[k]["pose"]["alpha_deg"]) < 0.05
    images = [run_ds / "images" / f"00000{k}.png" for k in range(4)]
    assert run_cli(["measure", *images, "--layout", layout, "--out", tmp_path / "m", "--workers", "1",
                    "--threads", "1", "--backend", "torch", "--overlay-size", "0", "--quiet"], capsys)[0] == 0
    measured = json.loads((tmp_path / "m" / "measurements.json").read_text())["images"]
    labels = _lines(videos / "video" / "unit0_run00.jsonl")
    summary = mp4[-1]
    assert summary["type"] == "summary" and summary["frames"] == summary["frames_with_pose"] == 4
    assert (summary["chroma"], lossless[-1]["chroma"]) == ("subsampled", "full")   # the edge fitted on the luma
    assert summary["latency_ms"]["p95"] >= summary["latency_ms"]["p50"] > 0
    for k in range(4):
        raw, ref, truth = lossless[k], measured[k], labels[k]["pose"]
        assert raw["frame"] == k and raw["timestamp_ms"] == pytest.approx(100.0 * k)
        assert max(abs(raw["pose"][n] - v) for n, v in ref["pose"].items()) < 1e-9   # measure's own path
        assert raw["focal_px"] == pytest.approx(ref["focal_px"], abs=1e-6)
        assert set(raw["timing_ms"]) == {"read", "detect", "solve", "total"} and raw["std"]["x_mm"] > 0
        line = mp4[k]
        assert abs(line["pose"]["x_mm"] - truth["x_mm"]) < 3 and abs(line["pose"]["y_mm"] - truth["y_mm"]) < 3
        assert abs(line["pose"]["alpha_deg"] - truth["alpha_deg"]) < 0.1
        assert set(line["filtered"]) >= {"x_mm", "y_mm", "alpha_deg"} and "pose" in line   # raw kept beside


@pytest.mark.slow   # the detector on 4 frames, twice, and two worker processes loading it
def test_two_worker_processes_give_the_same_lines_in_order(run_ds, videos, tmp_path, capsys):
    """--workers 2: the frames measured by two processes come back in frame order with the poses
    of one process to 1e-9; the display filter still runs in frame order in the parent."""
    args = ["--video", videos / "video_lossless" / "unit0_run00.mkv", "--layout", run_ds / "layout.json",
            "--filter", "kalman"]
    code, one, _ = _stream(args, capsys, tmp_path, "one.jsonl")
    code2, two, err = _stream([*args, "--workers", "2"], capsys, tmp_path, "two.jsonl")
    assert code == code2 == 0 and "4 of 4 frames with a pose" in err
    assert [ln["frame"] for ln in two[:-1]] == [0, 1, 2, 3]
    assert two[-1]["workers"] == 2 and one[-1]["workers"] == 1 and two[-1]["backend"] == "torch"
    assert two[-1]["prefetch"] == 0 and one[-1]["prefetch"] == 1   # the workers overlap the reads
    for a, b in zip(one[:-1], two[:-1]):
        assert max(abs(a["pose"][n] - b["pose"][n]) for n in a["pose"]) < 1e-9
        assert max(abs(a["filtered"][n] - b["filtered"][n]) for n in ("x_mm", "y_mm", "alpha_deg")) < 1e-9


@pytest.mark.slow   # the detector on 2 frames
def test_camera_path_on_a_file_backed_device(run_ds, tmp_path, capsys, monkeypatch):
    """--camera INDEX through VideoCapture, the index mapped to an image-sequence pattern; an
    acceptance hook's answer lands in each line (the decision itself lives in eval/)."""
    monkeypatch.setattr(measure_stream, "camera_source", lambda index: str(run_ds / "images" / "%06d.png"))
    code, lines, _ = _stream(["--camera", "0", "--layout", run_ds / "layout.json", "--max-frames", "2"],
                             capsys, tmp_path)
    assert code == 0 and [ln["type"] for ln in lines] == ["frame", "frame", "summary"]
    assert lines[-1]["source"] == "--camera 0" and lines[-1]["frames_with_pose"] == 2
    out = tmp_path / "hook.jsonl"
    summary = measure_stream.measure_stream(run_ds / "layout.json", _weights(), str(out), camera=0,
                                            options=measure_stream.StreamOptions(backend="torch", max_frames=1),
                                            decide=lambda line: "IN" if line["ok"] else "UNDECIDED")
    assert summary["acceptance"] and _lines(out)[0]["acceptance"] == "IN"


def _weights():
    from dockfactory.core.resources import shipped_weights
    return shipped_weights()


def test_stream_refusals_are_one_line_exit_2(run_ds, tmp_path, capsys, monkeypatch):
    layout = run_ds / "layout.json"
    empty = tmp_path / "empty.mp4"
    empty.write_bytes(b"")
    monkeypatch.setattr(measure_stream, "camera_source", lambda index: str(tmp_path / "no_device_%d.png"))
    cases = [(["--camera", "3"], "--camera 3: OpenCV's VideoCapture cannot open it"),
             (["--video", tmp_path / "missing.mp4"], "no such video file"),
             (["--video", empty], "cannot open it"),
             (["--video", empty, run_ds / "images"], "not both"),
             ([], "give images"),
             (["--video", empty, "--out", tmp_path / "o"], "a stream writes JSON lines"),
             (["--video", empty, "--self-calibrate", "sequence"], "a stream self-calibrates over a sliding window"),
             (["--video", empty, "--workers", "2", "--roi", "3"], "not with --roi"),
             (["--video", empty, "--workers", "17"], "expected 1 to 16 for a stream")]
    for args, words in cases:
        code, lines, err = _stream([*args, "--layout", layout], capsys, tmp_path)
        assert code == 2 and words in one_line_error(err), (args, err)
        assert lines is None, args   # nothing written
    code, _, err = run_cli(["measure", run_ds / "images", "--layout", layout, "--out", tmp_path / "o",
                            "--jsonl", "-"], capsys)
    assert code == 2 and "apply to a stream" in one_line_error(err)
    code, _, err = run_cli(["measure", "--video", empty, "--layout", layout, "--jsonl", tmp_path], capsys)
    assert code == 2 and "not a file in an existing folder" in one_line_error(err)


def test_a_real_camera_index_that_does_not_exist(run_ds, tmp_path, capsys):
    """No capture device 63 exists here (nor on CI): one line, exit 2, nothing written."""
    code, lines, err = _stream(["--camera", "63", "--layout", run_ds / "layout.json"], capsys, tmp_path)
    assert code == 2 and "--camera 63" in one_line_error(err) and lines is None


def test_kalman_smooths_a_constant_velocity_run_and_skips_gaps():
    """Noisy X, Y, alpha of B moving at constant rates (sigma 0.5 mm, 0.02 deg, 10 frames/s), with
    a process noise that trusts the constant velocity: the filtered track's RMSE over the last 30
    of 60 frames is under 0.6 of the raw one's, its rates within 10 % of the truth; a frame without
    a pose only predicts."""
    rng = np.random.default_rng(3)
    kf, raw_err, filt_err = PoseKalman({"x_mm": 0.01, "y_mm": 0.01, "alpha_deg": 1e-6}), [], []
    std = {"x_mm": 0.5, "y_mm": 0.5, "alpha_deg": 0.02}
    for k in range(60):
        t = 0.1 * k
        truth = {"x_mm": 150.0 - 20.0 * t, "y_mm": 3.0 + 1.0 * t, "alpha_deg": 0.5 - 0.05 * t}
        meas = {n: v + rng.normal(0.0, std[n]) for n, v in truth.items()}
        out = kf.step(t, None if k == 40 else meas, std)
        if k >= 30:
            raw_err.append([(meas[n] - truth[n]) / std[n] for n in truth])
            filt_err.append([(out[n] - truth[n]) / std[n] for n in truth])
    assert np.sqrt(np.mean(np.square(filt_err))) < 0.6 * np.sqrt(np.mean(np.square(raw_err)))
    assert out["rate_x_mm_per_s"] == pytest.approx(-20.0, rel=0.1)
    assert out["rate_alpha_deg_per_s"] == pytest.approx(-0.05, rel=0.1)
    assert PoseKalman().step(0.0, None, None) is None
    with pytest.raises(ValueError, match="backwards"):
        kf.step(1.0, None, None)


def test_roi_tracker_windows_the_markers_and_falls_back_to_full_frames():
    """The window holds every box of the last frame with its margin, keeps one size between full
    frames (one network input shape), has even corners, stays inside the image; a full frame comes
    every ``refresh`` frames, after a frame without detections, and when a marker is lost."""
    from dockfactory.measure.roi import RoiTracker
    boxes = [[500.0, 400.0, 530.0, 430.0], [700.0, 420.0, 731.0, 451.0], [610.0, 500.0, 640.0, 530.0]]
    dets = [{"bbox_px": b, "score": 0.9} for b in boxes]
    t = RoiTracker(1280, 960, refresh=3, min_score=0.25)
    assert t.region() is None   # nothing seen yet
    t.update(dets, None)
    roi = t.region()
    assert roi is not None and roi[0] % 2 == 0 and roi[1] % 2 == 0
    assert all(roi[0] < b[0] and roi[1] < b[1] and b[2] < roi[2] and b[3] < roi[3] for b in boxes)
    assert (roi[2] - roi[0]) % 64 == 0 and (roi[3] - roi[1]) % 64 == 0
    moved = [{"bbox_px": [b[0] + 40, b[1] - 20, b[2] + 40, b[3] - 20], "score": 0.9} for b in boxes]
    assert not t.lost(moved, roi)
    t.update(moved, roi)
    roi2 = t.region()
    assert roi2 is not None and (roi2[2] - roi2[0], roi2[3] - roi2[1]) == (roi[2] - roi[0], roi[3] - roi[1])
    assert t.lost(moved[:2], roi2)   # a marker fewer than the full frame saw
    t.update(moved, roi2)
    assert t.region() is None        # the third frame since the full one: refresh
    corner = RoiTracker(1280, 960, refresh=10)
    corner.update([{"bbox_px": [2.0, 900.0, 40.0, 955.0]}], None)
    x0, y0, x1, y1 = corner.region()
    assert 0 <= x0 and y1 <= 960 and x1 - x0 >= 38
    corner.update([], (x0, y0, x1, y1))
    assert corner.region() is None


@pytest.mark.slow   # the detector on 4 frames
def test_online_self_calibration_over_a_window_then_frozen(run_ds, videos, tmp_path, capsys):
    """--self-calibrate window:3 --freeze-after 1 on the painted run (an ideal pinhole camera):
    frames 0 and 1 are solved alone (the window is warming up), frame 2 jointly with 0 and 1
    (shared intrinsics: the principal point found at the image centre within 2 px), frame 3 with
    those intrinsics frozen; every pose within 1 mm / 0.05 deg of the labels."""
    code, lines, _ = _stream(["--video", videos / "video_lossless" / "unit0_run00.mkv", "--layout",
                              run_ds / "layout.json", "--self-calibrate", "window:3", "--freeze-after", "1"],
                             capsys, tmp_path)
    assert code == 0
    labels = _lines(videos / "video" / "unit0_run00.jsonl")
    assert "solved alone" in lines[0]["self_calibration"] and "solved alone" in lines[1]["self_calibration"]
    assert (lines[2]["self_calibrated"], lines[2]["run_frames"]) == ("window", 3)
    assert abs(lines[2]["intrinsics"]["cx"] - 639.5) < 2 and abs(lines[2]["intrinsics"]["cy"] - 479.5) < 2
    assert lines[3]["self_calibrated"] == "frozen"
    assert lines[3]["frozen_intrinsics"]["cx"] == lines[2]["intrinsics"]["cx"]
    for line, truth in zip(lines[:4], labels):
        assert abs(line["pose"]["x_mm"] - truth["pose"]["x_mm"]) < 1.0
        assert abs(line["pose"]["alpha_deg"] - truth["pose"]["alpha_deg"]) < 0.05
    assert lines[-1]["self_calibrate"] == "window:3" and lines[-1]["freeze_after"] == 1


def test_self_calibration_flags_are_checked(run_ds, videos, tmp_path, capsys):
    layout = run_ds / "layout.json"
    video = videos / "video_lossless" / "unit0_run00.mkv"
    for args, words in ((["--video", video, "--self-calibrate", "sequence"], "a stream self-calibrates over"),
                        (["--video", video, "--freeze-after", "2"], "needs --self-calibrate window:N"),
                        ([run_ds / "images", "--self-calibrate", "window:4", "--out", tmp_path / "o"],
                         "for a stream"),
                        ):
        code, _, err = run_cli(["measure", *args, "--layout", layout], capsys)
        assert code == 2 and words in one_line_error(err), (args, err)
    code, _, err = run_cli(["measure", "--video", video, "--self-calibrate", "window:1", "--layout", layout], capsys)
    assert code == 2 and "window:N with N in [2, 200]" in err.strip().splitlines()[-1]   # argparse: usage + error


@pytest.mark.slow   # the detector on 2 frames
def test_a_stream_judged_against_an_acceptance_spec(run_ds, tmp_path, capsys):
    """--acceptance SPEC on a stream: every line carries eval.conformity's decision of its pose
    (per gated component value, U = 2 u and the decision, the worst as the line's); a spec with
    wide tolerances says IN, one tighter than the guard band UNDECIDED; a bad spec is one line,
    exit 2, before the video is opened."""
    video = run_ds / "images" / "%06d.png"
    wide, tight = tmp_path / "wide.toml", tmp_path / "tight.toml"
    wide.write_text("[localization]\nx = 1000.0\ny = 1000.0\nalpha = 90.0\n")
    tight.write_text("[localization]\nx = 1e-6\n")
    for spec, want in ((wide, "IN"), (tight, None)):
        code, lines, _ = _stream(["--video", video, "--layout", run_ds / "layout.json", "--max-frames", "2",
                                  "--acceptance", spec], capsys, tmp_path, f"{spec.stem}.jsonl")
        assert code == 0
        for line in lines[:-1]:
            acc = line["acceptance"]
            x = acc["components"]["x_mm"]
            assert x["U"] == pytest.approx(2.0 * line["std"]["x_mm"]) and x["value"] == line["pose"]["x_mm"]
            if want == "IN":
                assert acc["decision"] == "IN" and set(acc["components"]) == {"x_mm", "y_mm", "alpha_deg"}
            else:   # |x| within 1e-6 mm is beyond any pose here: OUT unless the band covers it
                assert acc["decision"] == ("OUT" if abs(x["value"]) - x["U"] > 1e-6 else "UNDECIDED")
    bad = tmp_path / "bad.toml"
    bad.write_text("[localization]\n")
    code, _, err = run_cli(["measure", "--video", video, "--layout", run_ds / "layout.json",
                            "--acceptance", bad, "--jsonl", tmp_path / "bad.jsonl"], capsys)
    assert code == 2 and "[localization]" in one_line_error(err) and not (tmp_path / "bad.jsonl").exists()


def test_a_sequence_frame_of_another_size_is_refused_in_one_line_and_the_others_read(tmp_path):
    """An image sequence whose third frame is smaller: OpenCV decodes it at the first frame's
    size (garbled); the reader refuses it by its file header, in one line, and goes on."""
    seq = tmp_path / "seq"
    seq.mkdir()
    rng = np.random.default_rng(3)
    for i, (w, h) in enumerate(((320, 240), (320, 240), (200, 150), (320, 240))):
        cv2.imwrite(str(seq / f"{i + 1:06d}.png"), rng.integers(0, 255, (h, w, 3), dtype=np.uint8))
    check = measure_stream.sequence_frame_check(seq / "%06d.png")
    cap, _ = measure_stream.open_capture(video=seq / "%06d.png")
    items = list(measure_stream.FrameReader(cap, prefetch=0, check=check))
    assert [type(it[4]).__name__ for it in items] == ["ndarray", "ndarray", "str", "ndarray"]
    assert items[2][4] == (f"{seq / '000003.png'}: 200x150, the sequence's frames are 320x240 (its first, "
                           f"{seq / '000001.png'}): refused, OpenCV would decode it garbled at the first frame's size")
    measurer = measure_stream.StreamMeasurer(None, (), measure_stream.StreamOptions())
    record = measurer.solve(2, items[2][4])
    assert record["ok"] is False and record["category"] == "frame size" and record["reason"].startswith("frame 2: ")
    assert measure_stream.sequence_frame_check(tmp_path / "video.mp4") is None


def test_a_jsonl_file_another_stream_writes_is_refused_and_left_whole(tmp_path):
    """Two streams into one ``--jsonl`` file: the second is refused in one line (at once when the
    file is already held, else at its first line) and the first's lines stay whole (before:
    the second truncated the file under the first and their lines interleaved)."""
    path = tmp_path / "lines.jsonl"
    first = measure_stream.LineSink(str(path))
    first.write({"frame": 0})
    with pytest.raises(measure_stream.DockfactoryError, match="lines.jsonl: another process is writing it"):
        measure_stream.LineSink(str(path))
    path.unlink()                                   # a file made after the second sink was checked ...
    first.close()
    first = measure_stream.LineSink(str(path))
    second = measure_stream.LineSink(str(path))
    first.write({"frame": 0})
    with pytest.raises(measure_stream.DockfactoryError, match="another process is writing it"):
        second.write({"frame": 99})                 # ... is refused at the second's first line
    first.write({"frame": 1})
    first.close()
    assert [json.loads(x)["frame"] for x in path.read_text().splitlines()] == [0, 1]
    again = measure_stream.LineSink(str(path))      # free again: a new stream empties and writes it
    again.write({"frame": 5})
    again.close()
    assert path.read_text() == '{"frame": 5}\n'


def test_stream_statistics_use_constant_memory_and_keep_percentiles_within_1_percent():
    """The summary's latency and timing percentiles come from log-spaced histograms: 200,000
    frames use the same memory as 10, and p50 / p95 are within 1 % of numpy's (max exact)."""
    stats = measure_stream.StreamStats()
    rng = np.random.default_rng(0)
    lat = rng.lognormal(np.log(40.0), 0.5, 200_000)
    for k, v in enumerate(lat):
        stats.add({"ok": k % 7 != 0, "category": "no_pose", "timing_ms": {"detect": v / 2}}, v)
        if k == 9:
            size = stats.latency_ms.bins.nbytes + stats.timing_ms["detect"].bins.nbytes
    assert stats.latency_ms.bins.nbytes + stats.timing_ms["detect"].bins.nbytes == size
    s = stats.summary(10.0)
    for q, key in ((50, "p50"), (95, "p95")):
        assert s["latency_ms"][key] == pytest.approx(np.percentile(lat, q), rel=0.01)
    assert s["latency_ms"]["max"] == pytest.approx(lat.max(), abs=0.005)
    assert s["timing_ms_median"]["detect"] == pytest.approx(np.median(lat) / 2, rel=0.01)
    assert s["frames"] == 200_000 and s["failures"] == {"no_pose": 28_572}
    with pytest.raises(ValueError, match=">= 0"):
        stats.latency_ms.add(float("nan"))


PAINTED_CARD_PX = 0.04   # px per axis: the painted frames' centres through the shipped weights


@pytest.mark.slow  # several seconds of solves or pages; the full suite runs it
def test_a_calibrated_camera_streamed_is_measured_as_its_images(tmp_path_factory, capsys):
    """The painted run rendered through a calibrated camera (principal point 15 / -10 px off, k1
    -0.08; [camera_units] calibration), exported lossless and streamed with --calibration: every
    frame's pose is measure's own on the PNGs with --calibration (to 1e-9) and within 3 mm / 0.1
    deg of its label. The painted frames are their own camera: through the shipped weights their
    centres leave residuals of 0.03-0.07 px, several times the shipped card (measured on Cycles
    renders), so both runs take the shipped weights with a card stating PAINTED_CARD_PX."""
    import shutil

    from pipeline_data import write_painted_dataset

    from dockfactory.core.calibration_files import Calibration, write_calibration
    from dockfactory.core.resources import shipped_weights
    from dockfactory.cli import main
    from dockfactory.detector.noise_card import noise_card_path
    root = tmp_path_factory.mktemp("calibrated-stream")
    weights = root / "painted.pt"
    shutil.copyfile(shipped_weights(), weights)
    card = json.loads(noise_card_path(shipped_weights()).read_text())
    noise_card_path(weights).write_text(json.dumps({**card, "centre_noise_px": PAINTED_CARD_PX}))
    write_calibration(Calibration(1280, 960, 1500.0, 1500.0, 654.5, 469.5, (-0.08, 0.02, 0.0, 0.0, 0.0)),
                      root / "cam.yaml", "opencv-yaml")
    (root / "c.toml").write_text(CONFIG + '\n[camera]\ndistance_mm = [1300, 1500]\n'
                                 '[camera_units]\ncalibration = "cam.yaml"\n')
    write_painted_dataset(root / "ds", root / "c.toml")
    assert main(["dataset", "export", str(root / "ds"), "--format", "video_lossless"]) == 0
    layout, cal = root / "ds" / "layout.json", root / "cam.yaml"
    code, lines, _ = _stream(["--video", root / "ds" / "exports" / "video_lossless" / "unit0_run00.mkv",
                              "--layout", layout, "--calibration", cal, "--weights", weights], capsys, root)
    assert code == 0
    images = [root / "ds" / "images" / f"00000{k}.png" for k in range(4)]
    assert run_cli(["measure", *images, "--layout", layout, "--calibration", cal, "--weights", weights,
                    "--out", root / "m", "--workers",
                    "1", "--threads", "1", "--backend", "torch", "--overlay-size", "0", "--quiet"], capsys)[0] == 0
    measured = json.loads((root / "m" / "measurements.json").read_text())["images"]
    labels = [json.loads((root / "ds" / "labels" / f"00000{k}.json").read_text())["pose_b_in_d"] for k in range(4)]
    for k in range(4):
        assert max(abs(lines[k]["pose"][n] - v) for n, v in measured[k]["pose"].items()) < 1e-9
        assert lines[k]["calibration"]["principal_point"] == [654.5, 469.5]
        pose = lines[k]["pose"]
        assert abs(pose["x_mm"] - labels[k]["x_mm"]) < 3 and abs(pose["y_mm"] - labels[k]["y_mm"]) < 3
        assert abs(lines[k]["pose"]["alpha_deg"] - labels[k]["alpha_deg"]) < 0.1


class _NoMarkers:
    """A detector that finds nothing (or raises ``error``): the stream's records without a solve."""
    centre_noise_px, section_shift_px = 0.0174, None

    def __init__(self, error: Exception | None = None):
        self.error = error

    def detect(self, image, cfa=None, jpeg=False):
        if self.error is not None:
            raise self.error
        return []


@pytest.mark.parametrize("cfa, jpeg, cls", [(None, False, "three-chip"), ("rggb", False, "bayer"),
                                            (None, True, "jpeg"), ("rggb", True, "bayer-jpeg")])
def test_every_stream_line_names_the_frames_camera_class(cfa, jpeg, cls):
    """Each frame line names its ``camera_class`` as measure's records do: the class of the
    stream's ``--cfa`` and chroma (eval.camera_classes.camera_class), for a frame without
    markers, one refused by the reader, one whose measurement raised, a worker's record that names
    none (a dead worker's) and a solved record's own (before: no line carried it)."""
    options = measure_stream.StreamOptions(cfa=cfa, jpeg=jpeg)
    image = np.zeros((48, 64, 3), np.uint8)

    def line(detector, rgb, record=None):
        measurer = measure_stream.StreamMeasurer(detector, (), options)
        return measurer.line((3, 0.0, 1.0, 100.0, rgb), record)

    assert line(_NoMarkers(), image)["category"] == "no markers detected"
    assert line(_NoMarkers(), image)["camera_class"] == cls
    assert line(None, "refused")["camera_class"] == cls
    failed = line(_NoMarkers(RuntimeError("boom")), image)
    assert failed["category"] == "measure error" and failed["camera_class"] == cls
    dead = {"ok": False, "category": "measure error", "reason": "frame 3: the worker died"}
    assert line(None, None, dead)["camera_class"] == cls
    solved = {"ok": True, "covariance": np.eye(6).tolist(), "pose": {}, "focal_px": 1500.0, "rmse_px": {},
              "n_detections": 0, "marker_ids": [], "camera_class": "bayer"}
    assert measure_stream.frame_line(3, 100.0, solved)["camera_class"] == "bayer"
