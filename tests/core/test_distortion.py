"""core.distortion: OpenCV's Brown-Conrady model, matched against cv2 and differentiated exactly."""
import cv2
import numpy as np
import pytest

from dockfactory.core.distortion import (
    coeffs_array,
    distort_normalized,
    distort_pixels,
    distortion_jacobian,
    undistort_normalized,
    undistort_pixels,
)

LENSES = [(0.0, 0.0, 0.0, 0.0, 0.0), (-0.15, 0.05, 1e-3, -1e-3, 0.0), (0.05, -0.05, -1e-3, 1e-3, 0.01),
          (-0.3, 0.1, 0.0, 0.0, -0.02)]


def _grid(n=15, half=0.55):
    a = np.linspace(-half, half, n)
    return np.stack(np.meshgrid(a, a * 0.75), -1).reshape(-1, 2)


@pytest.mark.parametrize("coeffs", LENSES)
def test_matches_opencv_project_points(coeffs):
    xy = _grid()
    f, c = 1100.0, np.array([652.3, 471.9])
    pts = np.concatenate([xy, np.ones((len(xy), 1))], 1) * 1500.0
    uv_cv, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3),
                                 np.array([[f, 0, c[0]], [0, f, c[1]], [0, 0, 1.0]]), np.array(coeffs))
    ours = distort_normalized(xy, coeffs) * f + c
    assert np.max(np.abs(ours - uv_cv[:, 0])) < 1e-9


@pytest.mark.parametrize("coeffs", LENSES)
def test_undistort_inverts_distort_to_1e_12(coeffs):
    xy = _grid()
    assert np.max(np.abs(undistort_normalized(distort_normalized(xy, coeffs), coeffs) - xy)) < 1e-12
    uv = _grid() * 1000 + [640, 480]
    back = undistort_pixels(distort_pixels(uv, 1000.0, (650.0, 470.0), coeffs), 1000.0, (650.0, 470.0), coeffs)
    assert np.max(np.abs(back - uv)) < 1e-9


@pytest.mark.parametrize("coeffs", LENSES[1:])
def test_jacobians_match_central_differences(coeffs):
    xy = _grid(5)
    j_xy, j_c = distortion_jacobian(xy, coeffs)
    h = 1e-7
    for k in range(2):
        d = np.zeros(2)
        d[k] = h
        num = (distort_normalized(xy + d, coeffs) - distort_normalized(xy - d, coeffs)) / (2 * h)
        assert np.max(np.abs(num - j_xy[:, :, k])) < 1e-7
    c0 = coeffs_array(coeffs)
    for k in range(5):
        d = np.zeros(5)
        d[k] = h
        num = (distort_normalized(xy, c0 + d) - distort_normalized(xy, c0 - d)) / (2 * h)
        assert np.max(np.abs(num - j_c[:, :, k])) < 1e-7


def test_bad_coefficients_are_refused():
    with pytest.raises(ValueError, match="up to 5"):
        coeffs_array([0.1] * 6)
    with pytest.raises(ValueError, match="finite"):
        coeffs_array([np.nan])
    assert coeffs_array((0.1,)).tolist() == [0.1, 0, 0, 0, 0]
