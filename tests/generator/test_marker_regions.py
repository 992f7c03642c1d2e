"""Label-aware sampling without Blender: the marker regions, their merging and the blend
(generator.marker_regions), the config key and the identity it leaves alone."""
import dataclasses
import itertools
import json

import numpy as np
import pytest

from dockfactory.core.config import ConfigError, config_from_dict, config_from_identity, load_config
from dockfactory.core.config_text import load_config_text
from dockfactory.core.geometry import project_points
from dockfactory.core.scene import RenderSettings, from_dict, to_dict
from dockfactory.generator.datasets.folder import identity
from dockfactory.generator.marker_regions import (
    FEATHER_PX,
    HALO_PX,
    REGION_MARGIN_PX,
    Region,
    composite,
    halo_points,
    halo_weights,
    marker_halos,
    marker_regions,
    merge_boxes,
)
from dockfactory.generator.random_draws import static_scene
from dockfactory.generator.sampler import frame_plan, render_settings, sample_frame


def _cfg(**render):
    return config_from_dict({"dataset": {"frames": 12, "seed": 7}, "render": {"marker_samples": 40, **render}})


@pytest.fixture(scope="module")
def frames():
    cfg = _cfg()
    return cfg, [sample_frame(cfg, s) for s in frame_plan(cfg)[:8]]


def _canvas_points(frame, static, m):
    cam = frame.camera
    ox, oy, _, _ = cam.canvas()
    pose = frame.d_from_b_array() if m.section == "B" else np.eye(4)
    uv, _ = project_points(cam.k(), cam.cam_from_d_array() @ pose, halo_points(m, base_depth_mm=static.marker_base_depth_mm))
    return uv - [ox, oy]


def test_every_halo_and_its_margin_lies_in_one_region(frames):
    cfg, fs = frames
    static = static_scene(cfg)
    for f in fs:
        regions = marker_regions(f, static)
        _, _, wc, hc = f.camera.canvas()
        for m in static.markers:
            uv = _canvas_points(f, static, m)
            lo, hi = uv.min(axis=0), uv.max(axis=0)
            holders = [r for r in regions if r.x0 - 0.5 <= lo[0] and hi[0] <= r.x1 - 0.5
                       and r.y0 - 0.5 <= lo[1] and hi[1] <= r.y1 - 0.5]
            assert len(holders) == 1, (f.spec.frame_id, m.id)
            r = holders[0]
            # the margin, where the canvas leaves room for it
            assert lo[0] - (r.x0 - 0.5) >= REGION_MARGIN_PX - 1 or r.x0 == 0
            assert (r.x1 - 0.5) - hi[0] >= REGION_MARGIN_PX - 1 or r.x1 == wc
            assert lo[1] - (r.y0 - 0.5) >= REGION_MARGIN_PX - 1 or r.y0 == 0
            assert (r.y1 - 0.5) - hi[1] >= REGION_MARGIN_PX - 1 or r.y1 == hc


def test_regions_do_not_overlap_and_cover_a_few_per_cent(frames):
    cfg, fs = frames
    static = static_scene(cfg)
    for f in fs:
        regions = marker_regions(f, static)
        assert regions
        for a, b in itertools.combinations(regions, 2):
            assert not a.overlaps(b)
        share = sum(r.area for r in regions) / (f.camera.width * f.camera.height)
        assert 0.005 < share < 0.15, share


def test_merging_never_costs_more_and_does_not_depend_on_order():
    """Random boxes, some overlapping: the regions never overlap, hold every box, come out the same
    in any input order and, for disjoint boxes, cost no more than the boxes apart."""
    rng = np.random.default_rng(3)
    for _ in range(20):
        boxes = []
        for _ in range(10):
            x, y = rng.integers(0, 500, 2)
            w, h = rng.integers(10, 60, 2)
            boxes.append(Region(int(x), int(y), int(x + w), int(y + h)))
        for overhead in (0.0, 500.0, 5000.0):
            merged = merge_boxes(boxes, overhead)
            assert merge_boxes(boxes[::-1], overhead) == merged
            assert merge_boxes(list(rng.permutation(boxes)), overhead) == merged
            disjoint = not any(a.overlaps(b) for a, b in itertools.combinations(boxes, 2))
            if disjoint:   # overlapping boxes must merge whatever it costs
                assert sum(r.area + overhead for r in merged) <= sum(b.area + overhead for b in boxes)
            for a, b in itertools.combinations(merged, 2):
                assert not a.overlaps(b)
            for b in boxes:
                assert any(r.x0 <= b.x0 and r.y0 <= b.y0 and b.x1 <= r.x1 and b.y1 <= r.y1 for r in merged)


def test_a_large_overhead_merges_everything_and_none_keeps_separate_boxes_apart():
    boxes = [Region(0, 0, 10, 10), Region(100, 100, 110, 110)]
    assert merge_boxes(boxes, 0.0) == tuple(boxes)
    assert merge_boxes(boxes, 1e6) == (Region(0, 0, 110, 110),)


def test_distorted_camera_regions_are_in_canvas_pixels():
    cfg = config_from_dict({"dataset": {"frames": 4, "seed": 11}, "render": {"marker_samples": 16},
                            "camera_units": {"k1": [-0.2, -0.15]}})
    static = static_scene(cfg)
    f = sample_frame(cfg, frame_plan(cfg)[0])
    ox, oy, wc, hc = f.camera.canvas()
    assert (ox, oy) != (0, 0)       # a distorted lens renders an overscan canvas
    for m in static.markers:
        uv = _canvas_points(f, static, m)
        assert any(r.x0 - 0.5 <= uv[:, 0].min() and uv[:, 0].max() <= r.x1 - 0.5 and
                   r.y0 - 0.5 <= uv[:, 1].min() and uv[:, 1].max() <= r.y1 - 0.5
                   for r in marker_regions(f, static))


def _square_halo(cx, cy, half):
    return np.array([[cx - half, cy - half], [cx + half, cy - half], [cx + half, cy + half], [cx - half, cy + half]])


def test_halo_weight_is_one_on_the_halo_and_falls_off_over_the_feather():
    """A square halo of corners +-10 px about (40.0, 30.0) in a 100 x 80 region: weight 1 to
    HALO_PX beyond its edge, falling linearly to 0 at HALO_PX + FEATHER_PX (to 1/8 px), 0 beyond."""
    region = Region(0, 0, 100, 80)
    w = halo_weights([_square_halo(40.0, 30.0, 10.0)], region)
    assert w.shape == (80, 100) and w.dtype == np.float32
    assert np.all(w[20:41, 30:51] == 1.0)
    row = w[30]
    for d in range(0, HALO_PX + FEATHER_PX + 3):   # d px right of the halo's edge at x = 50
        want = float(np.clip((HALO_PX + FEATHER_PX - d) / FEATHER_PX, 0, 1))
        assert row[50 + d] == pytest.approx(want, abs=0.2), d
    assert np.all(w[:, 50 + HALO_PX + FEATHER_PX + 1:] == 0) and np.all(w[30 + 10 + HALO_PX + FEATHER_PX + 1:] == 0)
    assert np.all(halo_weights([_square_halo(400.0, 300.0, 10.0)], region) == 0)   # a halo elsewhere


def test_composite_takes_the_crop_on_the_halos_keeps_the_frame_elsewhere_and_refuses_a_misfit():
    rng = np.random.default_rng(0)
    frame = rng.random((60, 80, 3), dtype=np.float32)
    before = frame.copy()
    regions = (Region(5, 5, 35, 30), Region(40, 28, 78, 58))
    halos = [_square_halo(20.0, 17.0, 4.0), _square_halo(58.0, 43.0, 6.0)]
    crops = [np.full((r.y1 - r.y0, r.x1 - r.x0, 3), 7.0, np.float32) for r in regions]
    out = composite(frame, crops, regions, halos)
    assert np.array_equal(frame, before)     # a new array; the frame is not touched
    touched = np.zeros((60, 80), bool)
    for r in regions:
        wgt = halo_weights(halos, r)
        tile = out[r.y0:r.y1, r.x0:r.x1]
        assert (wgt == 1.0).sum() > 50 and np.allclose(tile[wgt == 1.0], 7.0)
        expect = frame[r.y0:r.y1, r.x0:r.x1] * (1 - wgt[..., None]) + 7.0 * wgt[..., None]
        assert np.allclose(tile, expect, atol=1e-5)
        touched[r.y0:r.y1, r.x0:r.x1] = wgt > 0
    assert np.array_equal(out[~touched], frame[~touched])
    assert np.array_equal(composite(frame, crops[::-1], regions[::-1], halos), out)
    with pytest.raises(ValueError, match="does not fit"):
        composite(frame, [crops[1], crops[0]], regions, halos)
    with pytest.raises(ValueError, match="2 marker regions"):
        composite(frame, crops[:1], regions, halos)


def test_each_region_holds_the_whole_blend_of_its_markers(frames):
    """Every pixel any marker's blend reaches (weight > 0 over the whole canvas) lies in a region,
    so no blend is cut by its rectangle, though the rectangles end where the feather does."""
    cfg, fs = frames
    static = static_scene(cfg)
    for f in fs:
        halos = marker_halos(f, static)
        _, _, wc, hc = f.camera.canvas()
        whole = halo_weights(halos, Region(0, 0, wc, hc))
        covered = np.zeros_like(whole, dtype=bool)
        for r in marker_regions(f, static):
            assert halo_weights(halos, r).max() == 1.0
            covered[r.y0:r.y1, r.x0:r.x1] = True
        assert whole.max() == 1.0 and np.all(whole[~covered] == 0)
        inner = covered
        for _ in range(2):   # the regions' last two pixels; the canvas's own edge is no region's edge
            padded = np.pad(inner, 1, constant_values=True)
            inner = inner & padded[:-2, 1:-1] & padded[2:, 1:-1] & padded[1:-1, :-2] & padded[1:-1, 2:]
        assert whole[covered & ~inner].max() > 0   # the feather reaches them: no spare margin


def test_off_renders_no_region(frames):
    cfg, fs = frames
    off = dataclasses.replace(fs[0], render=dataclasses.replace(fs[0].render, marker_samples=0))
    assert marker_regions(off, static_scene(cfg)) == ()


def test_render_settings_leave_the_key_out_while_off():
    """Labels record to_dict(frame.render): a render without label-aware sampling keeps the
    label bytes it had before the key existed."""
    off = RenderSettings(1, "fast", 2, 0.0, 0, 1.5, "none")
    assert "marker_samples" not in to_dict(off) and "marker_denoise" not in to_dict(off)
    on = dataclasses.replace(off, marker_samples=64, marker_denoise="off")
    assert to_dict(on)["marker_samples"] == 64 and to_dict(on)["marker_denoise"] == "off"
    assert from_dict(RenderSettings, to_dict(on)) == on and from_dict(RenderSettings, to_dict(off)) == off


def test_the_key_is_in_the_identity_only_when_on():
    plain = config_from_dict({"dataset": {"frames": 12, "seed": 7}})
    assert plain.render.marker_samples == 40                          # on by default
    assert identity(_cfg(marker_samples=40)) == identity(plain)
    assert "marker_samples" not in _cfg(marker_samples=0).to_dict()["render"]   # ids of before the key
    assert identity(_cfg(marker_samples=0)) != identity(plain)
    assert identity(_cfg(marker_samples=32)) != identity(_cfg(marker_samples=64))
    assert identity(_cfg(marker_denoise="off")) != identity(_cfg())
    assert identity(_cfg(marker_denoise="fast")) == identity(_cfg())
    assert identity(_cfg(marker_adaptive_threshold=0.05)) != identity(_cfg())
    assert identity(_cfg(marker_adaptive_threshold=0.0)) != identity(_cfg())


def test_the_adaptive_keys_count_only_where_they_change_a_pixel():
    """The crops' adaptive threshold (0.02 from 4 samples by default) reads as 0 without crops and
    its minimum as 0 without a threshold, leaving the identity of those configs as it was before
    the keys; a minimum above the crops' samples is their count; with both they are the frame's."""
    plain = _cfg()
    assert (plain.render.marker_adaptive_threshold, plain.render.marker_adaptive_min_samples) == (0.02, 4)
    off = _cfg(marker_samples=0)
    assert (off.render.marker_adaptive_threshold, off.render.marker_adaptive_min_samples) == (0.0, 0)
    assert identity(_cfg(marker_samples=0, marker_adaptive_threshold=0.05)) == identity(off)
    fixed = _cfg(marker_adaptive_threshold=0.0)
    assert fixed.render.marker_adaptive_min_samples == 0
    assert identity(_cfg(marker_adaptive_threshold=0.0, marker_adaptive_min_samples=8)) == identity(fixed)
    assert "marker_adaptive_threshold" not in fixed.to_dict()["render"]          # ids of before the keys
    assert _cfg(marker_samples=2).render.marker_adaptive_min_samples == 2
    on = _cfg(marker_adaptive_min_samples=8)
    assert identity(on) != identity(plain)
    assert render_settings(on.render).marker_adaptive_min_samples == 8
    assert render_settings(plain.render).marker_adaptive_threshold == 0.02
    assert "marker_adaptive_min_samples" not in to_dict(render_settings(fixed.render))
    assert "marker_adaptive_threshold" not in to_dict(render_settings(off.render))
    assert config_from_identity(json.loads(on.canonical_json())) == on


@pytest.mark.parametrize("key, value", [("marker_samples", -1), ("marker_samples", 1 << 25),
                                        ("marker_denoise", "oidn"), ("marker_adaptive_threshold", -0.01),
                                        ("marker_adaptive_min_samples", -1), ("marker_adaptive_min_samples", 1 << 25)])
def test_bad_values_are_refused_naming_the_key(key, value):
    with pytest.raises(ConfigError, match=key):
        _cfg(**{key: value})


def test_a_stored_identity_without_the_key_reads_back_off():
    """A dataset.json written while the key was off (or before it existed) leaves it out: read
    back, it is off, not today's default; a written config states it, so it reads back too."""
    off = _cfg(marker_samples=0)
    stored = json.loads(off.canonical_json())
    assert config_from_dict(stored).render.marker_samples == 40        # a config file's reading
    assert config_from_identity(stored) == off                         # a stored identity's
    assert config_from_identity(json.loads(_cfg().canonical_json())) == _cfg()
    assert off.resolved_dict()["render"]["marker_samples"] == 0
    assert config_from_dict(off.resolved_dict()) == off
    assert _cfg().resolved_dict() == _cfg().to_dict()                 # at the defaults: the identity


def test_a_config_set_off_writes_a_text_that_reads_back_off(tmp_path):
    src = tmp_path / "c.toml"
    src.write_text('[dataset]\nframes = 4\nseed = 3\n')
    cfg, text = load_config_text(src, ["render.marker_samples=0"])
    assert cfg.render.marker_samples == 0
    again = tmp_path / "again.toml"
    again.write_text(text)
    assert load_config(again) == cfg and cfg.canonical_json() == load_config(again).canonical_json()


def test_the_light_tree_is_in_the_identity_only_where_it_renders():
    """``light_tree = "markers"`` (the default) without label-aware sampling renders as off: the
    config reads back off and its identity is that of before the key; with the crops it is in the
    identity, and the frames' render settings carry it."""
    assert _cfg().render.light_tree == "markers" and "light_tree" in _cfg().to_dict()["render"]
    no_crops = _cfg(marker_samples=0)
    assert no_crops.render.light_tree == "off" and "light_tree" not in no_crops.to_dict()["render"]
    assert identity(no_crops) == identity(_cfg(marker_samples=0, light_tree="off"))
    assert identity(_cfg(light_tree="off")) != identity(_cfg())
    assert identity(_cfg(light_tree="on")) != identity(_cfg())
    assert config_from_identity(json.loads(_cfg().canonical_json())) == _cfg()
    assert render_settings(_cfg().render).light_tree == "markers"
    assert render_settings(no_crops.render).light_tree == "off"
    assert "light_tree" not in to_dict(render_settings(no_crops.render))     # label bytes of before


def test_a_light_tree_value_not_known_is_refused_naming_the_key():
    with pytest.raises(ConfigError, match=r"\[render\] light_tree.*'always'"):
        _cfg(light_tree="always")


def test_the_coverage_correction_is_on_by_default_and_stored_off_without_crops():
    """``marker_coverage_samples`` (default 128) is in the identity and the labels' render settings
    while label-aware sampling is on; without it the config reads back 0 and leaves the key out
    (the identity and the label bytes of before the key)."""
    assert _cfg().render.marker_coverage_samples == 128
    assert _cfg().to_dict()["render"]["marker_coverage_samples"] == 128
    assert identity(_cfg(marker_coverage_samples=0)) != identity(_cfg())
    assert "marker_coverage_samples" not in _cfg(marker_coverage_samples=0).to_dict()["render"]
    no_crops = _cfg(marker_samples=0)
    assert no_crops.render.marker_coverage_samples == 0
    assert "marker_coverage_samples" not in no_crops.to_dict()["render"]
    assert identity(no_crops) == identity(_cfg(marker_samples=0, marker_coverage_samples=0))
    for cfg in (_cfg(), no_crops, _cfg(marker_coverage_samples=256)):
        assert config_from_identity(json.loads(cfg.canonical_json())) == cfg
        assert config_from_dict(cfg.resolved_dict()) == cfg
    assert to_dict(render_settings(_cfg().render))["marker_coverage_samples"] == 128
    assert "marker_coverage_samples" not in to_dict(render_settings(no_crops.render))


@pytest.mark.parametrize("value, message", [(-1, "marker_coverage_samples"), (1 << 25, "Cycles' limit")])
def test_a_coverage_sample_count_it_cannot_render_is_refused_in_one_line(value, message):
    with pytest.raises(ConfigError, match=message) as err:
        _cfg(marker_coverage_samples=value)
    assert "\n" not in str(err.value)


def test_the_coverage_threshold_is_stored_only_where_a_coverage_render_uses_it():
    """``marker_coverage_threshold`` (default 0.005: adaptive) is in the identity and the frames'
    render settings beside a coverage render; without one (no coverage samples, or no crops) it
    reads back 0 and leaves the key out: the identity and label bytes of the configs before it."""
    assert _cfg().render.marker_coverage_threshold == 0.005
    assert _cfg().to_dict()["render"]["marker_coverage_threshold"] == 0.005
    assert identity(_cfg(marker_coverage_threshold=0.0)) != identity(_cfg())
    for off in (_cfg(marker_coverage_samples=0), _cfg(marker_samples=0)):
        assert off.render.marker_coverage_threshold == 0.0
        assert "marker_coverage_threshold" not in off.to_dict()["render"]
        assert "marker_coverage_threshold" not in to_dict(render_settings(off.render))
    assert identity(_cfg(marker_coverage_samples=0)) == identity(_cfg(marker_coverage_samples=0,
                                                                       marker_coverage_threshold=0.0))
    for cfg in (_cfg(), _cfg(marker_coverage_threshold=0.003), _cfg(marker_samples=0)):
        assert config_from_identity(json.loads(cfg.canonical_json())) == cfg
        assert config_from_dict(cfg.resolved_dict()) == cfg
    assert render_settings(_cfg().render).marker_coverage_threshold == 0.005


@pytest.mark.parametrize("value", [-0.01, 1.0, 5.0])
def test_a_coverage_threshold_out_of_range_is_refused_in_one_line(value):
    with pytest.raises(ConfigError, match=r"\[render\] marker_coverage_threshold") as err:
        _cfg(marker_coverage_threshold=value)
    assert "\n" not in str(err.value)


def test_the_light_smoothing_is_stored_only_where_the_coverage_correction_uses_it():
    """``marker_light_smoothing_px`` (default 1.0) is in the identity and the frames' render
    settings beside a coverage correction; without one (no coverage samples, or no crops) it reads
    back 0 and leaves the key out: the identity and label bytes of the configs before it."""
    assert _cfg().render.marker_light_smoothing_px == 1.0
    assert _cfg().to_dict()["render"]["marker_light_smoothing_px"] == 1.0
    assert identity(_cfg(marker_light_smoothing_px=0.0)) != identity(_cfg())
    for off in (_cfg(marker_coverage_samples=0), _cfg(marker_samples=0)):
        assert off.render.marker_light_smoothing_px == 0.0
        assert "marker_light_smoothing_px" not in off.to_dict()["render"]
        assert "marker_light_smoothing_px" not in to_dict(render_settings(off.render))
    for cfg in (_cfg(), _cfg(marker_light_smoothing_px=0.5), _cfg(marker_samples=0)):
        assert config_from_identity(json.loads(cfg.canonical_json())) == cfg
        assert config_from_dict(cfg.resolved_dict()) == cfg
    assert render_settings(_cfg(marker_light_smoothing_px=1.2).render).marker_light_smoothing_px == 1.2


@pytest.mark.parametrize("value, message", [(-0.5, "marker_light_smoothing_px"), (4.5, "across a small marker")])
def test_a_light_smoothing_out_of_range_is_refused_in_one_line(value, message):
    with pytest.raises(ConfigError, match=message) as err:
        _cfg(marker_light_smoothing_px=value)
    assert "\n" not in str(err.value)
