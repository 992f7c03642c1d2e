"""measure's joint solves keep each frame's camera class: ``--self-calibrate sequence``
(dockfactory.measure.images.self_calibrate_sequence) and a stream's window
(dockfactory.measure.selfcal.WindowCalibration) replace a frame's record by the run's, which keeps
its ``camera_class`` (and the frame's ``notes``), and the run gate judges the run at that class's
noise (eval.fit_gate.run_misfits).

The frames are synthetic far frames of one docking run (solver.synthetic.docking_run, scene B's
geometry) whose centres carry a Bayer + JPEG camera's noise (7.9x the card), each solved alone as
measure solves an image of that class (eval.solve_frames.solve_frame with the class's factor and
section shift), no detector."""
from pathlib import Path

import numpy as np
import pytest
from disc_noise_draws import disc_noise

from dockfactory.core.layout import DEFAULT_LAYOUT_A, DEFAULT_LAYOUT_B, build_layout
from dockfactory.eval.camera_classes import CAMERA_CLASS_FACTORS, class_section_shift
from dockfactory.eval.solve_frames import UNCALIBRATED_LENS, docking_options, solve_frame
from dockfactory.measure.images import Frame, self_calibrate_sequence
from dockfactory.measure.selfcal import WindowCalibration
from dockfactory.solver.synthetic import IMAGE_SIZE, docking_run

CARD = 0.0098
BAYER_JPEG = "bayer-jpeg"
LAYOUT = build_layout(DEFAULT_LAYOUT_A, DEFAULT_LAYOUT_B, 450.0, 30.0)
FAR = dict(radius_mm=450.0, distance_range=(2000.0, 2500.0), focal_range=(2000.0, 3600.0))


def _options(cls: str):
    return docking_options(CARD, UNCALIBRATED_LENS, class_section_shift(cls, None))


def _frames(cls: str, seed: int = 0, n: int = 6) -> list[Frame]:
    """measure's Frames of a run's images whose centres carry camera class ``cls``'s noise (its
    factor times the card), each solved alone (pinhole) as measure solves an image of that class."""
    run = docking_run(np.random.default_rng(seed), n, markers=LAYOUT, **FAR)
    pp = ((IMAGE_SIZE[0] - 1) / 2.0, (IMAGE_SIZE[1] - 1) / 2.0)
    out = []
    for k, sc in enumerate(run.frames):
        uv = np.vstack([sc.uv_a, sc.uv_b])
        uv = uv + disc_noise(sc, LAYOUT, CAMERA_CLASS_FACTORS[cls] * CARD, np.random.default_rng(100 * seed + k))
        ids = np.r_[np.zeros(len(sc.uv_a), int), np.ones(len(sc.uv_b), int)]
        record, used = solve_frame(LAYOUT, pp, (ids, uv, None, None), None, "pinhole", _options(cls),
                                   CAMERA_CLASS_FACTORS[cls])
        record.update(camera_class=cls, image_size=list(IMAGE_SIZE), timing_ms={"detect": 1.0, "solve": 1.0})
        out.append(Frame(k, Path(f"{k:03d}.png"), record, principal_point=pp, used_points=used))
    return out


@pytest.mark.parametrize("cls", ["three-chip", BAYER_JPEG])
def test_a_sequence_runs_records_keep_their_class_and_pass_at_its_noise(cls):
    frames = _frames(cls)
    alone = [f for f in frames if f.record["ok"]]
    assert len(alone) >= 5
    run = self_calibrate_sequence(frames, LAYOUT, "auto", CARD, None, class_section_shift(cls, None))
    assert all(f.record["camera_class"] == cls for f in frames)
    assert run["ok"] and run["frames"] == len(alone)
    for f in alone:
        r = f.record
        assert r["ok"] and r["self_calibrated"] == "sequence", r.get("reason")
        if cls == BAYER_JPEG:
            assert r["fit_test"]["camera_class_factor"] == CAMERA_CLASS_FACTORS[cls]
            assert r["fit_test"]["card"]["ratio"] > 3                    # the card alone refuses it


@pytest.mark.parametrize("cls", ["three-chip", BAYER_JPEG])
def test_a_streams_window_keeps_the_frames_class_and_judges_it_at_its_noise(cls):
    window = WindowCalibration(tuple(LAYOUT), 6, "auto", options=_options(cls))
    joint = [window.apply(f.index, f) for f in _frames(cls) if f.record["ok"]][2:]   # from the third
    assert joint and all(r.get("self_calibrated") == "window" and r["ok"] for r in joint), \
        [r.get("self_calibration") for r in joint]
    assert all(r["camera_class"] == cls for r in joint)
    if cls == BAYER_JPEG:
        assert all(r["fit_test"]["camera_class_factor"] == CAMERA_CLASS_FACTORS[cls] for r in joint)


NOTES = ["UserWarning: a decoder's message"]


def test_a_sequence_runs_records_keep_each_frames_notes():
    """``--self-calibrate sequence`` replaces a frame's record by the run's: the frame's ``notes``
    (the decoder's messages and the warnings raised measuring it) stay in it, as its size, timings
    and class do (before: dropped)."""
    frames = _frames("three-chip")
    for f in frames[::2]:
        f.record["notes"] = list(NOTES)
    run = self_calibrate_sequence(frames, LAYOUT, "auto", CARD, None, None)
    assert run["ok"] and all(f.record["self_calibrated"] == "sequence" for f in frames)
    assert [f.record.get("notes") for f in frames] == [NOTES if k % 2 == 0 else None for k in range(len(frames))]
    assert all(f.record["image_size"] == list(IMAGE_SIZE) for f in frames)


def test_a_streams_joint_records_keep_each_frames_notes():
    """A stream's window and frozen-intrinsics records keep the frame's own ``notes`` too."""
    window = WindowCalibration(tuple(LAYOUT), 6, "auto", freeze_after=2, options=_options("three-chip"))
    records = []
    for f in _frames("three-chip"):
        f.record["notes"] = list(NOTES)
        records.append(window.apply(f.index, f))
    kinds = [r.get("self_calibrated") for r in records]
    assert "window" in kinds and "frozen" in kinds, kinds
    assert all(r["notes"] == NOTES for r in records)
