"""The overlay's text: +- 1 sigma without a spec, value +- U (k = 2) and the decision of each
component with one (measure --acceptance), and every line fitting the overlay's width."""
from types import SimpleNamespace

import cv2
import numpy as np
import pytest

from dockfactory.measure.overlay import _text_lines, draw_measurement, text_scale


def _record(conformity=None) -> dict:
    cov = np.diag([0.04, 0.01, 0.09, 1e-4, 1e-4, 1e-4]).tolist()
    r = {"ok": True, "pose": {"x_mm": 1.2345, "y_mm": -0.5, "z_mm": 3.0, "alpha_deg": 0.0123,
                              "beta_deg": 0.0, "gamma_deg": 0.0},
         "covariance": cov, "camera_model": "pinhole", "focal_px": 2400.0, "rmse_px": {"A": 0.1, "B": 0.12},
         "cam_from_a": np.eye(4).tolist(), "d_from_b": np.eye(4).tolist(), "image_size": [1280, 960]}
    if conformity:
        r["conformity"] = conformity
    return r


CONF = {"decision": "UNDECIDED", "k": 2.0, "components": {
    "x_mm": {"value": 1.2345, "U": 0.4, "decision": "IN"},
    "y_mm": {"value": -0.5, "U": 0.2, "decision": "UNDECIDED"},
    "alpha_deg": {"value": 0.0123, "U": 0.02, "decision": "IN"}}}


def test_without_a_spec_the_pose_carries_one_sigma():
    lines = _text_lines(_record(), "img")
    assert "X 1.23 +- 0.20 mm" in lines[1] and "(+- 1 sigma)" in lines[1]


def test_with_a_decision_each_component_carries_U_and_its_decision():
    lines = _text_lines(_record(CONF), "img")
    assert lines[0] == "img: UNDECIDED (+- U, k = 2)"
    assert "X 1.234 +- 0.400 mm IN" in lines[1] and "Y -0.500 +- 0.200 mm UNDECIDED" in lines[1]
    assert "alpha 0.012 +- 0.020 deg IN" in lines[1]


@pytest.mark.parametrize("width", [320, 640, 1280])
def test_every_line_fits_the_overlay(width):
    lines = _text_lines(_record(CONF), "a_rather_long_image_name_0001")
    scale = text_scale(lines, width, 0.5)
    assert scale <= 0.5
    widest = max(cv2.getTextSize(t, cv2.FONT_HERSHEY_SIMPLEX, scale, 3)[0][0] for t in lines)
    assert widest <= width - 16 or scale == pytest.approx(0.5 / 3)
    if width >= 1280:
        assert scale == 0.5              # room enough: the font is not shrunk


def test_the_overlay_is_written_with_the_decision(tmp_path):
    out = tmp_path / "img.png"
    marker = SimpleNamespace(section="A", center_mm=(0.0, 0.0, 1500.0))
    draw_measurement(np.full((480, 640, 3), 90, np.uint8), [], _record(CONF), [marker], out, size=1.0)
    img = cv2.imread(str(out))
    assert img.shape == (480, 640, 3)
    assert (img[:70] > 200).all(axis=2).sum() > 200     # white text drawn in the header band
    assert (img[70:] > 200).all(axis=2).sum() == 0
