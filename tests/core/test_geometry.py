import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from dockfactory.core.geometry import (
    BLENDER_CAM_FROM_CV_CAM,
    blender_camera_intrinsics,
    blender_world_from_camera,
    euler_deg_from_rotation,
    intrinsics,
    invert_transform,
    look_at_cam_from_world,
    MAX_PIXEL_ASPECT_DIFF,
    pinhole_intrinsics,
    pose_components,
    project_points,
    render_canvas,
    rot_x,
    rot_y,
    rot_z,
    rotation_from_euler_deg,
    transform_from_pose_components,
    transform_points,
)

angles = st.floats(-89.0, 89.0)


@settings(max_examples=200, deadline=None)
@given(angles, angles, angles)
def test_euler_round_trip(a, b, g):
    r = rotation_from_euler_deg(a, b, g)
    assert np.allclose(r @ r.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(r) == pytest.approx(1.0, abs=1e-12)
    assert np.allclose(euler_deg_from_rotation(r), (a, b, g), atol=1e-9)


def test_euler_order_is_z_then_y_then_x():
    a, b, g = 10.0, -20.0, 30.0
    expected = rot_z(np.radians(a)) @ rot_y(np.radians(b)) @ rot_x(np.radians(g))
    assert np.allclose(rotation_from_euler_deg(a, b, g), expected, atol=1e-15)
    # alpha turns +X toward +Y (rotation about Z)
    assert np.allclose(rotation_from_euler_deg(90, 0, 0) @ [1, 0, 0], [0, 1, 0], atol=1e-15)


@settings(max_examples=100, deadline=None)
@given(st.floats(-200, 200), st.floats(-50, 50), st.floats(-50, 50), angles, angles, angles)
def test_pose_components_round_trip(x, y, z, a, b, g):
    t = transform_from_pose_components(x, y, z, a, b, g)
    comps = pose_components(t)
    assert np.allclose([comps[k] for k in ("x_mm", "y_mm", "z_mm", "alpha_deg", "beta_deg", "gamma_deg")],
                       [x, y, z, a, b, g], atol=1e-9)
    assert np.allclose(invert_transform(t) @ t, np.eye(4), atol=1e-12)


def test_project_principal_point_and_behind_camera():
    k = intrinsics(1000.0, (639.5, 479.5))
    uv, z = project_points(k, np.eye(4), [[0, 0, 1000.0], [10, -20, 1000.0], [0, 0, -5.0]])
    assert np.allclose(uv[0], [639.5, 479.5])
    assert np.allclose(uv[1], [649.5, 459.5])
    assert np.all(np.isnan(uv[2])) and z[2] == -5.0


def test_look_at_faces_target_with_image_x_along_world_x():
    cam_from_w = look_at_cam_from_world([0, 0, 1500.0], [0, 0, 300.0])
    p = transform_points(cam_from_w, [[0, 0, 300.0], [100, 0, 300.0], [0, 100, 300.0]])
    assert np.allclose(p[0], [0, 0, 1200])
    assert p[1, 0] > 0 and abs(p[1, 1]) < 1e-9      # world +X -> image right
    assert p[2, 1] < 0                              # world +Y (up) -> image up (y down)


def test_blender_camera_axes():
    cam_from_w = look_at_cam_from_world([100, 50, 1500.0], [0, 0, 300.0])
    world_from_bl = blender_world_from_camera(cam_from_w, scale=1.0)
    # Blender camera looks down its local -Z: that must be OpenCV's +Z in the world
    cv_forward_world = invert_transform(cam_from_w)[:3, :3] @ [0, 0, 1]
    assert np.allclose(world_from_bl[:3, :3] @ [0, 0, -1], cv_forward_world)
    assert np.allclose(world_from_bl[:3, 3], [100, 50, 1500])
    assert np.allclose(BLENDER_CAM_FROM_CV_CAM @ BLENDER_CAM_FROM_CV_CAM, np.eye(4))
    scaled = blender_world_from_camera(cam_from_w, scale=0.001)
    assert np.allclose(scaled[:3, 3], [0.1, 0.05, 1.5])


def test_blender_intrinsics_centre_has_no_shift():
    intr = blender_camera_intrinsics(1800.0, (639.5, 479.5), 1280, 960)
    assert intr["shift_x"] == pytest.approx(0.0, abs=1e-15)
    assert intr["shift_y"] == pytest.approx(0.0, abs=1e-15)
    assert intr["lens_mm"] / intr["sensor_width_mm"] * 1280 == pytest.approx(1800.0)
    # a principal point right of and above the centre: Blender's view window moves left and down
    # (rendered and checked against the index pass in tests/generator/test_render.py, distorted labels)
    off = blender_camera_intrinsics(1800.0, (639.5 + 12.8, 479.5 - 25.6), 1280, 960)
    assert off["shift_x"] == pytest.approx(-0.01) and off["shift_y"] == pytest.approx(-0.02)


@pytest.mark.parametrize("bad", [np.zeros((3, 2)), np.full((2, 3), np.nan), [[1, 2, np.inf]]])
def test_bad_points_raise(bad):
    with pytest.raises(ValueError):
        transform_points(np.eye(4), bad)


def test_bad_focal_raises():
    with pytest.raises(ValueError, match="focal_px"):
        intrinsics(-1.0, (0, 0))


def test_a_pixel_aspect_scales_fy_and_the_render_has_square_pixels_at_fx():
    k = intrinsics(1000.0, (320.0, 240.0), 1.004)
    assert k[0, 0] == 1000.0 and k[1, 1] == pytest.approx(1004.0, rel=1e-15) and k[1, 2] == 240.0
    assert intrinsics(1000.0, (320.0, 240.0), 1.0).tobytes() == intrinsics(1000.0, (320.0, 240.0)).tobytes()
    assert pinhole_intrinsics(k).tolist() == intrinsics(1000.0, (320.0, 240.0)).tolist()
    for bad in (0.0, -1.0, np.nan):
        with pytest.raises(ValueError, match="pixel_aspect"):
            intrinsics(1000.0, (0, 0), bad)


def test_the_render_canvas_of_non_square_pixels_holds_the_rows_at_fx():
    """No distortion: fy > fx shows fewer pinhole (square, fx) rows than the image has: the canvas
    holds the image's H / aspect rows about cy (plus the 2 px margin), its columns are the square
    camera's; beyond MAX_PIXEL_ASPECT_DIFF it is refused."""
    ox, oy, wc, hc = render_canvas(640, 480, 1000.0, (319.5, 239.5), (0,) * 5, pixel_aspect=1.04)
    assert (ox, wc) == (-3, 646)   # columns: [-0.5, 639.5] floored / ceiled, 2 px margin each side
    assert oy == np.floor(239.5 - 240 / 1.04) - 2 and oy + hc - 1 == np.ceil(239.5 + 240 / 1.04) + 2
    with pytest.raises(ValueError, match="MAX_PIXEL_ASPECT_DIFF"):
        render_canvas(640, 480, 1000.0, (319.5, 239.5), (0,) * 5, pixel_aspect=1.0 + 1.01 * MAX_PIXEL_ASPECT_DIFF)
