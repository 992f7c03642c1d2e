"""Non-square pixels ([camera_units] pixel_aspect = fy / fx), without Blender: the config and its
bound, the unit's K, the lens maps that take the square-pixel render to the delivered rows, the
labels against OpenCV's projectPoints with the label's own K (1e-6 px), and a painted dataset
(tests/pipeline_data.py: the canvas painted exactly at pixel centres, then the real
post-processing) whose delivered index pass is the exact rasterisation of the labels' outlines.

NONSQUARE is LENS_CHECK (strong barrel lens, principal point off centre, aberration, JPEG) with
three units drawing fy / fx in [0.96, 1.04] (seed 5: 0.970, 0.980, 1.0065)."""
import json

import cv2
import numpy as np
import pytest
from pipeline_data import LENS_CHECK, label_vs_index, write_painted_dataset

from dockfactory.core.config import ConfigError, config_from_dict, load_config
from dockfactory.core.distortion import undistort_pixels
from dockfactory.core.geometry import transform_points
from dockfactory.core.layout import marker_outline
from dockfactory.core.scene import CameraModel, to_dict
from dockfactory.generator.camera_units import unit_lens
from dockfactory.generator.datasets import tools as dt
from dockfactory.generator.exr import RenderPasses
from dockfactory.generator.labels import frame_labels, marker_outline_px
from dockfactory.generator.motion import label_rolling_view, moving_b
from dockfactory.generator.random_draws import static_scene
from dockfactory.generator.sampler import check_focal_fits, frame_plan, sample_frame
from dockfactory.core.camera_chain import resample_passes
from dockfactory.core.camera_chain.lens import distortion_maps

NONSQUARE = LENS_CHECK.replace("frames = 4", "frames = 6").replace(
    "[camera_units]\ncount = 2\n", "[camera_units]\ncount = 3\npixel_aspect = [0.96, 1.04]\n")
STRONG = (-0.15, -0.05, 1e-3, -1e-3, 0.0)


def camera(aspect, coeffs=STRONG, aberration=(0.0, 0.0), w=1280, h=960, focal=1200.0, pp=(679.5, 440.5)):
    return CameraModel(w, h, focal, pp, tuple(map(tuple, np.eye(4))), (0.0, 0.0, 0.0), 1000.0, 0, tuple(coeffs),
                       aberration, pixel_aspect=aspect)


@pytest.fixture(scope="module")
def cfg(tmp_path_factory):
    path = tmp_path_factory.mktemp("aspect") / "aspect.toml"
    path.write_text(NONSQUARE)
    return load_config(path)


@pytest.fixture(scope="module")
def painted(tmp_path_factory):
    root = tmp_path_factory.mktemp("painted-aspect")
    (root / "c.toml").write_text(NONSQUARE)
    cfg = write_painted_dataset(root / "ds", root / "c.toml", exact=True)
    for fmt in ("coco", "bop", "cameras"):
        dt.export(root / "ds", fmt)
    return root / "ds", cfg


# ----------------------------------------------------------------------------- config and units

@pytest.mark.parametrize("value", [[0.9, 1.0], [1.0, 1.06], [1.02, 1.01]])
def test_an_aspect_beyond_the_bound_is_one_line(value):
    with pytest.raises(ConfigError) as err:
        config_from_dict({"camera_units": {"pixel_aspect": value}}, "cfg.toml")
    assert str(err.value).startswith("cfg.toml: [camera_units] pixel_aspect: ") and "\n" not in str(err.value)


def test_each_unit_draws_its_aspect_and_every_frame_has_its_k(cfg):
    aspects = [unit_lens(cfg.camera_units, cfg.dataset.seed, u).pixel_aspect for u in range(3)]
    assert min(aspects) < 0.99 and max(aspects) > 1.0 and all(0.96 <= a <= 1.04 for a in aspects)
    check_focal_fits(cfg, "aspect.toml")
    for spec in frame_plan(cfg):
        cam = sample_frame(cfg, spec).camera
        k = cam.k()
        assert cam.pixel_aspect == aspects[spec.unit] and k[0, 0] == cam.focal_px
        assert k[1, 1] == pytest.approx(cam.focal_px * aspects[spec.unit], rel=1e-15)
        assert cam.pinhole_k()[1, 1] == cam.focal_px and not cam.is_pinhole()
        assert to_dict(cam)["pixel_aspect"] == aspects[spec.unit]
    # the default is square: the key stays out of every scene record
    square = sample_frame(config_from_dict({}), frame_plan(config_from_dict({}))[0]).camera
    assert square.pixel_aspect == 1.0 and "pixel_aspect" not in to_dict(square)


# ----------------------------------------------------------------------------- the lens maps

@pytest.mark.parametrize("aspect", [0.96, 1.0037, 1.05])
@pytest.mark.parametrize("coeffs", [STRONG, (0.0,) * 5])
def test_the_map_is_the_exact_inverse_with_the_aspect(coeffs, aspect):
    """Every delivered pixel's map entry is the square-pixel render position undistort_pixels gives
    (5e-4 px, as for square pixels), and it lies inside the canvas; cv2.projectPoints with the
    camera's K takes it back to the pixel (1e-6 px)."""
    cam = camera(aspect, coeffs)
    mx, my = distortion_maps(cam)
    ox, oy, wc, hc = cam.canvas()
    ys, xs = np.mgrid[0:960:3, 0:1280:3]
    pix = np.stack([xs.ravel(), ys.ravel()], 1).astype(float)
    exact = undistort_pixels(pix, cam.focal_px, cam.principal_point, coeffs, aspect)
    got = np.stack([mx[ys, xs].ravel() + ox, my[ys, xs].ravel() + oy], 1)
    assert np.abs(got - exact).max() < 5e-4
    assert mx.min() >= 1 and my.min() >= 1 and mx.max() <= wc - 2 and my.max() <= hc - 2
    rays = np.c_[(exact - cam.principal_point) / cam.focal_px, np.ones(len(exact))]
    back, _ = cv2.projectPoints(rays, np.zeros(3), np.zeros(3), cam.k(), np.array(coeffs))
    assert np.abs(back.reshape(-1, 2) - pix).max() < 1e-6


def test_resampling_a_ramp_lands_each_pixel_on_its_square_source():
    """A linear ramp painted on the canvas (square pixels) comes back at each delivered pixel's
    exact source, rows included (cv2.remap's 1/32 px steps), with no distortion as well."""
    for coeffs in (STRONG, (0.0,) * 5):
        cam = camera(1.03, coeffs, aberration=(0.25, -0.25), w=320, h=240, focal=330.0, pp=(165.2, 115.7))
        ox, oy, wc, hc = cam.canvas()
        ys, xs = np.mgrid[0:hc, 0:wc].astype(np.float32)
        ramp = np.dstack([xs + ox, ys + oy, 0.5 * (xs + ox)])
        out = resample_passes(RenderPasses(ramp, np.ones((hc, wc), np.float32), np.zeros((hc, wc), np.int32)), cam)
        py, px = np.mgrid[0:240, 0:320]
        src = undistort_pixels(np.stack([px.ravel(), py.ravel()], 1).astype(float), 330.0, cam.principal_point,
                               coeffs, 1.03)
        assert np.abs(out.rgb[..., 1].ravel() - src[:, 1]).max() < 1 / 32 + 1e-3


# ----------------------------------------------------------------------------- labels

def test_labels_are_opencvs_projection_through_the_labels_k(cfg):
    static = static_scene(cfg)
    for spec in frame_plan(cfg):
        frame = sample_frame(cfg, spec)
        cam = frame.camera
        lab = frame_labels(frame, static, None, 0.5)
        k = np.array(lab["camera"]["K"])
        assert k[1, 1] / k[0, 0] == pytest.approx(cam.pixel_aspect, rel=1e-14) and lab["camera"]["focal_px"] == k[0, 0]
        cam_from_d = cam.cam_from_d_array()
        r, _ = cv2.Rodrigues(cam_from_d[:3, :3])
        dist = np.array(lab["camera"]["distortion"])
        for m, rec in zip(static.markers, lab["markers"]):
            centre = np.array([rec["center_d_mm"]])
            uv, _ = cv2.projectPoints(centre, r, cam_from_d[:3, 3], k, dist)
            assert np.abs(uv.ravel() - rec["center_px"]).max() < 1e-6
            ideal, _ = cv2.projectPoints(centre, r, cam_from_d[:3, 3], k, np.zeros(5))   # K alone
            assert np.abs(ideal.ravel() - rec["center_pinhole_px"]).max() < 1e-6
            cam_from_s = cam_from_d @ (frame.d_from_b_array() if m.section == "B" else np.eye(4))
            outline, _ = marker_outline_px(m, k, cam.distortion, cam_from_s)
            assert np.allclose(rec["bbox_unclipped_px"], [*outline.min(0), *outline.max(0)])
            ring, _ = cv2.projectPoints(transform_points(cam_from_s, marker_outline(m)), np.zeros(3), np.zeros(3),
                                        k, dist)
            assert np.abs(ring.reshape(-1, 2) - outline).max() < 1e-6


def test_a_rolling_shutter_reprojects_from_the_label_as_it_was_labelled(cfg):
    """Consumers of a label (exports) rebuild B's rolling-shutter view from the label's K: the
    same square-pixel render camera the labels used."""
    data = {"motion": {"enabled": True, "velocity_mm_s": [100.0, 300.0], "rolling_shutter_ms": 20.0},
            "camera_units": {"pixel_aspect": [1.03, 1.03]}, "dataset": {"frames": 2}}
    c = config_from_dict(data)
    for spec in frame_plan(c):
        frame = sample_frame(c, spec)
        label = frame_labels(frame, static_scene(c), None, 0.5)
        mb, again = moving_b(frame), label_rolling_view(label)
        assert mb.k[1, 1] == mb.k[0, 0] == frame.camera.focal_px
        assert np.array_equal(again.k, mb.k) and again.row_offset == mb.row_offset


# ----------------------------------------------------------------------------- a painted dataset

def test_painted_non_square_frames_match_their_labels(painted):
    """The delivered index pass (the square-pixel canvas painted exactly at pixel centres,
    resampled by finish_frame) is the exact rasterisation of every marker's outline in the
    label's camera, and its centroid is within 0.25 px of the label's centre."""
    root, c = painted
    got = label_vs_index(root, c)
    assert got["markers"] >= 60 and got["pixels"] > 8000 and len(got["centre_err"]) >= 30
    assert got["mismatch"] == 0, f"{got['mismatch']} of {got['pixels']} marker pixels differ"
    assert got["centre_err"].max() < 0.25 and got["centroid_err"].max() < 0.25
    for p in (root / "labels").glob("*.json"):   # sections: the silhouette through the lens and the aspect
        for sec in json.loads(p.read_text())["sections"]:
            assert abs(sec["pixels_visible"] - sec["pixels_all"]) < 0.01 * sec["pixels_all"]


def test_exports_carry_fx_and_fy(painted):
    root, _ = painted
    labels = {p.stem: json.loads(p.read_text()) for p in (root / "labels").glob("*.json")}
    coco = json.loads(next((root / "exports" / "coco" / "annotations").glob("*.json")).read_text())
    for ann in coco["annotations"]:   # the polygon is the outline in the non-square image: the label's box
        lab = labels[next(i["frame_id"] for i in coco["images"] if i["id"] == ann["image_id"])]
        rec = next(m for m in lab["markers"] if m["id"] == ann["marker_id"])
        poly = np.array(ann["segmentation"][0]).reshape(-1, 2) - 0.5
        assert np.allclose([*poly.min(0), *poly.max(0)], rec["bbox_px"], atol=0.03)
    for split_dir in (root / "exports" / "bop").iterdir():
        if (split_dir / "000000").is_dir():
            cams = json.loads((split_dir / "000000" / "scene_camera.json").read_text())
            ids = json.loads((split_dir / "000000" / "frame_ids.json").read_text())
            for im, fid in ids.items():
                k = np.array(cams[im]["cam_K"]).reshape(3, 3)
                assert k[1, 1] == labels[fid]["camera"]["K"][1][1] != k[0, 0]
    bop = json.loads((root / "exports" / "bop" / "camera.json").read_text())
    assert bop["fy"] == pytest.approx(bop["fx"])   # the config's mean aspect: 1.0 for [0.96, 1.04]


def test_the_true_camera_reference_and_the_video_lines_take_the_aspect(cfg):
    """eval's true-camera reference undistorts a label's centres onto the square-pixel pinhole at
    fx (where the solver's single focal is fx; 1e-6 px), and a video line names a non-square
    camera's fy / fx (a square one's line has no such key)."""
    from dockfactory.eval.solve_frames import true_camera_centres
    from dockfactory.generator.exports.video import frame_label
    static = static_scene(cfg)
    for spec in frame_plan(cfg)[:3]:
        frame = sample_frame(cfg, spec)
        label = frame_labels(frame, static, None, 0.5)
        k = np.array(label["camera"]["K"])
        uv = np.array([m["center_px"] for m in label["markers"] if m["in_frame"]])
        centres_d = np.array([m["center_d_mm"] for m in label["markers"] if m["in_frame"]])
        _, (_, ideal, _, _) = true_camera_centres(label, (None, uv, None, None))
        want, _ = cv2.projectPoints(transform_points(frame.camera.cam_from_d_array(), centres_d), np.zeros(3),
                                    np.zeros(3), frame.camera.pinhole_k(), np.zeros(5))
        assert np.abs(ideal - want.reshape(-1, 2)).max() < 1e-6
        assert frame_label(0, label)["pixel_aspect"] == k[1, 1] / k[0, 0]
    square = frame_labels(sample_frame(config_from_dict({}), frame_plan(config_from_dict({}))[0]),
                          static_scene(config_from_dict({})), None, 0.5)
    assert "pixel_aspect" not in frame_label(0, square)
