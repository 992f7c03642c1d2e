"""Camera units and docking runs (issue 11, part 1), without Blender: the config, the plan, the
lens (render canvas, exact distortion maps, chromatic aberration, JPEG), the labels through the
lens, and a painted dataset through the real post-processing (tests/pipeline_data.py).

Figures these tests pin (LENS_CHECK, 4 frames, 2 units, k1 -0.15 .. -0.1, painted exactly at
pixel centres): the delivered index pass equals the exact rasterisation of the distorted
outlines (0 of ~7,500 marker pixels differ); plain nearest resampling would differ in ~420 of
them (5.5 %, all within 0.75 px of the outline) and move centroids by up to 0.52 px.
"""
import collections
import dataclasses
import json

import cv2
import numpy as np
import pytest
from pipeline_data import LENS_CHECK, label_vs_index, painted_passes, write_painted_dataset

from dockfactory.core.config import ConfigError, config_from_dict, load_config
from dockfactory.core.distortion import distort_pixels, undistort_pixels
from dockfactory.core.geometry import blender_camera_intrinsics, pose_components, render_canvas
from dockfactory.core.resources import shipped_config
from dockfactory.core.scene import CameraModel, to_dict
from dockfactory.generator.datasets import tools as dt
from dockfactory.generator.camera_units import ImageFit, largest_fitting_focal, unit_lens, unit_sensor
from dockfactory.generator.random_draws import markers_in_d, static_scene
from dockfactory.generator.labels import frame_labels, marker_outline_px, marker_pinhole_outlines
from dockfactory.generator.sampler import check_focal_fits, frame_plan, sample_frame
from dockfactory.core.camera_chain import jpeg_round_trip, resample_passes
from dockfactory.core.camera_chain.lens import channel_maps, distortion_maps

STRONG = (-0.15, -0.05, 1e-3, -1e-3, 0.0)


def camera(coeffs=STRONG, pp=(679.5, 440.5), focal=1200.0, aberration=(0.0, 0.0), w=1280, h=960):
    return CameraModel(w, h, focal, pp, tuple(map(tuple, np.eye(4))), (0.0, 0.0, 0.0), 1000.0, 0,
                       tuple(coeffs), aberration)


@pytest.fixture(scope="module")
def lens_cfg(tmp_path_factory):
    path = tmp_path_factory.mktemp("lens") / "lens.toml"
    path.write_text(LENS_CHECK)
    return path, load_config(path)


@pytest.fixture(scope="module")
def painted_lens(lens_cfg, tmp_path_factory):
    """LENS_CHECK painted exactly at pixel centres through finish_frame (exports written)."""
    path, _ = lens_cfg
    root = tmp_path_factory.mktemp("painted-lens") / "ds"
    cfg = write_painted_dataset(root, path, exact=True)
    for fmt in ("coco", "bop"):
        dt.export(root, fmt)
    return root, cfg


# ----------------------------------------------------------------------------- config and plan

def test_defaults_are_one_ideal_unit_without_runs():
    cfg = config_from_dict({})
    assert cfg.camera_units.count == 1 and cfg.runs.frames_per_run == 0
    lens = unit_lens(cfg.camera_units, cfg.dataset.seed, 0)
    assert lens.is_ideal() and lens.aberration_px == (0.0, 0.0) and lens.f_number == 0 and lens.jpeg_quality == 0
    cam = sample_frame(cfg, frame_plan(cfg)[0]).camera
    assert cam.is_pinhole() and cam.canvas() == (0, 0, 1280, 960)
    assert cam.principal_point == (639.5, 479.5)


@pytest.mark.parametrize("table, data, key", [
    ("camera_units", {"count": 0}, "count"),
    ("camera_units", {"count": 101}, "count"),
    ("camera_units", {"k1": [-1.5, 0.0]}, "k1"),
    ("camera_units", {"k3": [0.0, 2.0]}, "k3"),
    ("camera_units", {"p2": [-0.1, 0.0]}, "p2"),
    ("camera_units", {"p1": [0.001, -0.001]}, "p1"),
    ("camera_units", {"principal_offset_x_px": [-400, 0]}, "principal_offset_x_px"),
    ("camera_units", {"aberration_red_px": [0, 6]}, "aberration_red_px"),
    ("camera_units", {"f_number": [0.1, 2]}, "f_number"),
    ("camera_units", {"focus_error_mm": [-600, 0]}, "focus_error_mm"),
    ("camera_units", {"jpeg_quality": [0, 90]}, "jpeg_quality"),
    ("camera_units", {"jpeg_quality": [95, 85]}, "jpeg_quality"),
    ("camera_units", {"sensor_width_mm": 1.0}, "sensor_width_mm"),
    ("camera_units", {"jpeg": "yes"}, "jpeg"),
    ("camera_units", {"k4": [0, 0]}, "k4"),
    ("runs", {"frames_per_run": 1}, "frames_per_run"),
    ("runs", {"frames_per_run": -2}, "frames_per_run"),
    ("runs", {"x_end_mm": [1, 150]}, "x_end_mm"),
    ("runs", {"x_end_mm": [-1, 3]}, "x_end_mm"),
])
def test_bad_camera_unit_and_run_values_name_file_table_and_key(table, data, key):
    with pytest.raises(ConfigError) as err:
        config_from_dict({table: data}, "cfg.toml")
    msg = str(err.value)
    assert msg.startswith("cfg.toml: [") and key in msg and "\n" not in msg


def test_a_folding_lens_is_refused_by_the_feasibility_check():
    cfg = config_from_dict({"camera_units": {"k1": [-0.9, -0.9]}, "camera": {"focal_px": [700, 3000]}})
    with pytest.raises(ConfigError, match=r"^x.toml: \[camera_units\] k1: camera unit 0 .*(monotone|folds over|times)"):
        check_focal_fits(cfg, "x.toml")


def test_frames_are_dealt_to_units_and_repeatability_stays_on_one():
    cfg = config_from_dict({"dataset": {"frames": 101}, "repeatability": {"poses": 3, "captures": 4},
                            "camera_units": {"count": 3, "k1": [-0.1, 0.05], "principal_offset_x_px": [-30, 30]}})
    plan = frame_plan(cfg)
    counts = collections.Counter(s.unit for s in plan if s.kind == "main")
    assert sorted(counts.values()) == [33, 34, 34]
    assert len({s.unit for s in plan if s.kind == "repeat"}) == 1
    lenses = {u: unit_lens(cfg.camera_units, cfg.dataset.seed, u) for u in range(3)}
    assert len({lens.distortion for lens in lenses.values()}) == 3
    for spec in plan[:30]:   # a frame's lens is its unit's, whatever the frame
        cam = sample_frame(cfg, spec).camera
        assert cam.unit == spec.unit and cam.distortion == lenses[spec.unit].distortion
    assert frame_plan(cfg) == plan


def test_runs_fix_the_camera_per_unit_and_approach_smoothly():
    cfg = load_config(shipped_config("realistic"))
    plan = frame_plan(cfg)
    frames = {s.frame_id: sample_frame(cfg, s) for s in plan}
    by_run = collections.defaultdict(list)
    for s in plan:
        if s.run >= 0:
            by_run[s.run].append(frames[s.frame_id])
    assert len(by_run) == 4 and all(len(v) == 20 for v in by_run.values())
    cams = collections.defaultdict(set)
    for f in frames.values():
        cams[f.camera.unit].add((f.camera.cam_from_d, f.camera.focal_px, f.camera.principal_point))
    assert sorted(cams) == [0, 1] and all(len(v) == 1 for v in cams.values())   # pose and zoom per unit
    for run in by_run.values():
        assert len({f.spec.condition for f in run}) == 1 and len({f.spec.split for f in run}) == 1
        assert len({f.appearance for f in run}) == 1 and len({f.lights for f in run}) == 1
        pose = np.array([list(pose_components(f.d_from_b_array()).values()) for f in run])
        assert pose[0, 0] == pytest.approx(cfg.pose.x_mm[1]) and cfg.runs.x_end_mm[0] <= pose[-1, 0] <= cfg.runs.x_end_mm[1]
        assert np.all(np.diff(pose[:, 0]) < 0)
        for i, key in enumerate(("y_mm", "z_mm", "alpha_deg", "beta_deg", "gamma_deg"), start=1):
            lo, hi = getattr(cfg.pose, key)
            assert np.all((pose[:, i] >= lo) & (pose[:, i] <= hi))
            assert np.abs(np.diff(pose[:, i], 2)).max() < 0.1 * (hi - lo)   # smooth: small second differences
    splits = collections.Counter((s.unit, s.split) for s in plan if s.kind == "main")
    assert splits == {(0, "train"): 20, (0, "test"): 20, (1, "train"): 20, (1, "test"): 20}
    # frame i is a function of (config, seed, i): alone, or after any other frame
    for s in reversed(plan[::7]):
        assert to_dict(sample_frame(cfg, s)) == to_dict(frames[s.frame_id])
    check_focal_fits(cfg, "realistic.toml")


def test_realistic_config_has_the_issue_ranges():
    cfg = load_config(shipped_config("realistic"))
    u = cfg.camera_units
    assert u.count >= 2 and cfg.runs.frames_per_run > 0
    assert u.principal_offset_x_px == u.principal_offset_y_px == (-40.0, 40.0)
    assert u.k1 == (-0.15, 0.05) and u.k2 == (-0.05, 0.05) and u.p1 == u.p2 == (-1e-3, 1e-3)
    assert u.aberration_red_px == u.aberration_blue_px == (-0.3, 0.3)
    assert u.depth_of_field and u.jpeg and u.jpeg_quality == (85, 95)
    assert (cfg.image.width, cfg.image.height) == (1280, 960)
    spec = frame_plan(cfg)[0]
    frame = sample_frame(cfg, spec)
    lens = unit_lens(cfg.camera_units, cfg.dataset.seed, spec.unit)
    cam = frame_labels(frame, static_scene(cfg), None, 0.5)["camera"]
    dof = cam["depth_of_field"]
    assert 2.8 <= dof["f_number"] <= 5.6 and dof["focus_distance_mm"] == pytest.approx(cam["distance_mm"] + lens.focus_error_mm)
    assert dof["focal_mm"] == pytest.approx(cam["focal_px"] * 8.8 / 1280) and dof["aperture_mm"] == pytest.approx(dof["focal_mm"] / dof["f_number"])
    assert 85 <= cam["jpeg_quality"] <= 95 and cam["render_canvas"]["width"] >= 1280 - 100
    # a Bayer sensor with a published preset behind an ISP in each unit, one frame's chain in its label
    assert [unit_sensor(cfg.sensor, cfg.dataset.seed, u).preset for u in range(2)] == ["imx273", "imx174"]
    assert frame.sensor.chain.cfa == ("RGGB", "BGGR")[spec.unit]
    assert frame_labels(frame, static_scene(cfg), None, 0.5)["sampled"]["sensor"]["chain"]["cfa"] == frame.sensor.chain.cfa


@pytest.mark.parametrize("extra", [{"principal_offset_x_px": [-40, 40]}, {"pixel_aspect": [0.95, 1.05]}],
                         ids=["square", "pixel-aspect"])
def test_focal_cap_through_the_lens_is_exact(extra):
    """At the largest fitting focal the outermost distorted marker corner is exactly margin_px
    inside the image (its rows at fy = aspect fx); ideal lenses keep the closed form of the pinhole."""
    cfg = config_from_dict({"camera_units": {"k1": [-0.15, 0.05], "principal_offset_y_px": [-40, 40], "count": 4,
                                             **extra}})
    static = static_scene(cfg)
    for spec in frame_plan(cfg)[:8]:
        frame = sample_frame(cfg, spec)
        lens = unit_lens(cfg.camera_units, cfg.dataset.seed, spec.unit)
        pts = markers_in_d(static, frame.d_from_b_array())
        cap = largest_fitting_focal(ImageFit.of(cfg), frame.camera.cam_from_d_array(), pts, lens)
        pc = (frame.camera.cam_from_d_array()[:3, :3] @ pts.T).T + frame.camera.cam_from_d_array()[:3, 3]
        r = cfg.markers.diameter_mm / 2
        corners = np.concatenate([(pc[:, :2] + r * np.array(s)) / pc[:, 2:] for s in ((1, 1), (1, -1), (-1, 1), (-1, -1))])
        pp = np.array(frame.camera.principal_point)
        uv = distort_pixels(corners * cap + pp, cap, pp, lens.distortion, lens.pixel_aspect)
        room = np.concatenate([uv.min(0) + 0.5, np.array([1280, 960]) - 0.5 - uv.max(0)]) - cfg.camera.margin_px
        assert room.min() == pytest.approx(0.0, abs=1e-6)


# ----------------------------------------------------------------------------- lens maths

def test_canvas_holds_every_source_and_is_the_image_for_a_pinhole():
    assert camera(coeffs=(0, 0, 0, 0, 0)).canvas() == (0, 0, 1280, 960)
    for coeffs in (STRONG, (0.05, 0.05, -1e-3, 1e-3, 0.0), (-0.15, 0.05, 0, 0, 0.02)):
        cam = camera(coeffs, aberration=(0.3, -0.3))
        ox, oy, wc, hc = cam.canvas()
        for mx, my in channel_maps(cam):
            assert mx.min() >= 1 and my.min() >= 1 and mx.max() <= wc - 2 and my.max() <= hc - 2
    ox, oy, wc, hc = camera(STRONG).canvas()
    assert (wc * hc) / (1280 * 960) == pytest.approx(1.27, abs=0.02)   # the overscan of a strong barrel lens at 1200 px
    with pytest.raises(ValueError, match="monotone|folds over"):
        render_canvas(1280, 960, 700.0, (639.5, 479.5), (-0.9, 0, 0, 0, 0))
    with pytest.raises(ValueError, match="monotone|folds over"):
        render_canvas(1280, 960, 1200.0, (639.5, 479.5), (-0.6, 0, 0, 0, 0))


@pytest.mark.parametrize("coeffs, focal", [(STRONG, 1200.0), ((0.05, 0.05, -1e-3, 1e-3, 0.0), 1200.0),
                                           ((-0.15, 0.05, 1e-3, 1e-3, 0.0), 3000.0)])
def test_distortion_map_is_the_exact_inverse(coeffs, focal):
    """Every delivered pixel's map entry is the Newton-exact undistorted position, to 5e-4 px
    (measured 3e-4 at the corners of the strongest lens; float32 steps are 1.2e-4 px there)."""
    cam = camera(coeffs, focal=focal)
    mx, my = distortion_maps(cam)
    ox, oy, _, _ = cam.canvas()
    ys, xs = np.mgrid[0:960:3, 0:1280:3]
    exact = undistort_pixels(np.stack([xs.ravel(), ys.ravel()], 1).astype(float), focal, cam.principal_point, coeffs)
    got = np.stack([mx[ys, xs].ravel() + ox, my[ys, xs].ravel() + oy], 1)
    assert np.abs(got - exact).max() < 5e-4
    # and distorting the source gives the pixel back (OpenCV's model: cv2.projectPoints agrees)
    k = cam.k()
    back, _ = cv2.projectPoints(np.c_[(exact - k[:2, 2]) / focal, np.ones(len(exact))], np.zeros(3), np.zeros(3), k,
                                np.array(coeffs))
    assert np.abs(back.reshape(-1, 2) - np.stack([xs.ravel(), ys.ravel()], 1)).max() < 1e-6


def test_chromatic_aberration_magnifies_red_and_blue_about_the_principal_point():
    cam = camera((0, 0, 0, 0, 0), aberration=(0.3, -0.2))
    (rx, ry), (gx, gy), (bx, by) = channel_maps(cam)
    ox, oy, _, _ = cam.canvas()
    corner = np.array([1279, 959])
    pp = np.array(cam.principal_point)
    shift = lambda mx, my: np.hypot(mx[959, 1279] + ox - corner[0], my[959, 1279] + oy - corner[1])   # noqa: E731
    # the red image is larger by 0.3 px at the farthest corner: the red channel of the corner pixel
    # shows what lies 0.3 px nearer the centre (minus the half-pixel from corner to pixel centre)
    r = cam.corner_radius_px()
    dist = np.hypot(*(corner - pp))
    assert shift(gx, gy) == pytest.approx(0.0, abs=1e-4)
    assert shift(rx, ry) == pytest.approx(0.3 * dist / r, abs=1e-3)
    assert shift(bx, by) == pytest.approx(0.2 * dist / r, abs=1e-3)
    assert np.hypot(rx[959, 1279] + ox - pp[0], ry[959, 1279] + oy - pp[1]) < dist


def test_resampling_a_linear_image_is_exact_to_the_remap_step():
    """A linear ramp painted on the canvas comes back as the ramp at each pixel's exact source
    (bilinear is exact on it; cv2.remap quantises positions to 1/32 px)."""
    cam = camera(STRONG, aberration=(0.25, -0.25), w=320, h=240, focal=330.0, pp=(165.2, 115.7))
    ox, oy, wc, hc = cam.canvas()
    ys, xs = np.mgrid[0:hc, 0:wc].astype(np.float32)
    ramp = np.dstack([xs + ox, ys + oy, 0.5 * (xs + ox) + 0.25 * (ys + oy)])
    from dockfactory.generator.exr import RenderPasses
    out = resample_passes(RenderPasses(ramp, np.ones((hc, wc), np.float32), np.zeros((hc, wc), np.int32)), cam)
    py, px = np.mgrid[0:240, 0:320]
    src = undistort_pixels(np.stack([px.ravel(), py.ravel()], 1).astype(float), cam.focal_px, cam.principal_point, STRONG)
    pp = np.array(cam.principal_point)
    scales = cam.channel_scales()
    want_r = (pp + (src - pp) / scales[0])[:, 0]
    want_g = src[:, 1]
    assert np.abs(out.rgb[..., 0].ravel() - want_r).max() < 1 / 32 + 1e-3
    assert np.abs(out.rgb[..., 1].ravel() - want_g).max() < 1 / 32 + 1e-3


def test_jpeg_round_trip_is_deterministic_and_lossy():
    rng = np.random.default_rng(1)
    image = cv2.GaussianBlur(rng.integers(0, 256, (96, 128, 3), dtype=np.uint8), (5, 5), 1.5)
    a, b = jpeg_round_trip(image, 85), jpeg_round_trip(image, 85)
    assert a.tobytes() == b.tobytes() and a.shape == image.shape and a.dtype == np.uint8
    err85 = np.abs(a.astype(int) - image).mean()
    err95 = np.abs(jpeg_round_trip(image, 95).astype(int) - image).mean()
    assert 0 < err95 < err85 < 8


def test_blender_shift_puts_the_principal_point_where_k_has_it():
    """Blender's shift moves the view window: a principal point right of and below the centre
    needs a negative shift_x and a positive shift_y (pinned by the render test of distorted
    frames, whose units have their principal point off centre)."""
    intr = blender_camera_intrinsics(1000.0, (659.5, 489.5), 1280, 960)
    assert intr["shift_x"] == pytest.approx(-20 / 1280) and intr["shift_y"] == pytest.approx(10 / 1280)


# ----------------------------------------------------------------------------- labels

def test_labels_go_through_the_lens_analytically(lens_cfg):
    _, cfg = lens_cfg
    static = static_scene(cfg)
    for spec in frame_plan(cfg):
        frame = sample_frame(cfg, spec)
        cam = frame.camera
        lab = frame_labels(frame, static, None, 0.5)
        assert lab["camera"]["distortion"] == list(cam.distortion) and lab["camera"]["unit"] == spec.unit
        assert lab["camera"]["distortion_names"] == ["k1", "k2", "p1", "p2", "k3"]
        k = np.array(lab["camera"]["K"])
        assert k[0, 2] == cam.principal_point[0] and k[1, 2] == cam.principal_point[1]
        r, _ = cv2.Rodrigues(cam.cam_from_d_array()[:3, :3])
        for m, rec in zip(static.markers, lab["markers"]):
            # the centre: OpenCV's projectPoints with the label's K and distortion
            uv, _ = cv2.projectPoints(np.array([rec["center_d_mm"]]), r, cam.cam_from_d_array()[:3, 3], k,
                                      np.array(lab["camera"]["distortion"]))
            assert np.allclose(uv.ravel(), rec["center_px"], atol=1e-6)
            outline, _ = marker_outline_px(m, k, cam.distortion,
                                           cam.cam_from_d_array() @ (frame.d_from_b_array() if m.section == "B" else np.eye(4)))
            assert np.allclose(rec["bbox_unclipped_px"], [*outline.min(0), *outline.max(0)])
            assert np.linalg.norm(np.subtract(rec["outline_centroid_px"], rec["center_px"])) < 0.1
            # the pinhole projection is where K alone puts it
            assert np.allclose(distort_pixels(np.array([rec["center_pinhole_px"]]), cam.focal_px, cam.principal_point,
                                              cam.distortion)[0], rec["center_px"])


def test_painted_distorted_frames_match_their_labels(painted_lens):
    """The label-vs-pixels check on distorted frames (painted exactly at pixel centres, resampled
    by finish_frame): the delivered index pass is the exact rasterisation of each marker's
    distorted outline, and its centroid is within 0.25 px of the label's centre."""
    root, cfg = painted_lens
    got = label_vs_index(root, cfg)
    assert got["markers"] >= 40 and got["pixels"] > 5000 and len(got["centre_err"]) >= 20
    assert got["mismatch"] == 0, f"{got['mismatch']} of {got['pixels']} marker pixels differ"
    assert got["centre_err"].max() < 0.25 and got["centroid_err"].max() < 0.25
    # sections: the silhouette through the lens (a region no longer convex) against the painted hull
    for p in (root / "labels").glob("*.json"):
        for sec in json.loads(p.read_text())["sections"]:
            assert abs(sec["pixels_visible"] - sec["pixels_all"]) < 0.01 * sec["pixels_all"]
            assert np.allclose(sec["bbox_obj_px"], sec["bbox_visible_px"], atol=1.0)


def test_plain_nearest_resampling_differs_only_at_the_boundary(lens_cfg):
    """Without the exact edges, nearest resampling tests the source pixel nearest to each
    delivered pixel's source: the pixels it gets wrong lie within 0.75 px of the outline (in the
    source), about 5 % of the marker pixels, and they move centroids coherently by up to half a
    pixel (why the index pass's marker edges are decided by the exact outline)."""
    _, cfg = lens_cfg
    static = static_scene(cfg)
    wrong = total = 0
    for spec in frame_plan(cfg):
        frame = sample_frame(cfg, spec)
        cam = frame.camera
        canvas = painted_passes(frame, static, exact=True)
        plain = resample_passes(canvas, cam).index
        refined = resample_passes(canvas, cam, marker_pinhole_outlines(frame, static)).index
        mx, my = distortion_maps(cam)
        ox, oy, _, _ = cam.canvas()
        outlines = dict(marker_pinhole_outlines(frame, static))
        for value, poly in outlines.items():
            diff = (plain == value) != (refined == value)
            total += int((refined == value).sum())
            wrong += int(diff.sum())
            ys, xs = np.nonzero(diff)
            src = np.stack([mx[ys, xs] + ox, my[ys, xs] + oy], 1).astype(float)
            d = np.min(np.hypot(*(src[:, None, :] - poly[None]).transpose(2, 0, 1)), axis=1) if len(src) else np.zeros(0)
            assert np.all(d <= 0.75), d.max()
    assert 0.02 < wrong / total < 0.10


# ----------------------------------------------------------------------------- exports

def test_exports_carry_k_and_the_distortion(painted_lens):
    root, cfg = painted_lens
    labels = {p.stem: json.loads(p.read_text()) for p in (root / "labels").glob("*.json")}
    coco = json.loads(next((root / "exports" / "coco" / "annotations").glob("*.json")).read_text())
    assert set(coco["info"]["cameras"]) <= {"0", "1"} and coco["info"]["cameras"]
    for im in coco["images"]:
        cam = labels[im["frame_id"]]["camera"]
        assert im["K"] == cam["K"] and im["dist_coeffs"] == cam["distortion"] and im["camera_unit"] == cam["unit"]
        assert coco["info"]["cameras"][str(cam["unit"])]["dist_coeffs"] == cam["distortion"]
    for ann in coco["annotations"]:   # polygons are the distorted outline: their box is the label's box
        lab = labels[next(i["frame_id"] for i in coco["images"] if i["id"] == ann["image_id"])]
        rec = next(m for m in lab["markers"] if m["id"] == ann["marker_id"])
        poly = np.array(ann["segmentation"][0]).reshape(-1, 2) - 0.5
        assert np.allclose([*poly.min(0), *poly.max(0)], rec["bbox_px"], atol=0.03)
    for split_dir in (root / "exports" / "bop").iterdir():
        if not (split_dir / "000000").is_dir():
            continue
        cams = json.loads((split_dir / "000000" / "scene_camera.json").read_text())
        lens = json.loads((split_dir / "000000" / "scene_camera_lens.json").read_text())
        ids = json.loads((split_dir / "000000" / "frame_ids.json").read_text())
        for im, fid in ids.items():
            k = np.array(labels[fid]["camera"]["K"])
            assert np.allclose(np.array(cams[im]["cam_K"]).reshape(3, 3), k + [[0, 0, 0.5], [0, 0, 0.5], [0, 0, 0]])
            assert lens[im]["dist_coeffs"] == labels[fid]["camera"]["distortion"]
            assert lens[im]["camera_unit"] == labels[fid]["camera"]["unit"]


def test_delivered_images_are_jpeg_decoded(painted_lens):
    root, cfg = painted_lens
    for p in (root / "labels").glob("*.json"):
        lab = json.loads(p.read_text())
        assert 85 <= lab["camera"]["jpeg_quality"] <= 95
        image = cv2.imread(str(root / "images" / f"{lab['frame_id']}.png"))
        # a flat painted image through JPEG: 8x8 block artefacts leave values the painter never used
        assert len(np.unique(image.reshape(-1, 3), axis=0)) > 20


def test_a_pinhole_frame_keeps_its_bytes_path(tmp_path):
    """A pinhole unit's render is its delivered image: no resampling, the same passes object."""
    cfg = config_from_dict({"image": {"width": 64, "height": 48}, "camera": {"focal_px": [40, 60], "margin_px": 2},
                            "camera_units": {"principal_offset_x_px": [3, 3]}, "dataset": {"frames": 1}})
    frame = sample_frame(cfg, frame_plan(cfg)[0])
    assert frame.camera.is_pinhole() and frame.camera.principal_point == (34.5, 23.5)
    passes = painted_passes(frame, static_scene(cfg))
    assert resample_passes(passes, frame.camera) is passes
    assert dataclasses.replace(frame.camera, distortion=(-0.02, 0, 0, 0, 0)).canvas() != (0, 0, 64, 48)
