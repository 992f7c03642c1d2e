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


# ----------------------------------------------------------------------------- non-square pixels

ASPECTS = (0.97, 1.0037, 1.05)   # fy / fx: a real calibration's 0.37 %, and the bound's 5 % either way


def _k(f, c, aspect):
    return np.array([[f, 0, c[0]], [0, f * aspect, c[1]], [0, 0, 1.0]])


@pytest.mark.parametrize("aspect", ASPECTS)
@pytest.mark.parametrize("coeffs", LENSES)
def test_non_square_projection_matches_opencv_project_points(coeffs, aspect):
    """Points projected by the square-pixel pinhole at fx and moved by distort_pixels with the
    aspect land where cv2.projectPoints puts them with K = [[fx, 0, cx], [0, fy, cy]] (1e-6 px)."""
    xy = _grid()
    f, c = 1100.0, np.array([652.3, 471.9])
    pts = np.concatenate([xy, np.ones((len(xy), 1))], 1) * 1500.0
    uv_cv, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), _k(f, c, aspect), np.array(coeffs))
    pinhole = pts[:, :2] / pts[:, 2:] * f + c   # the render's square pixels
    ours = distort_pixels(pinhole, f, c, coeffs, aspect)
    assert np.max(np.abs(ours - uv_cv[:, 0])) < 1e-6


@pytest.mark.parametrize("aspect", ASPECTS)
@pytest.mark.parametrize("coeffs", LENSES)
def test_non_square_undistort_inverts_distort_and_matches_opencv(coeffs, aspect):
    """undistort_pixels(distort_pixels(uv)) = uv to 1e-9 px, and it is cv2.undistortPoints with
    the non-square K onto the square-pixel K at fx (1e-6 px)."""
    f, c = 1000.0, (650.0, 470.0)
    uv = _grid() * 1000 + [640, 480]
    delivered = distort_pixels(uv, f, c, coeffs, aspect)
    assert np.max(np.abs(undistort_pixels(delivered, f, c, coeffs, aspect) - uv)) < 1e-9
    cv_back = cv2.undistortPointsIter(delivered.reshape(-1, 1, 2), _k(f, c, aspect), np.array(coeffs), None,
                                      _k(f, c, 1.0), (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-15))
    assert np.max(np.abs(cv_back.reshape(-1, 2) - uv)) < 1e-6
    if aspect != 1.0:   # the aspect moves rows only, about the principal point
        assert not np.allclose(delivered, distort_pixels(uv, f, c, coeffs))


def test_unit_aspect_is_the_square_arithmetic_and_a_bad_aspect_is_refused():
    uv = _grid() * 1000 + [640, 480]
    for coeffs in LENSES:
        assert distort_pixels(uv, 1000.0, (650.0, 470.0), coeffs, 1.0).tobytes() == \
            distort_pixels(uv, 1000.0, (650.0, 470.0), coeffs).tobytes()
    for bad in (0.0, -1.0, np.nan, np.inf):
        with pytest.raises(ValueError, match="pixel_aspect"):
            distort_pixels(uv, 1000.0, (650.0, 470.0), LENSES[1], bad)
        with pytest.raises(ValueError, match="pixel_aspect"):
            undistort_pixels(uv, 1000.0, (650.0, 470.0), LENSES[1], bad)
