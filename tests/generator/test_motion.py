"""[motion]: B moving during the exposure (generator/motion.py, docs/motion.md). Pure numpy.

- configs: defaults off, one-line errors naming the file, [motion] and the key;
- a config without [motion] samples and labels the bytes it did before motion existed
  (tests/data/motion_off_golden.json, made by bench/render/motion_off_golden.py at commit 0724401);
- the draws: B's velocity from the frame's own stream, whatever the frame order, nothing else
  drawn; the exposure is the colour chain's exposure time;
- the label holds B at mid-exposure; a global shutter's geometry is the static frame's;
- the rolling shutter's row time is Cycles' (transcribed), and the fixed point of every B point
  matches a brute-force root search (1e-3 px) and a row-by-row integration of the rolling image
  (outline centroid, 0.02 px).
"""
import dataclasses
import hashlib
import json

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from dockfactory.core.config import ConfigError, config_from_dict, load_config
from dockfactory.core.layout import marker_outline
from dockfactory.core.scene import FrameScene, MotionParams, from_dict, to_dict
from dockfactory.generator.random_draws import STREAM_FRAME_ISP, STREAM_FRAME_MOTION, rng_for, static_scene
from dockfactory.generator.frame_output import label_text
from dockfactory.generator.labels import frame_labels, image_px, marker_pinhole_outlines
from dockfactory.generator.motion import (
    MovingB,
    frame_motion,
    label_rolling_view,
    moving_b,
    rolling_view,
    row_time_s,
)
from dockfactory.generator.sampler import frame_plan, sample_frame

MOTION = {"enabled": True, "velocity_mm_s": [50.0, 400.0], "velocity_y_mm_s": [-60.0, 60.0],
          "velocity_z_mm_s": [-20.0, 20.0]}


def motion_cfg(frames=6, rolling_ms=0.0, **extra):
    data = {"dataset": {"frames": frames, "seed": 7}, "sensor": {"exposure_time_ms": [4.0, 25.0]},
            "motion": {**MOTION, "rolling_shutter_ms": rolling_ms}}
    for table, values in extra.items():
        data.setdefault(table, {}).update(values)
    return config_from_dict(data)


def motion_of(cfg, spec):
    """``frame_motion`` of a planned frame, from the sections it reads."""
    return frame_motion(cfg.motion, cfg.sensor.exposure_time_ms, cfg.dataset.seed, spec.index)


def sha(text: str) -> str:
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


# ----------------------------------------------------------------------------- config

def test_motion_is_off_by_default_and_a_full_table_parses(tmp_config):
    assert config_from_dict({}).motion.enabled is False
    cfg = load_config(tmp_config('[motion]\nenabled = true\nvelocity_mm_s = [10, 80]\nvelocity_y_mm_s = [-5, 5]\n'
                                 'velocity_z_mm_s = [-2, 2]\nrolling_shutter_ms = 25\n'))
    assert cfg.motion.velocity_mm_s == (10.0, 80.0) and cfg.motion.rolling_shutter_ms == 25.0
    assert cfg.motion.velocity_y_mm_s == (-5.0, 5.0) and cfg.motion.velocity_z_mm_s == (-2.0, 2.0)


@pytest.mark.parametrize("text, key", [
    ("[motion]\nenabled = true\nspeed = [1, 2]\n", "unknown key 'speed'"),
    ("[motion]\nenabled = 'yes'\n", "enabled: expected true or false"),
    ("[motion]\nenabled = true\nvelocity_mm_s = 'fast'\n", "velocity_mm_s: expected a list"),
    ("[motion]\nenabled = true\nvelocity_mm_s = [300, 100]\n", "velocity_mm_s: min 300.0 > max 100.0"),
    ("[motion]\nenabled = true\nvelocity_mm_s = [10, 20000]\n", "velocity_mm_s: [10.0, 20000.0] is outside"),
    ("[motion]\nenabled = true\nvelocity_mm_s = [10, nan]\n", "velocity_mm_s[1]: must be a finite number"),
    ("[motion]\nenabled = true\nvelocity_mm_s = [10, 20]\nvelocity_y_mm_s = [1]\n",
     "velocity_y_mm_s: expected 2 values"),
    ("[motion]\nenabled = true\nvelocity_mm_s = [10, 20]\nrolling_shutter_ms = -1\n",
     "rolling_shutter_ms: must be in [0, 1000]"),
    ("[motion]\nenabled = true\nvelocity_mm_s = [10, 20]\nrolling_shutter_ms = 5000\n",
     "rolling_shutter_ms: must be in"),
    ("[motion]\nvelocity_mm_s = [10, 20]\n", "velocity_mm_s: is set but [motion] enabled is false"),
    ("[motion]\nrolling_shutter_ms = 20\n", "rolling_shutter_ms: is set but [motion] enabled is false"),
    ("[motion]\nenabled = true\n", "enabled: B never moves"),
    ("[motion]\nenabled = true\nvelocity_mm_s = [10, 20]\n[sensor]\nexposure_time_ms = [0, 0]\n",
     "enabled: nothing moves during the exposure"),
])
def test_bad_motion_tables_fail_in_one_line_naming_file_table_and_key(tmp_config, text, key):
    path = tmp_config(text)
    with pytest.raises(ConfigError) as err:
        load_config(path)
    msg = str(err.value)
    assert "\n" not in msg
    assert msg.startswith(f"{path}: [motion]") and key in msg, msg


def test_a_rolling_shutter_too_slow_for_b_is_refused_when_the_frame_is_sampled():
    from dockfactory.generator.sampler import check_focal_fits
    cfg = motion_cfg(frames=2, rolling_ms=1000.0, motion={"velocity_y_mm_s": [5000.0, 5000.0]},
                     image={"width": 320, "height": 240}, camera={"focal_px": [300.0, 700.0], "margin_px": 10.0})
    with pytest.raises(ConfigError, match=r"^\[motion\] rolling_shutter_ms: frame 00000\d: B's image crosses rows"):
        sample_frame(cfg, frame_plan(cfg)[0])
    with pytest.raises(ConfigError, match=r"^cfg.toml: \[motion\] rolling_shutter_ms: frame 00000\d: "):
        check_focal_fits(cfg, "cfg.toml")    # check-config, render and run
    check_focal_fits(motion_cfg(frames=2, rolling_ms=30.0), "cfg.toml")


def test_runs_and_repeatability_frames_move_too():
    cfg = motion_cfg(frames=6, rolling_ms=20.0, runs={"frames_per_run": 3}, repeatability={"poses": 1, "captures": 2},
                     camera_units={"count": 2, "k1": [-0.1, 0.0]})
    static = static_scene(cfg)
    for spec in frame_plan(cfg):
        frame = sample_frame(cfg, spec)
        assert frame.motion is not None and frame.motion.readout_ms == 20.0
        assert "motion" in frame_labels(frame, static, None, 0.5)


# ----------------------------------------------------------------------------- motion off

@pytest.mark.parametrize("name", ["quick", pytest.param("realistic", marks=pytest.mark.slow), "ideal"])
def test_configs_without_motion_sample_and_label_the_bytes_of_before(repo_root, name):
    """Every frame's scene (to_dict) and label text (no index pass) against their digests: the scenes' at
    0724401 (before motion), the labels' re-recorded when the section silhouette changed (the file's about);
    with label-aware sampling off and the raised puck, the values those digests were recorded at (each
    became another default since)."""
    golden = json.loads((repo_root / "tests" / "data" / "motion_off_golden.json").read_text())["configs"][name]
    cfg = load_config(repo_root / "configs" / f"{name}.toml")
    cfg = dataclasses.replace(cfg, render=dataclasses.replace(cfg.render, marker_samples=0),
                              markers=dataclasses.replace(cfg.markers, form="puck", raise_mm=1.0))
    static = static_scene(cfg)
    got = {}
    for spec in frame_plan(cfg):
        frame = sample_frame(cfg, spec)
        assert frame.motion is None and "motion" not in to_dict(frame)
        label = frame_labels(frame, static, None, cfg.labels.visible_threshold)
        got[spec.frame_id] = [sha(json.dumps(to_dict(frame), sort_keys=True)), sha(label_text(label))]
    bad = [fid for fid in golden if got.get(fid) != golden[fid]]
    assert set(got) == set(golden) and not bad, f"{len(bad)} frames differ, first {bad[:3]}"


def test_an_explicit_motion_off_table_is_no_table(repo_root):
    cfg = load_config(repo_root / "configs" / "quick.toml")
    off = dataclasses.replace(cfg, motion=dataclasses.replace(cfg.motion, enabled=False))
    for spec in frame_plan(cfg)[:5]:
        assert sample_frame(off, spec) == sample_frame(cfg, spec)


# ----------------------------------------------------------------------------- draws

def test_motion_draws_only_its_own_stream_and_nothing_else_changes():
    """The same config with and without [motion]: every frame identical but for ``motion``."""
    on = motion_cfg(frames=8)
    off = dataclasses.replace(on, motion=dataclasses.replace(on.motion, enabled=False))
    for spec in frame_plan(on):
        moving = sample_frame(on, spec)
        assert dataclasses.replace(moving, motion=None) == sample_frame(off, spec)
        rng = rng_for(on.dataset.seed, STREAM_FRAME_MOTION, spec.index)
        vx, vy, vz = rng.uniform(50.0, 400.0), rng.uniform(-60.0, 60.0), rng.uniform(-20.0, 20.0)
        exposure = rng_for(on.dataset.seed, STREAM_FRAME_ISP, spec.index).uniform(4.0, 25.0)
        assert moving.motion == MotionParams((-vx, vy, vz), exposure, 0.0)


def test_velocity_draws_do_not_depend_on_frame_order_and_differ_between_frames():
    cfg = motion_cfg(frames=12)
    plan = frame_plan(cfg)
    forward = {s.frame_id: motion_of(cfg, s) for s in plan}
    backward = {s.frame_id: motion_of(cfg, s) for s in reversed(plan)}
    assert forward == backward
    assert all(sample_frame(cfg, s).motion == forward[s.frame_id] for s in plan[::-1][:4])
    assert len({m.velocity_mm_s for m in forward.values()}) == len(plan)
    assert all(-400.0 <= m.velocity_mm_s[0] <= -50.0 for m in forward.values())   # toward A: -X
    other_seed = motion_cfg(frames=12, dataset={"seed": 8})
    assert motion_of(other_seed, plan[0]) != forward[plan[0].frame_id]


def test_the_exposure_is_the_colour_chain_exposure_time():
    cfg = motion_cfg(frames=4, sensor={"presets": ["imx273"], "cfa": ["RGGB"]})
    for spec in frame_plan(cfg):
        frame = sample_frame(cfg, spec)
        assert frame.sensor.chain.exposure_s == frame.motion.exposure_ms / 1000.0


def test_frame_scene_round_trips_with_and_without_motion():
    cfg = motion_cfg(frames=2, rolling_ms=12.0)
    frame = sample_frame(cfg, frame_plan(cfg)[0])
    assert to_dict(frame)["motion"] == {"velocity_mm_s": frame.motion.velocity_mm_s,
                                        "exposure_ms": frame.motion.exposure_ms, "readout_ms": 12.0}
    assert from_dict(FrameScene, json.loads(json.dumps(to_dict(frame)))) == frame
    still = dataclasses.replace(frame, motion=None)
    assert "motion" not in to_dict(still) and from_dict(FrameScene, to_dict(still)) == still


# ----------------------------------------------------------------------------- labels: global shutter

def test_the_label_holds_b_at_mid_exposure_and_the_shutter_ends():
    cfg = motion_cfg(frames=3)
    static = static_scene(cfg)
    for spec in frame_plan(cfg):
        frame = sample_frame(cfg, spec)
        label = frame_labels(frame, static, None, 0.5)
        m, d_from_b = frame.motion, np.array(frame.d_from_b)
        half_s = (m.exposure_ms + m.readout_ms) / 2000.0
        assert label["d_from_b"] == d_from_b.tolist()
        rec = label["motion"]
        assert rec["shutter"] == "global" and rec["velocity_d_mm_s"] == list(m.velocity_mm_s)
        step = np.array(m.velocity_mm_s) * half_s
        np.testing.assert_allclose(np.array(rec["d_from_b_open"])[:3, 3], d_from_b[:3, 3] - step)
        np.testing.assert_allclose(np.array(rec["d_from_b_close"])[:3, 3], d_from_b[:3, 3] + step)
        assert "mid" in rec["pose_time"] and "index pass" in rec["pixels"]


def test_a_global_shutter_labels_the_static_geometry_of_b_at_mid_exposure():
    """Every field but the motion ones equals the label of the same frame without motion."""
    cfg = motion_cfg(frames=3)
    static = static_scene(cfg)
    for spec in frame_plan(cfg):
        frame = sample_frame(cfg, spec)
        moving = frame_labels(frame, static, None, 0.5)
        still = frame_labels(dataclasses.replace(frame, motion=None), static, None, 0.5)
        assert moving.pop("motion") and "motion" not in still
        for m in moving["markers"]:
            extra = {k: m.pop(k, None) for k in ("time_ms", "blur_px", "bbox_swept_px")}
            assert (extra["time_ms"] == 0.0) == (m["section"] == "B")
            assert (extra["blur_px"] is None) == (m["section"] == "A")
        assert moving == still


def test_blur_and_swept_box_follow_b_over_the_exposure():
    cfg = motion_cfg(frames=3)
    static = static_scene(cfg)
    frame = sample_frame(cfg, frame_plan(cfg)[1])
    label = frame_labels(frame, static, None, 0.5)
    mb, half_s = moving_b(frame), frame.motion.exposure_ms / 2000.0
    by_id = {m.id: m for m in static.markers}
    for rec in (r for r in label["markers"] if r["section"] == "B"):
        centre = np.array([by_id[rec["id"]].center_mm])
        ends = [image_px(mb.project(centre, off)[0], mb.k, frame.camera.distortion)[0] for off in (-half_s, half_s)]
        np.testing.assert_allclose(rec["blur_px"], ends[1] - ends[0], atol=1e-9)
        assert np.hypot(*rec["blur_px"]) > 0.1
        sx0, sy0, sx1, sy1 = rec["bbox_swept_px"]
        bx0, by0, bx1, by1 = rec["bbox_px"]
        assert sx0 <= bx0 and sy0 <= by0 and sx1 >= bx1 and sy1 >= by1


def test_time_averaged_image_centroid_is_the_mid_exposure_projection():
    """For a constant velocity the image path is projective, not straight: the mean over the
    exposure of B's projected centre misses the mid-exposure projection by a second-order term,
    far below the labels' 0.02 px (worst here: 400 mm/s for 25 ms, 10 mm of travel)."""
    cfg = motion_cfg(frames=6)
    static = static_scene(cfg)
    worst = 0.0
    for spec in frame_plan(cfg):
        frame = sample_frame(cfg, spec)
        mb = moving_b(frame)
        pts = np.array([m.center_mm for m in static.markers if m.section == "B"])
        offsets = np.linspace(-mb.exposure_s / 2, mb.exposure_s / 2, 2001)
        mean = np.mean([mb.project(pts, off)[0] for off in offsets], axis=0)
        worst = max(worst, float(np.abs(mean - mb.project(pts)[0]).max()))
    assert worst < 2e-3, worst


def test_blurred_b_markers_leave_edge_refinement_to_cycles_samples():
    cfg = motion_cfg(frames=2)
    static = static_scene(cfg)
    frame = sample_frame(cfg, frame_plan(cfg)[0])
    n_a = sum(m.section == "A" for m in static.markers)
    assert len(marker_pinhole_outlines(frame, static)) == n_a
    assert len(marker_pinhole_outlines(dataclasses.replace(frame, motion=None), static)) == len(static.markers)


# ----------------------------------------------------------------------------- rolling shutter

def cycles_ray_time_ms(y_bottom_up: int, u: float, height: int, exposure_ms: float, readout_ms: float) -> float:
    """Cycles' camera ray time (intern/cycles/kernel/camera/camera.h, camera_sample, rolling
    shutter 'TOP'), transcribed: pixel row y counted from the bottom, u the time sample in
    [0, 1], duration = rolling_shutter_duration; as ms from the shutter's centre."""
    duration = exposure_ms / (exposure_ms + readout_ms)
    time = 1.0 - y_bottom_up / height
    ray_time = (u - 0.5) * duration + (time - 0.5) * (1.0 - duration) + 0.5
    return (ray_time - 0.5) * (exposure_ms + readout_ms)


def test_row_times_are_cycles_top_first_rolling_shutter():
    h, e, r = 240, 8.0, 30.0
    rows = np.arange(h)
    centre = np.array([cycles_ray_time_ms(h - 1 - v, 0.5, h, e, r) for v in rows])
    np.testing.assert_allclose(row_time_s(rows, h, r), centre, atol=1e-12)   # ms in, ms out
    start = np.array([cycles_ray_time_ms(h - 1 - v, 0.0, h, e, r) for v in rows])
    np.testing.assert_allclose(centre - start, e / 2, atol=1e-12)            # every row exposed for e
    assert row_time_s(h - 1, h, r) == r / 2 and row_time_s(0, h, r) == pytest.approx(-r / 2 + r / h)
    with pytest.raises(ValueError):
        row_time_s(0, 0, r)


def brute_force_fixed_point(mb: MovingB, point_b: np.ndarray, offset_s: float = 0.0) -> np.ndarray:
    """Pinhole pixel of one point of B under the rolling shutter, by a dense scan of t for the
    sign change of t - row_time(v(t)) - offset and bisection (no derivative)."""
    x0 = (mb.cam_from_d @ mb.d_from_b @ np.append(point_b, 1.0))[:3]
    w = mb.cam_from_d[:3, :3] @ mb.velocity_mm_s

    def g(t):
        xc = x0 + np.multiply.outer(t, w)
        v = mb.k[1, 1] * xc[..., 1] / xc[..., 2] + mb.k[1, 2]
        return t - row_time_s(v - mb.row_offset, mb.canvas_height, mb.readout_s) - offset_s

    span = mb.readout_s + abs(offset_s) + 1e-3
    ts = np.linspace(-span, span, 20001)
    i = np.flatnonzero(np.diff(np.sign(g(ts))))
    assert len(i) == 1, "one fixed point"
    lo, hi = ts[i[0]], ts[i[0] + 1]
    for _ in range(80):
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if np.sign(g(mid)) == np.sign(g(lo)) else (lo, mid)
    xc = x0 + (lo + hi) / 2 * w
    return (mb.k @ (xc / xc[2]))[:2]


@pytest.mark.parametrize("lens", [False, True])
def test_rolling_fixed_point_matches_brute_force(lens):
    """Every B marker's centre and a few outline points, at their exposure centre and ends, in a
    pinhole camera and in a distorted one (whose render canvas is offset and taller)."""
    extra = {"camera_units": {"k1": [-0.15, -0.1], "principal_offset_y_px": [-30, 30]}} if lens else {}
    cfg = motion_cfg(frames=3, rolling_ms=33.0, **extra)
    static = static_scene(cfg)
    worst = 0.0
    for spec in frame_plan(cfg):
        frame = sample_frame(cfg, spec)
        mb = rolling_view(frame)
        assert (mb.row_offset != 0) == lens and mb.canvas_height >= frame.camera.height
        for m in (m for m in static.markers if m.section == "B"):
            pts = np.vstack([m.center_mm, marker_outline(m)[::64]])
            for off in (0.0, -mb.exposure_s / 2, mb.exposure_s / 2):
                got = mb.project(pts, off)[0]
                want = np.array([brute_force_fixed_point(mb, p, off) for p in pts])
                worst = max(worst, float(np.abs(got - want).max()))
    assert worst < 1e-3, worst


@given(vy=st.floats(-300, 300), vx=st.floats(-500, 500), readout_ms=st.floats(0.1, 80), row=st.floats(-500, 1500))
def test_the_fixed_point_satisfies_its_equation(vy, vx, readout_ms, row):
    """Wherever a point of B sits and however B moves (within the config's bounds of pace), the
    pixel the solver returns is the projection of B at that pixel's own row time."""
    k = np.array([[1500.0, 0, 640], [0, 1500.0, 480], [0, 0, 1]])
    cam_from_d = np.eye(4)
    cam_from_d[:3, 3] = (0, 0, 1500.0)
    d_from_b = np.eye(4)
    mb = MovingB(k, cam_from_d, d_from_b, np.array([vx, vy, 0.0]), 0.01, readout_ms / 1000.0, 0.0, 960)
    point = np.array([[0.0, (row - 480) / 1500 * 1500, 0.0]])
    uv, z, t = mb.project(point)
    d_from_b_t = MotionParams((vx, vy, 0.0), 10.0).d_from_b_at(d_from_b, t[0])
    want = k @ (mb.cam_from_d @ d_from_b_t @ np.append(point[0], 1))[:3]
    np.testing.assert_allclose(uv[0], want[:2] / want[2], atol=1e-6)
    np.testing.assert_allclose(t[0], row_time_s(uv[0, 1], 960, mb.readout_s), atol=1e-9)


def rolling_image_centroid(mb: MovingB, marker, step: float = 0.01) -> np.ndarray:
    """Area centroid of the rolling-shutter image of a marker disc, integrated row by row: image
    row y shows the disc at time row_time(y), and contributes the span of the disc's projected
    outline at that time that crosses y."""
    outline = marker_outline(marker, 720)
    ys_all = mb.project(outline)[0][:, 1]
    area, mx, my = 0.0, 0.0, 0.0
    for y in np.arange(np.floor(ys_all.min()) - 1, np.ceil(ys_all.max()) + 1, step) + step / 2:
        t = row_time_s(y - mb.row_offset, mb.canvas_height, mb.readout_s)
        uv = MovingB(mb.k, mb.cam_from_d, mb.d_from_b, mb.velocity_mm_s, 0.0, 0.0, 0.0, 1).project(outline, t)[0]
        a, b = uv, np.roll(uv, -1, axis=0)
        cross = (a[:, 1] - y) * (b[:, 1] - y) < 0
        if not cross.any():
            continue
        xs = a[cross, 0] + (y - a[cross, 1]) / (b[cross, 1] - a[cross, 1]) * (b[cross, 0] - a[cross, 0])
        span = xs.max() - xs.min()
        area += span * step
        mx += span * step * (xs.max() + xs.min()) / 2
        my += span * step * y
    return np.array([mx, my]) / area


@pytest.mark.slow  # several seconds of solves or pages; the full suite runs it
def test_rolling_outline_centroid_matches_a_row_by_row_integration():
    cfg = motion_cfg(frames=2, rolling_ms=40.0, motion={"velocity_y_mm_s": [-200.0, 200.0]})
    static = static_scene(cfg)
    frame = sample_frame(cfg, frame_plan(cfg)[0])
    label = frame_labels(frame, static, None, 0.5)
    still = frame_labels(dataclasses.replace(frame, motion=None), static, None, 0.5)
    mb = rolling_view(frame)
    by_id = {m.id: m for m in static.markers}
    shift = []
    for rec, rec0 in zip(label["markers"], still["markers"]):
        if rec["section"] != "B":
            assert rec == rec0
            continue
        want = rolling_image_centroid(mb, by_id[rec["id"]])
        assert np.abs(np.array(rec["outline_centroid_px"]) - want).max() < 0.02, (rec["id"], want)
        shift.append(np.hypot(*(np.array(rec["center_px"]) - rec0["center_px"])))
    assert max(shift) > 1.0   # the rolling shutter moves B's markers by pixels: the check has teeth


def test_rolling_labels_use_row_times_for_centres_boxes_and_silhouettes():
    cfg = motion_cfg(frames=2, rolling_ms=30.0)
    static = static_scene(cfg)
    frame = sample_frame(cfg, frame_plan(cfg)[1])
    label = frame_labels(frame, static, None, 0.5)
    mb = rolling_view(frame)
    assert label["motion"]["shutter"] == "rolling_top_first" and label["motion"]["canvas_rows"] == 960
    by_id = {m.id: m for m in static.markers}
    for rec in (r for r in label["markers"] if r["section"] == "B"):
        m = by_id[rec["id"]]
        uv, _, t = mb.project(np.array([m.center_mm]))
        assert rec["center_px"] == uv[0].tolist() and rec["time_ms"] == t[0] * 1000.0
        assert rec["time_ms"] == pytest.approx(1000 * row_time_s(uv[0, 1], 960, 0.03))
        outline = mb.project(marker_outline(m))[0]
        assert rec["bbox_px"] == [outline[:, 0].min(), outline[:, 1].min(), outline[:, 0].max(), outline[:, 1].max()]
    still = frame_labels(dataclasses.replace(frame, motion=None), static, None, 0.5)
    assert label["sections"][0] == still["sections"][0]          # A does not move
    # B's silhouette: its flange and body hulls with every point at its row time, at pixel centres
    import cv2

    from dockfactory.generator.silhouette import mask_pixels, outlines_mask, silhouette_parts
    hulls = []
    for pts in silhouette_parts(static, "B"):
        uv = mb.project(pts)[0]
        hulls.append(uv[cv2.convexHull(uv.astype(np.float32), returnPoints=False).ravel()])
    count, box = mask_pixels(outlines_mask(hulls, 1280, 960))
    assert label["sections"][1]["pixels_all"] == count and label["sections"][1]["bbox_obj_px"] == box
    assert abs(count - still["sections"][1]["pixels_all"]) > 100   # the row times move the silhouette


def test_coco_outlines_of_a_rolling_frame_are_the_labels():
    from dockfactory.generator.exports.coco import outline_px
    cfg = motion_cfg(frames=2, rolling_ms=30.0, camera_units={"k1": [-0.1, -0.1]})
    static = static_scene(cfg)
    frame = sample_frame(cfg, frame_plan(cfg)[0])
    label = json.loads(label_text(frame_labels(frame, static, None, 0.5)))
    assert label_rolling_view(label) is not None
    for rec, m in zip(label["markers"], static.markers):
        poly = outline_px(label, m)
        assert [poly[:, 0].min(), poly[:, 1].min(), poly[:, 0].max(), poly[:, 1].max()] == rec["bbox_px"]
