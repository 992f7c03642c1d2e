import dataclasses

import numpy as np
import pytest

from dockfactory.core.config import CHALLENGING, ConfigError, config_from_dict
from dockfactory.core.geometry import pose_components, project_points, transform_points
from dockfactory.core.layout import (
    DEFAULT_LAYOUT_A,
    DEFAULT_LAYOUT_B,
    build_layout,
    layout_problems,
    marker_outline,
    marker_points,
)
from dockfactory.core.scene import FrameScene, from_dict, to_dict
from dockfactory.generator.random_draws import markers_in_d, static_scene
from dockfactory.generator.sampler import condition_counts, frame_geometry, frame_plan, sample_frame


@pytest.fixture(scope="module")
def cfg():
    return config_from_dict({"dataset": {"frames": 300, "seed": 42},
                             "repeatability": {"poses": 3, "captures": 4}})


def test_frame_is_a_function_of_seed_and_index_alone(cfg):
    plan = frame_plan(cfg)
    a = [to_dict(sample_frame(cfg, s)) for s in plan[:20]]
    b = [to_dict(sample_frame(cfg, s)) for s in reversed(plan[:20])][::-1]
    assert a == b
    # a larger dataset with the same seed keeps the geometry of shared frames
    bigger = config_from_dict({"dataset": {"frames": 600, "seed": 42}})
    f_small = sample_frame(cfg, plan[5])
    spec_big = dataclasses.replace(plan[5], condition=plan[5].condition)
    f_big = sample_frame(bigger, spec_big)
    assert f_small.d_from_b == f_big.d_from_b and f_small.camera == f_big.camera
    other_seed = config_from_dict({"dataset": {"frames": 300, "seed": 43}})
    assert sample_frame(other_seed, plan[5]).d_from_b != f_small.d_from_b


@pytest.mark.parametrize("runs", [0, 5])
def test_frame_geometry_is_sample_frames_pose_and_camera(cfg, runs):
    """The design predictor's frames (frame_geometry: no stage drawn) are the rendered ones: the
    same d_from_b and camera as sample_frame, main and repeatability frames, with and without
    docking runs."""
    c = cfg if runs == 0 else config_from_dict({"dataset": {"frames": 40, "seed": 9}, "runs": {"frames_per_run": runs},
                                                "repeatability": {"poses": 2, "captures": 3}})
    plan = frame_plan(c)
    specs = list(plan[:12]) + [s for s in plan if s.kind == "repeat"][:4]
    assert {s.kind for s in specs} == {"main", "repeat"}
    for spec in specs:
        f = sample_frame(c, spec)
        d_from_b, camera = frame_geometry(c, spec)
        assert np.array_equal(np.asarray(d_from_b, dtype=float), f.d_from_b_array()) and camera == f.camera


def test_scene_serialisation_round_trip(cfg):
    for spec in frame_plan(cfg)[:10]:
        f = sample_frame(cfg, spec)
        assert from_dict(FrameScene, to_dict(f)) == f


def test_condition_counts_are_exact_and_split_is_stratified():
    cfg = config_from_dict({"dataset": {"frames": 3000},
                            "conditions": {"normal": 2000, "low_light": 334, "occlusion": 333, "glare": 333}})
    plan = frame_plan(cfg)
    by = {}
    for s in plan:
        by.setdefault(s.condition, []).append(s.split)
    assert len(by["normal"]) == 2000
    assert sum(len(by[c]) for c in CHALLENGING) == 1000
    for cond, splits in by.items():
        n_train = int(np.floor(0.8 * len(splits) + 0.5))
        assert splits.count("train") + splits.count("val") == n_train, cond
        assert splits.count("val") == int(np.floor(0.1 * n_train + 0.5)), cond
    assert condition_counts({"normal": 1.0, "glare": 1.0, "low_light": 1.0}, 10) == \
        {"normal": 4, "glare": 3, "low_light": 3}


def test_val_is_carved_from_train_and_leaves_test_alone():
    base = {"frames": 600, "seed": 9, "train_fraction": 0.7}
    without = frame_plan(config_from_dict({"dataset": {**base, "val_fraction": 0.0}}))
    with_val = frame_plan(config_from_dict({"dataset": {**base, "val_fraction": 0.25}}))
    assert with_val == frame_plan(config_from_dict({"dataset": {**base, "val_fraction": 0.25}}))  # deterministic
    assert "val" not in {s.split for s in without}
    for a, b in zip(without, with_val):
        assert (a.frame_id, a.condition) == (b.frame_id, b.condition)
        assert (a.split == "test") == (b.split == "test")
        assert b.split != "val" or a.split == "train"
    for cond in {s.condition for s in with_val}:
        n_train = sum(1 for s in without if s.condition == cond and s.split == "train")
        assert sum(1 for s in with_val if s.condition == cond and s.split == "val") == int(np.floor(0.25 * n_train + 0.5))


# sha256 of the comma-joined test frame ids, computed with frame_plan at commit 8f58d10 (before
# the val split existed): adding val_fraction must not move a frame into or out of the test split
TEST_SPLIT_SHA256 = {
    "detector.toml": (61, "108ebf372716564602ea87135fd96ef90bf9427fc93df43bb97aa2abecedae93"),
    "paper.toml": (601, "0d1723b453a57bd2b0099c3592ee3428c2b1e44cac9c5bbaa9ad55e25d5526b8"),
}


@pytest.mark.parametrize("name", sorted(TEST_SPLIT_SHA256))
def test_test_split_of_shipped_configs_is_unchanged(repo_root, name):
    import hashlib

    from dockfactory.core.config import load_config
    plan = frame_plan(load_config(repo_root / "configs" / name))
    test_ids = [s.frame_id for s in plan if s.split == "test"]
    assert (len(test_ids), hashlib.sha256(",".join(test_ids).encode()).hexdigest()) == TEST_SPLIT_SHA256[name]
    assert any(s.split == "val" for s in plan)


def test_sampled_ranges_and_focal_fit(cfg):
    static = static_scene(cfg)
    focals = []
    for spec in frame_plan(cfg):
        f = sample_frame(cfg, spec)
        p = pose_components(f.d_from_b_array())
        assert 5 <= p["x_mm"] <= 150 and abs(p["y_mm"]) <= 15 and abs(p["z_mm"]) <= 15
        assert abs(p["alpha_deg"]) <= 1.5 + 1e-9 and abs(p["beta_deg"]) <= 1.5 + 1e-9
        assert abs(p["gamma_deg"]) <= 5 + 1e-9
        assert 1000 - 1e-9 <= f.camera.distance_mm <= 1800 + 1e-9
        assert cfg.camera.focal_px[0] <= f.camera.focal_px <= cfg.camera.focal_px[1]
        focals.append(f.camera.focal_px)
        # every marker disc lies inside the image with the margin
        d_from_b = f.d_from_b_array()
        for m in static.markers:
            d_from_s = d_from_b if m.section == "B" else np.eye(4)
            uv, z = project_points(f.camera.k(), f.camera.cam_from_d_array(),
                                   transform_points(d_from_s, marker_outline(m)))
            assert np.all(z > 0)
            margin = cfg.camera.margin_px - 1e-6
            assert uv[:, 0].min() >= -0.5 + margin and uv[:, 0].max() <= cfg.image.width - 0.5 - margin
            assert uv[:, 1].min() >= -0.5 + margin and uv[:, 1].max() <= cfg.image.height - 0.5 - margin
    assert np.std(focals) > 100  # a zoom lens: focal varies between frames


def test_repeatability_captures_share_geometry_not_look(cfg):
    plan = [s for s in frame_plan(cfg) if s.kind == "repeat"]
    assert len(plan) == 12
    f0, f1 = sample_frame(cfg, plan[0]), sample_frame(cfg, plan[1])
    assert plan[0].pose_index == plan[1].pose_index
    assert f0.d_from_b == f1.d_from_b and f0.camera == f1.camera
    assert f0.lights != f1.lights and f0.sensor.noise_seed != f1.sensor.noise_seed
    f4 = sample_frame(cfg, plan[4])  # next static pose
    assert f4.d_from_b != f0.d_from_b


def test_conditions_shape_the_scene(cfg):
    seen = set()
    for spec in frame_plan(cfg)[:80]:
        f = sample_frame(cfg, spec)
        occluders = f.occluders
        if spec.condition == "occlusion":
            assert 1 <= len(occluders) <= 3
            assert all(o.target_marker for o in occluders)
        else:
            assert not occluders
        if spec.condition == "low_light":
            assert f.sensor.exposure_ev <= -3.0
        if spec.condition == "glare":
            assert f.glare_kind in ("lamp_in_view", "specular")
        seen.add(spec.condition)
    assert seen == {"normal", "low_light", "occlusion", "glare"}


def test_ideal_frames_are_clean():
    cfg = config_from_dict({"conditions": {"normal": 0, "low_light": 0, "occlusion": 0, "glare": 0, "ideal": 1},
                            "dataset": {"frames": 10}})
    for spec in frame_plan(cfg):
        f = sample_frame(cfg, spec)
        assert f.sensor.ideal and not f.occluders and f.glare_kind == "none"
        assert f.appearance.roughness_variation == 0


def test_default_layout_is_asymmetric_and_on_the_camera_side():
    markers = build_layout(DEFAULT_LAYOUT_A, DEFAULT_LAYOUT_B, 300.0, 20.0)
    assert layout_problems(markers) == []
    assert len({m.id for m in markers}) == len(markers) >= 12
    for section in "AB":
        p = marker_points(markers, section)
        assert len(p) >= 6
        assert np.all(p[:, 2] > 0)                           # camera side (+Z)
        assert np.ptp(p[:, 2]) > 20                          # on the curve: not coplanar
        assert np.allclose(np.hypot(p[:, 1], p[:, 2]), 301.0)  # on the surface, raised 1 mm
        assert np.all(p[:, 0] < 0) if section == "A" else np.all(p[:, 0] > 0)


def test_symmetric_layout_is_reported():
    sym = ((50, -20), (50, 20), (100, -20), (100, 20), (150, -20), (150, 20))
    problems = layout_problems(build_layout(sym, DEFAULT_LAYOUT_B, 300.0, 20.0))
    assert any("same distance signature" in p for p in problems)


def test_markers_in_d_moves_only_b(cfg):
    f = sample_frame(cfg, frame_plan(cfg)[0])
    static = static_scene(cfg)
    pts = markers_in_d(static, f.d_from_b_array())
    local = marker_points(static.markers)
    is_a = np.array([m.section == "A" for m in static.markers])
    assert np.allclose(pts[is_a], local[is_a])
    assert not np.allclose(pts[~is_a], local[~is_a])


def test_a_white_ring_changes_the_ring_alone(cfg):
    """``[markers] ring = "white"``: every frame keeps its pose, camera and every other material
    (one draw either way); the ring's grey level moves from the dark range to the white one."""
    from dockfactory.core.layout import RING_REFLECTANCE
    white = config_from_dict({"dataset": {"frames": 300, "seed": 42}, "repeatability": {"poses": 3, "captures": 4},
                              "markers": {"ring": "white"}})
    for spec in frame_plan(cfg)[:12]:
        d, w = sample_frame(cfg, spec), sample_frame(white, spec)
        assert d.d_from_b == w.d_from_b and d.camera == w.camera and d.lights == w.lights
        assert dataclasses.replace(w.appearance, ring_color=d.appearance.ring_color) == d.appearance
        lo, hi = RING_REFLECTANCE["white"]
        assert lo <= w.appearance.ring_color[0] <= hi and d.appearance.ring_color[0] <= RING_REFLECTANCE["dark"][1]


def test_a_mixed_ring_draws_each_frame_dark_or_white(cfg):
    """``[markers] ring = "mixed"`` (detector training on both designs): every frame keeps its pose,
    camera and other materials; its ring is in the dark range or the white one, the two about half
    and half over 200 frames (binomial: 100 +- 7 expected; asserted 70-130)."""
    from dockfactory.core.layout import RING_REFLECTANCE
    mixed = config_from_dict({"dataset": {"frames": 300, "seed": 42}, "repeatability": {"poses": 3, "captures": 4},
                              "markers": {"ring": "mixed"}})
    white = 0
    for k, spec in enumerate(frame_plan(cfg)[:200]):
        m = sample_frame(mixed, spec)
        grey = m.appearance.ring_color[0]
        assert any(lo <= grey <= hi for lo, hi in RING_REFLECTANCE.values()), grey
        white += grey >= RING_REFLECTANCE["white"][0]
        if k < 12:
            d = sample_frame(cfg, spec)
            assert d.d_from_b == m.d_from_b and d.camera == m.camera and d.lights == m.lights
            assert dataclasses.replace(m.appearance, ring_color=d.appearance.ring_color) == d.appearance
    assert 70 <= white <= 130, white


def test_an_unknown_ring_is_refused_in_one_line():
    with pytest.raises(ConfigError, match=r"\[markers\] ring: 'grey' is not one of dark, white, mixed"):
        config_from_dict({"markers": {"ring": "grey"}})
