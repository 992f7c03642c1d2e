"""Calibration files in and out (core.calibration_files): OpenCV YAML / JSON, ROS camera_info,
COLMAP cameras.txt. Round trips are exact; OpenCV's own reader reads what we write; the camera
read projects points as OpenCV's projectPoints does with the original; COLMAP's half-pixel
convention is converted both ways; bad files are one line naming file and key."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from dockfactory.core.calibration_files import (
    FORMATS,
    Calibration,
    CalibrationError,
    calibration_text,
    read_calibration,
    write_calibration,
)

CAL = Calibration(1280, 960, 2000.5, 2001.25, 640.2, 480.7, (-0.1, 0.02, 0.001, -0.002, 0.003))
SUFFIX = {"opencv-yaml": ".yaml", "opencv-json": ".json", "ros": ".yaml", "colmap": ".txt"}


@pytest.mark.parametrize("fmt", FORMATS)
def test_every_format_round_trips_exactly_and_projects_as_opencv(tmp_path, fmt):
    path = tmp_path / f"cam{SUFFIX[fmt]}"
    write_calibration(CAL, path, fmt)
    got = read_calibration(path)
    assert got == CAL
    pts = np.random.default_rng(3).uniform([-400, -300, 1500], [400, 300, 2500], (50, 3))
    rvec, tvec = np.array([0.02, -0.01, 0.03]), np.array([5.0, -3.0, 20.0])
    want, _ = cv2.projectPoints(pts, rvec, tvec, CAL.K, np.array(CAL.dist))
    have, _ = cv2.projectPoints(pts, rvec, tvec, got.K, np.array(got.dist))
    assert np.max(np.abs(want - have)) < 1e-9


@pytest.mark.parametrize("fmt", ["opencv-yaml", "opencv-json"])
def test_opencv_reads_what_we_write(tmp_path, fmt):
    path = tmp_path / f"cam{SUFFIX[fmt]}"
    write_calibration(CAL, path, fmt)
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    assert np.array_equal(fs.getNode("camera_matrix").mat(), CAL.K)
    assert np.array_equal(fs.getNode("distortion_coefficients").mat().ravel(), np.array(CAL.dist))
    assert (int(fs.getNode("image_width").real()), int(fs.getNode("image_height").real())) == (1280, 960)
    fs.release()


def test_files_opencv_writes_and_a_ros_camera_info_are_read(tmp_path):
    path = tmp_path / "opencv.yaml"
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    fs.write("image_width", 1280)
    fs.write("image_height", 960)
    fs.write("camera_matrix", CAL.K)
    fs.write("distortion_coefficients", np.array([[*CAL.dist, 0.0, 0.0, 0.0]]))   # 8 values, rational 0
    fs.release()
    assert read_calibration(path) == CAL
    ros = tmp_path / "camera_info.yaml"
    ros.write_text("image_width: 1280\nimage_height: 960\ncamera_name: left\ncamera_matrix:\n  rows: 3\n  cols: 3\n"
                   "  data: [2000.5, 0, 640.2, 0, 2001.25, 480.7, 0, 0, 1]\ndistortion_model: plumb_bob\n"
                   "distortion_coefficients:\n  rows: 1\n  cols: 5\n  data: [-0.1, 0.02, 0.001, -0.002, 0.003]\n")
    assert read_calibration(ros) == CAL


def test_colmap_puts_the_pixel_centre_at_a_half(tmp_path):
    """COLMAP's principal point is OpenCV's + 0.5 px; SIMPLE_RADIAL's one f and k."""
    assert " 640.7 481.2 " in calibration_text(CAL, "colmap")
    path = tmp_path / "cameras.txt"
    path.write_text("# comment\n\n7 SIMPLE_RADIAL 1280 960 2000.0 640.0 480.0 -0.05\n")
    assert read_calibration(path) == Calibration(1280, 960, 2000.0, 2000.0, 639.5, 479.5, (-0.05, 0, 0, 0, 0))


@pytest.mark.parametrize("name, text, message", [
    ("c.txt", "1 FISHEYE 1280 960 1 2 3 4\n", r"c\.txt:1: expected CAMERA_ID MODEL .* got '1 FISHEYE'"),
    ("c.txt", "1 PINHOLE 1280 960 2000 2000 640\n", r"c\.txt:1: PINHOLE has 4 parameters"),
    ("c.txt", "1 FULL_OPENCV 1280 960 1 1 1 1 0 0 0 0 0 0.1 0 0\n", r"c\.txt:1: FULL_OPENCV's k4-k6"),
    ("c.txt", "# nothing\n", r"c\.txt: no camera line"),
    ("c.yaml", "image_width: 1280\nimage_height: 960\n", r"c\.yaml: camera_matrix: missing"),
    ("c.yaml", "image_width: 1280\nimage_height: 960\ncamera_matrix:\n  rows: 3\n  cols: 3\n  data: [1, 0, 1, 0, 1, 1, 0, 0, 2]\n"
               "distortion_coefficients:\n  rows: 1\n  cols: 5\n  data: [0, 0, 0, 0, 0]\n", r"camera_matrix: expected \[\[fx"),
    ("c.yaml", "image_width: 0\nimage_height: 960\n", r"c\.yaml: camera_matrix: missing|image_width"),
    ("c.yaml", "distortion_model: equidistant\ncamera_matrix: [1]\n", r"distortion_model: 'equidistant' is not plumb_bob"),
    ("c.yaml", "[unclosed\n", r"c\.yaml: not an OpenCV or ROS calibration file"),
    ("c.ini", "x", r"c\.ini: expected a \.yaml"),
])
def test_a_bad_file_is_one_line(tmp_path, name, text, message):
    (tmp_path / name).write_text(text)
    with pytest.raises(CalibrationError, match=message):
        read_calibration(tmp_path / name)
