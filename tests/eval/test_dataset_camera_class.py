"""The camera class of a dataset's frames (eval.simulated_cameras.frame_camera_class) and what
solve / evaluate of a dataset do with it (eval.solve_frames): the class's factor in the gate and its
section shift in the pose, as measure does for an image of that class (eval.camera_classes).

The labels are the factory's own (``sample_frame`` and ``frame_labels``, no render) or a painted
smoke dataset (tests/pipeline_data.py); the gate's behaviour is tested on synthetic far frames whose
centres carry a Bayer + JPEG camera's noise (tests/eval/test_fit_gate.py's frames).
"""
import tomllib
from types import SimpleNamespace

import numpy as np
import pytest

from disc_noise_draws import disc_noise
from pipeline_data import painted_from_text

from dockfactory.core.config import config_from_dict
from dockfactory.core.layout import DEFAULT_LAYOUT_A, DEFAULT_LAYOUT_B, build_layout
from dockfactory.core.resources import shipped_config
from dockfactory.eval import solve_frames
from dockfactory.eval.camera_classes import CAMERA_CLASS_FACTORS, class_section_shift
from dockfactory.eval.simulated_cameras import frame_camera, frame_camera_class
from dockfactory.eval.solve_frames import UNCALIBRATED_LENS, solve_dataset
from dockfactory.generator.datasets.reader import Dataset
from dockfactory.generator.labels import frame_labels
from dockfactory.generator.random_draws import static_scene
from dockfactory.generator.sampler import frame_plan, sample_frame
from dockfactory.solver.synthetic import IMAGE_SIZE, docking_run, docking_scene

SMOKE = shipped_config("smoke").read_text()
BAYER = '\n[sensor]\npresets = ["imx273"]\ncfa = ["RGGB"]\n'
JPEG = "\n[camera_units]\njpeg = true\n"
BAYER_JPEG_TEXT = SMOKE + JPEG + BAYER


def _labels(text: str) -> tuple[object, list[dict]]:
    """(config, the label of every planned frame) of the config ``text``, sampled, not rendered."""
    cfg = config_from_dict(tomllib.loads(text))
    static = static_scene(cfg)
    return cfg, [frame_labels(sample_frame(cfg, spec), static, None, cfg.labels.visible_threshold)
                 for spec in frame_plan(cfg)]


@pytest.mark.parametrize("extra, cls", [("", "three-chip"), (BAYER, "bayer"), (JPEG, "jpeg"),
                                        (JPEG + BAYER, "bayer-jpeg")])
def test_every_frame_of_a_dataset_gets_its_configs_class(extra, cls):
    cfg, labels = _labels(SMOKE + extra)
    assert len(labels) >= 8 and {frame_camera_class(lab, cfg) for lab in labels} == {cls}


def test_the_class_is_the_frames_own_record_then_its_units():
    """Two units (a Bayer one and a three-chip preset, both JPEG) and ideal frames, which skip the
    sensor (no CFA) but not the JPEG: each frame's label says what its image went through; a label
    without those records (an older format) gets its unit's."""
    text = (SMOKE.replace("glare = 1\n", "glare = 1\nideal = 2\n") + "\n[camera_units]\ncount = 2\njpeg = true\n"
            '\n[sensor]\npresets = ["imx273"]\ncfa = ["RGGB", "none"]\n')
    cfg, labels = _labels(text)
    want = {(0, False): "bayer-jpeg", (1, False): "jpeg", (0, True): "jpeg", (1, True): "jpeg"}
    seen = set()
    for lab in labels:
        key = (lab["spec"]["unit"], lab["spec"]["condition"] == "ideal")
        seen.add(key)
        assert frame_camera_class(lab, cfg) == want[key], key
        bare = {"spec": lab["spec"], "camera": {k: v for k, v in lab["camera"].items() if k != "jpeg_quality"}}
        assert frame_camera(bare, cfg) == (("RGGB", True) if key[0] == 0 else (None, True))
    assert {(0, False), (1, False), (0, True)} <= seen


@pytest.fixture(scope="module")
def bayer_jpeg(tmp_path_factory):
    return Dataset.open(painted_from_text(tmp_path_factory, "bayer-jpeg", BAYER_JPEG_TEXT))


def _detections(ds, card_shift=None) -> dict:
    """Every fully visible marker at its exact centroid + 0.02 px, with a noise card."""
    rng = np.random.default_rng(5)
    frames = {fid: [{"class_id": m["class_id"], "score": 1.0,
                     "center_px": (np.array(m["outline_centroid_px"]) + rng.normal(0.0, 0.02, 2)).tolist()}
                    for m in ds.labels[fid]["markers"] if m.get("visibility") == 2]
              for fid in ds.frames(("test", "repeat"))}
    return {"centre_noise_px": 0.02, "frames": frames,
            **({} if card_shift is None else {"section_shift_px": list(card_shift)})}


def _recorded(monkeypatch, ds, **kwargs) -> tuple[dict, list]:
    """(poses, [(section shift, class factor) of each solve_frame call]) of solve_dataset."""
    calls, real = [], solve_frames.solve_frame

    def spy(markers, pp, centres, sigma, model, options, class_factor=1.0):
        calls.append((options.section_shift_px, class_factor))
        return real(markers, pp, centres, sigma, model, options, class_factor)
    monkeypatch.setattr(solve_frames, "solve_frame", spy)
    return solve_dataset(ds, **kwargs), calls


def test_a_bayer_jpeg_datasets_frames_are_solved_with_their_class(bayer_jpeg, monkeypatch):
    card = (0.002, 0.06)
    poses, calls = _recorded(monkeypatch, bayer_jpeg, detections=_detections(bayer_jpeg, card))
    assert len(calls) == len(poses["frames"]) >= 6
    assert all(r["camera_class"] == "bayer-jpeg" for r in poses["frames"].values())
    shift = class_section_shift("bayer-jpeg", card)
    assert shift[0] > card[0] and shift[1] == card[1]                       # per axis the larger
    assert all(c == (shift, CAMERA_CLASS_FACTORS["bayer-jpeg"]) for c in calls)
    given, calls = _recorded(monkeypatch, bayer_jpeg, detections=_detections(bayer_jpeg, card),
                             section_shift_px=(0.0, 0.0))
    assert all(c == ((0.0, 0.0), CAMERA_CLASS_FACTORS["bayer-jpeg"]) for c in calls)   # a given shift as given
    oracle, calls = _recorded(monkeypatch, bayer_jpeg, oracle_sigma_px=0.05)
    assert all(c == (None, 1.0) for c in calls)               # label centroids: no camera in them
    assert all(r["camera_class"] == "bayer-jpeg" for r in oracle["frames"].values())


def test_a_three_chip_datasets_frames_keep_the_card(painted_source, monkeypatch):
    ds = Dataset.open(painted_source)
    card = (0.002, 0.003)
    poses, calls = _recorded(monkeypatch, ds, detections=_detections(ds, card))
    assert calls and all(c == (card, 1.0) for c in calls)
    assert all(r["camera_class"] == "three-chip" for r in poses["frames"].values())


def test_a_docking_run_carries_its_classes_section_shift_and_factor(tmp_path_factory, monkeypatch):
    text = BAYER_JPEG_TEXT + "\n[runs]\nframes_per_run = 4\n"
    ds = Dataset.open(painted_from_text(tmp_path_factory, "bayer-jpeg-runs", text))
    runs, real = [], solve_frames.solve_run

    def spy(markers, pp, group, frames, used, sigma, model, options, class_factor=1.0):
        runs.append((options.section_shift_px, class_factor))
        return real(markers, pp, group, frames, used, sigma, model, options, class_factor)
    monkeypatch.setattr(solve_frames, "solve_run", spy)
    poses = solve_dataset(ds, detections=_detections(ds), self_calibrate="sequence")
    assert runs and all(r == (class_section_shift("bayer-jpeg", None), CAMERA_CLASS_FACTORS["bayer-jpeg"]) for r in runs)
    assert all(r["camera_class"] == "bayer-jpeg" for r in poses["frames"].values())


CARD = 0.0098   # a card like the shipped ones (test_fit_gate.SHIPPED_CARD)
FAR = dict(radius_mm=450.0, distance_range=(2000.0, 2500.0), focal_range=(2000.0, 3600.0))
FAR_LAYOUT = build_layout(DEFAULT_LAYOUT_A, DEFAULT_LAYOUT_B, 450.0, 30.0)


def _far_dataset(seeds, told: bool):
    """(an opened-dataset stand-in, its detections) of synthetic far frames (scene B's geometry)
    whose centres carry a Bayer + JPEG camera's noise (its class factor times CARD); their labels
    record a Bayer CFA and a JPEG when ``told``, else neither."""
    noise = CAMERA_CLASS_FACTORS["bayer-jpeg"] * CARD
    cfg = config_from_dict(tomllib.loads(f"[image]\nwidth = {IMAGE_SIZE[0]}\nheight = {IMAGE_SIZE[1]}\n"))
    labels, frames = {}, {}
    for s in seeds:
        sc = docking_scene(np.random.default_rng(s), markers=FAR_LAYOUT, **FAR)
        uv = np.vstack([sc.uv_a, sc.uv_b])
        uv = uv + noise * np.random.default_rng(s + 1000).standard_normal(uv.shape)
        cls = [0] * len(sc.uv_a) + [1] * len(sc.uv_b)
        labels[f"{s:06d}"] = {"spec": {"unit": 0}, "camera": {"jpeg_quality": 90 if told else None},
                              "sampled": {"sensor": {"chain": {"cfa": "RGGB"}} if told else {}}}
        frames[f"{s:06d}"] = [{"class_id": c, "score": 1.0, "center_px": p.tolist()} for c, p in zip(cls, uv)]
    ds = SimpleNamespace(config=cfg, labels=labels, markers=lambda: FAR_LAYOUT, frames=lambda splits: list(labels),
                         version_id="synthetic", root="synthetic")
    return ds, {"centre_noise_px": CARD, "frames": frames}


def test_told_the_class_frames_the_card_refuses_pass_whole():
    """Frames the card alone strips (seed 0) or refuses (7, 10): told the class by their labels,
    they pass whole, the class's test noted, and their poses carry the class's section shift."""
    seeds = (0, 7, 10)
    recs = {}
    for told in (False, True):
        ds, dets = _far_dataset(seeds, told)
        recs[told] = solve_dataset(ds, ("test",), detections=dets, lens=UNCALIBRATED_LENS)["frames"]
    assert all(not r["ok"] or r.get("left_out") for r in recs[False].values())
    assert all(r["camera_class"] == "three-chip" and "section_shift_variance" not in r for r in recs[False].values())
    for r in recs[True].values():
        assert r["ok"] and not r.get("left_out") and r["camera_class"] == "bayer-jpeg", r.get("reason")
        assert r["fit_test"]["camera_class_factor"] == CAMERA_CLASS_FACTORS["bayer-jpeg"]
        assert r["fit_test"]["card"]["ratio"] > 3 and "section_shift_variance" in r


def _far_run(seed: int, zoomed: float = 1.0):
    """(an opened-dataset stand-in with one docking run of 6 frames, its detections): synthetic far
    frames of one fixed camera whose centres carry a Bayer + JPEG camera's noise, their labels
    telling the class; frame 000004's centres scaled by ``zoomed`` about the principal point (its
    zoom changed: not the run's camera)."""
    noise = CAMERA_CLASS_FACTORS["bayer-jpeg"] * CARD
    cfg = config_from_dict(tomllib.loads(f"[image]\nwidth = {IMAGE_SIZE[0]}\nheight = {IMAGE_SIZE[1]}\n"
                                         "[runs]\nframes_per_run = 6\n"))
    run = docking_run(np.random.default_rng(seed), 6, markers=FAR_LAYOUT, **FAR)
    labels, frames = {}, {}
    for k, sc in enumerate(run.frames):
        uv = np.vstack([sc.uv_a, sc.uv_b]) + disc_noise(sc, FAR_LAYOUT, noise, np.random.default_rng(100 * seed + k))
        if k == 4:
            uv = sc.principal_point + zoomed * (uv - sc.principal_point)
        fid = f"{k:06d}"
        labels[fid] = {"spec": {"unit": 0, "run": 0}, "camera": {"jpeg_quality": 90},
                       "sampled": {"sensor": {"chain": {"cfa": "RGGB"}}}}
        frames[fid] = [{"class_id": int(i >= len(sc.uv_a)), "score": 1.0, "center_px": p.tolist()}
                       for i, p in enumerate(uv)]
    ds = SimpleNamespace(config=cfg, labels=labels, markers=lambda: FAR_LAYOUT, frames=lambda splits: list(labels),
                         version_id="synthetic", root="synthetic")
    return ds, {"centre_noise_px": CARD, "frames": frames}


def test_a_runs_frames_at_their_classs_noise_pass_the_run_gate_and_another_camera_still_fails():
    """A docking run whose centres carry a Bayer + JPEG camera's noise (7.9x the card): the frames
    the frame gate passed (told their class) also pass the run gate, at the class's noise where the
    card alone refuses them (residuals over 3x it); a frame whose zoom changed by 1 % is still left
    out of its run."""
    for seed in (0, 1):
        ds, dets = _far_run(seed)
        frames = solve_dataset(ds, ("test",), detections=dets, lens=UNCALIBRATED_LENS, camera_model="auto",
                               self_calibrate="sequence")["frames"]
        joint = [r for r in frames.values() if r.get("self_calibrated") == "sequence"]
        assert len(joint) >= 5 and all(r["camera_class"] == "bayer-jpeg" for r in frames.values())
        for r in joint:
            assert r["ok"], r.get("reason")
            assert r["fit_test"]["camera_class_factor"] == CAMERA_CLASS_FACTORS["bayer-jpeg"]
            assert r["fit_test"]["card"]["ratio"] > 3 and r["run_frames"] == len(joint)
        ds, dets = _far_run(seed, zoomed=1.01)
        frames = solve_dataset(ds, ("test",), detections=dets, lens=UNCALIBRATED_LENS, camera_model="auto",
                               self_calibrate="sequence")["frames"]
        assert not frames["000004"]["ok"] and frames["000004"]["reason"].startswith("docking run solve: residuals")
        assert sum(r["ok"] for r in frames.values()) == len(joint) - 1
