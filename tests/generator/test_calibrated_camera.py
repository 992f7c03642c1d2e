"""A calibration file in the factory (core.config_calibration) and every frame's true camera out
(generator.exports.cameras), without Blender: a config naming a calibration file renders that
camera (the file's image size, fx and fy, principal point and lens on every frame), the dataset's
stored config reproduces it without the file, a key set twice or fy / fx beyond the bound is one
line; the cameras export is read by OpenCV's own FileStorage and COLMAP's format back to the
labels' camera (fx != fy), and cv2.projectPoints through it lands on the labels' centres (1e-6 px)."""
from __future__ import annotations

import json
import tomllib

import cv2
import numpy as np
import pytest
from pipeline_data import write_painted_dataset

from dockfactory.core.calibration_files import Calibration, CalibrationError, read_calibration, write_calibration
from dockfactory.core.config import ConfigError, config_from_dict, load_config
from dockfactory.core.config_text import load_config_text
from dockfactory.generator.datasets import tools as dt
from dockfactory.generator.datasets.reader import Dataset
from dockfactory.generator.exports.cameras import label_calibration
from dockfactory.generator.sampler import check_focal_fits, frame_plan, sample_frame
from dockfactory.generator.version import dataset_version_id

# fy / fx = 1.0037: a real calibration's focal lengths differ by 0.1-1 %
CAL = Calibration(640, 480, 700.3, 702.9, 326.3, 236.9, (-0.08, 0.05, 0.0004, -0.0003, 0.01))
SMALL = """[dataset]
name = "calibrated"
seed = 4
frames = 4
[conditions]
normal = 1
low_light = 0
occlusion = 0
glare = 0
[camera]
distance_mm = [900, 1000]
margin_px = 10
[render]
keep_exr = false
[export]
formats = []
"""


def _config(tmp_path, extra: str = "", cal: Calibration = CAL, name: str = "cam.yaml"):
    write_calibration(cal, tmp_path / name, "opencv-yaml" if name.endswith(".yaml") else "colmap")
    path = tmp_path / "c.toml"
    path.write_text(SMALL + f'[camera_units]\ncalibration = "{name}"\n' + extra)
    return path


@pytest.mark.parametrize("name", ["cam.yaml", "cameras.txt"])
def test_every_frame_is_the_calibrated_camera(tmp_path, name):
    path = _config(tmp_path, name=name)
    cfg, text = load_config_text(path)
    check_focal_fits(cfg, str(path))
    assert cfg.camera.focal_px == (CAL.fx, CAL.fx) and cfg.camera_units.pixel_aspect == (CAL.fy / CAL.fx,) * 2
    for spec in frame_plan(cfg):
        cam = sample_frame(cfg, spec).camera
        assert (cam.width, cam.height) == (640, 480)
        k = cam.k()   # the unit's K is the file's: fx and fy
        assert k[0, 0] == CAL.fx and k[1, 1] == pytest.approx(CAL.fy, rel=1e-15)
        assert cam.principal_point == pytest.approx((CAL.cx, CAL.cy), abs=1e-9)
        assert cam.distortion == pytest.approx(CAL.dist, abs=1e-15)
    assert load_config(path) == cfg   # every loader resolves it
    assert text.startswith(f"# c.toml with [camera_units] calibration = '{name}' (sha256 ")
    # the stored text reproduces the config without the file: the same version id
    (tmp_path / name).unlink()
    again = config_from_dict(tomllib.loads(text))
    assert again == cfg
    assert dataset_version_id(again.canonical_json()) == dataset_version_id(cfg.canonical_json())


@pytest.mark.parametrize("extra, message", [
    ("k1 = [-0.1, 0.0]\n", "[camera_units] k1: set by [camera_units] calibration = 'cam.yaml' too"),
    ("pixel_aspect = [1.0, 1.0]\n", "[camera_units] pixel_aspect: set by [camera_units] calibration = 'cam.yaml' too"),
    ("[camera]\nfocal_px = [600, 800]\n", None),
    ("[image]\nwidth = 1280\n", "[image] width: 1280, but the calibration file 'cam.yaml' is 640 x 480 px"),
])
def test_a_key_set_twice_is_one_line(tmp_path, extra, message):
    path = _config(tmp_path)
    if extra.startswith("[camera]"):   # SMALL already has [camera]: add the key to it
        path.write_text(path.read_text().replace("margin_px = 10\n", "margin_px = 10\nfocal_px = [600, 800]\n"))
        message = "[camera] focal_px: set by [camera_units] calibration = 'cam.yaml' too"
    else:
        path.write_text(path.read_text() + extra)
    with pytest.raises(CalibrationError) as err:
        load_config_text(path)
    assert message in str(err.value) and str(path) in str(err.value) and "\n" not in str(err.value)


def test_an_equal_image_size_a_missing_file_and_the_aspect_bound(tmp_path):
    path = _config(tmp_path, "[image]\nwidth = 640\nheight = 480\n")
    assert load_config_text(path)[0].image.width == 640
    (tmp_path / "cam.yaml").unlink()
    missing = r"c.toml: \[camera_units\] calibration: .*cam.yaml: calibration file not found"
    with pytest.raises(CalibrationError, match=missing):
        load_config(path)
    for fy in (702.0, 668.0):   # 0.29 % and -4.6 %: within MAX_PIXEL_ASPECT_DIFF (5 %), rendered as they are
        path = _config(tmp_path, cal=Calibration(640, 480, 700.0, fy, 320.0, 240.0))
        cfg = load_config(path)
        assert cfg.camera.focal_px == (700.0, 700.0) and cfg.camera_units.pixel_aspect == (fy / 700.0,) * 2
    path = _config(tmp_path, cal=Calibration(640, 480, 700.0, 740.0, 320.0, 240.0))
    with pytest.raises(CalibrationError) as err:
        load_config(path)
    msg = str(err.value)
    head = f"{tmp_path / 'c.toml'}: [camera_units] calibration: {tmp_path / 'cam.yaml'}: camera_matrix: "
    assert msg.startswith(head)
    assert "fx 700 and fy 740 px: fy / fx = 1.05714 is 5.71 % from 1, beyond the 5 %" in msg and "\n" not in msg


def test_a_config_built_from_data_cannot_name_a_file():
    with pytest.raises(ConfigError, match=r"calibration: 'cam.yaml' is read when a config file is loaded"):
        config_from_dict({"camera_units": {"calibration": "cam.yaml"}})


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory):
    root = tmp_path_factory.mktemp("calibrated")
    path = _config(root)
    write_painted_dataset(root / "ds", path)
    return root / "ds", dt.export(root / "ds", "cameras")


def _markers_in_camera(label: dict) -> tuple[np.ndarray, np.ndarray]:
    """(centres in the camera frame (N, 3) mm, their label centres (N, 2) px)."""
    cam_from_d = np.array(label["camera"]["cam_from_d"])
    pts = np.array([m["center_d_mm"] for m in label["markers"]])
    pc = pts @ cam_from_d[:3, :3].T + cam_from_d[:3, 3]
    return pc, np.array([m["center_px"] for m in label["markers"]])


def test_the_cameras_export_projects_onto_the_labels(calibrated):
    root, out = calibrated
    ds = Dataset.open(root)
    ids = json.loads((out / "colmap" / "frame_ids.json").read_text())
    colmap_lines = [ln for ln in (out / "colmap" / "cameras.txt").read_text().splitlines() if not ln.startswith("#")]
    assert len(colmap_lines) == len(ids) == len(ds.frames())
    for line in colmap_lines:
        fid = ids[line.split()[0]]
        label = ds.read_label(fid)
        fs = cv2.FileStorage(str(out / "opencv" / f"{fid}.yaml"), cv2.FILE_STORAGE_READ)
        k, dist = fs.getNode("camera_matrix").mat(), fs.getNode("distortion_coefficients").mat().ravel()
        fs.release()
        pc, uv = _markers_in_camera(label)
        proj, _ = cv2.projectPoints(pc, np.zeros(3), np.zeros(3), k, dist)
        assert np.max(np.abs(proj.reshape(-1, 2) - uv)) < 1e-6, fid
        assert read_calibration(out / "opencv" / f"{fid}.yaml") == label_calibration(label)
        assert read_calibration(out / "ros" / f"{fid}.yaml") == read_calibration(out / "opencv" / f"{fid}.yaml")
        (out / "one.txt").write_text(line + "\n")
        assert read_calibration(out / "one.txt") == read_calibration(out / "opencv" / f"{fid}.yaml")
        (out / "one.txt").unlink()


def test_a_fixed_unit_is_written_once_and_is_the_calibration_file(calibrated):
    root, out = calibrated
    unit = read_calibration(out / "units" / "unit_00.yaml")
    assert (unit.width, unit.height) == (CAL.width, CAL.height)
    assert unit.fx == CAL.fx and unit.fy == pytest.approx(CAL.fy, rel=1e-15) and unit.fy != unit.fx
    assert (unit.cx, unit.cy) == pytest.approx((CAL.cx, CAL.cy), abs=1e-9) and unit.dist == pytest.approx(CAL.dist)
    assert read_calibration(out / "units" / "unit_00.ros.yaml") == unit
    assert read_calibration(out / "units" / "unit_00.cameras.txt") == unit


@pytest.mark.render
@pytest.mark.parametrize("fy", [338.0, 341.1])   # square, and fy / fx = 1.0092 (rows resampled)
def test_cycles_renders_the_calibrated_camera(tmp_path, fy):
    """The lens check of tests/generator/test_render.py (LENS_CHECK's scene at 320 x 240) with its
    lens from a calibration file instead of ranges, rendered by Cycles: the index pass's marker
    pixels are the exact rasterisation of the calibrated camera's outlines (at most 0.5 % differ)
    and their centroids within 0.25 px of the labels' centres, which the cameras export projects."""
    from pipeline_data import LENS_CHECK, label_vs_index

    from dockfactory.generator.render_job import JobOptions, run_render
    cal = Calibration(320, 240, 338.0, fy, 166.4, 115.2, (-0.12, 0.03, 8e-4, -6e-4, 0.0))
    write_calibration(cal, tmp_path / "cam.json", "opencv-json")
    lens_keys = ("principal_offset", "k1 ", "k2 ", "p1 ", "p2 ", "aberration", "count", "focal_px", "jpeg")
    text = "".join(ln + "\n" for ln in LENS_CHECK.splitlines() if not ln.startswith(lens_keys))
    text = text.replace("frames = 4", "frames = 2")
    text = text.replace("[camera_units]\n", '[camera_units]\ncalibration = "cam.json"\n')
    (tmp_path / "c.toml").write_text(text)
    cfg, stored = load_config_text(tmp_path / "c.toml")
    summary = run_render(cfg, tmp_path / "ds", stored, JobOptions(progress=False))
    assert summary.ok and summary.complete, summary.text()
    got = label_vs_index(tmp_path / "ds", cfg)
    assert got["markers"] >= 16 and len(got["centre_err"]) >= 8
    assert got["mismatch"] <= 0.005 * got["pixels"], f"{got['mismatch']} of {got['pixels']} marker pixels differ"
    assert got["centre_err"].max() < 0.25, f"median {np.median(got['centre_err']):.3f} px"
    out = dt.export(tmp_path / "ds", "cameras")
    unit = read_calibration(out / "units" / "unit_00.yaml")
    assert (unit.cx, unit.cy, unit.dist) == (pytest.approx(cal.cx), pytest.approx(cal.cy), pytest.approx(cal.dist))
    assert (unit.fx, unit.fy) == (cal.fx, pytest.approx(cal.fy, rel=1e-15))
