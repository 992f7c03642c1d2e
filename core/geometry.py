"""Pure rigid-body and camera geometry shared by every part of dockfactory.

Conventions (see README, "Conventions"):
- transforms are 4x4 float64 arrays named ``<to>_from_<from>``;
- lengths in mm, angles in degrees at the API, radians inside;
- R = Rz(alpha) @ Ry(beta) @ Rx(gamma) for the pose of B in D;
- camera frame is OpenCV's (x right, y down, z forward); pixel (0, 0) is the centre of the
  top-left pixel.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from dockfactory.core.distortion import coeffs_array, distortion_jacobian, undistort_pixels

__all__ = [
    "rot_x", "rot_y", "rot_z", "rotation_from_euler_deg", "euler_deg_from_rotation",
    "make_transform", "invert_transform", "transform_points", "pose_components",
    "transform_from_pose_components", "intrinsics", "project_points",
    "look_at_cam_from_world", "BLENDER_CAM_FROM_CV_CAM", "blender_world_from_camera",
    "blender_camera_intrinsics", "check_array", "polygon_area_centroid", "render_canvas",
]


def check_array(name: str, value, shape: tuple) -> np.ndarray:
    """Return ``value`` as a finite float64 array of ``shape`` (-1 = any length) or raise ValueError."""
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim != len(shape) or any(s != -1 and s != n for s, n in zip(shape, arr.shape)):
        want = "x".join("N" if s == -1 else str(s) for s in shape)
        raise ValueError(f"{name}: expected shape ({want}), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: contains NaN or inf")
    return arr


def rot_x(angle_rad: float) -> np.ndarray:
    """Rotation about +X by ``angle_rad``: (3, 3)."""
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(angle_rad: float) -> np.ndarray:
    """Rotation about +Y by ``angle_rad``: (3, 3)."""
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(angle_rad: float) -> np.ndarray:
    """Rotation about +Z by ``angle_rad``: (3, 3)."""
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rotation_from_euler_deg(alpha_deg: float, beta_deg: float, gamma_deg: float) -> np.ndarray:
    """R = Rz(alpha) @ Ry(beta) @ Rx(gamma), angles in degrees: (3, 3)."""
    a, b, g = np.radians([alpha_deg, beta_deg, gamma_deg])
    return rot_z(a) @ rot_y(b) @ rot_x(g)


def euler_deg_from_rotation(rotation) -> tuple[float, float, float]:
    """Inverse of :func:`rotation_from_euler_deg`: (alpha, beta, gamma) in degrees.

    ``rotation``: (3, 3). beta is returned in [-90, 90]; at gimbal lock (|beta| = 90) gamma is 0.
    """
    r = check_array("rotation", rotation, (3, 3))
    beta = np.arcsin(np.clip(-r[2, 0], -1.0, 1.0))
    if abs(np.cos(beta)) > 1e-12:
        alpha = np.arctan2(r[1, 0], r[0, 0])
        gamma = np.arctan2(r[2, 1], r[2, 2])
    else:  # gimbal lock: only alpha - gamma (or alpha + gamma) is defined
        alpha = np.arctan2(-r[0, 1], r[1, 1])
        gamma = 0.0
    return float(np.degrees(alpha)), float(np.degrees(beta)), float(np.degrees(gamma))


def make_transform(rotation, translation) -> np.ndarray:
    """4x4 transform from rotation (3, 3) and translation (3,)."""
    t = np.eye(4)
    t[:3, :3] = check_array("rotation", rotation, (3, 3))
    t[:3, 3] = check_array("translation", translation, (3,))
    return t


def invert_transform(transform) -> np.ndarray:
    """Inverse of a rigid 4x4 transform: (4, 4)."""
    t = check_array("transform", transform, (4, 4))
    r, p = t[:3, :3], t[:3, 3]
    out = np.eye(4)
    out[:3, :3] = r.T
    out[:3, 3] = -r.T @ p
    return out


def transform_points(transform, points) -> np.ndarray:
    """Apply a 4x4 transform to points (N, 3); returns (N, 3)."""
    t = check_array("transform", transform, (4, 4))
    p = check_array("points", points, (-1, 3))
    return p @ t[:3, :3].T + t[:3, 3]


def pose_components(d_from_b) -> dict[str, float]:
    """X, Y, Z (mm) and alpha, beta, gamma (deg) of ``d_from_b`` (4, 4)."""
    t = check_array("d_from_b", d_from_b, (4, 4))
    alpha, beta, gamma = euler_deg_from_rotation(t[:3, :3])
    return {"x_mm": float(t[0, 3]), "y_mm": float(t[1, 3]), "z_mm": float(t[2, 3]),
            "alpha_deg": alpha, "beta_deg": beta, "gamma_deg": gamma}


def transform_from_pose_components(x_mm, y_mm, z_mm, alpha_deg, beta_deg, gamma_deg) -> np.ndarray:
    """Inverse of :func:`pose_components`: a 4x4 ``d_from_b``."""
    return make_transform(rotation_from_euler_deg(alpha_deg, beta_deg, gamma_deg),
                          [x_mm, y_mm, z_mm])


def intrinsics(focal_px: float, principal_point, pixel_aspect: float = 1.0) -> np.ndarray:
    """Pinhole K (3, 3), no skew: fx = ``focal_px``, fy = ``pixel_aspect`` fx (1: square pixels),
    ``principal_point``: (2,) px. ValueError for a non-positive or non-finite focal or aspect."""
    if not np.isfinite(focal_px) or focal_px <= 0:
        raise ValueError(f"focal_px must be positive and finite, got {focal_px}")
    if not np.isfinite(pixel_aspect) or pixel_aspect <= 0:
        raise ValueError(f"pixel_aspect must be positive and finite, got {pixel_aspect}")
    c = check_array("principal_point", principal_point, (2,))
    return np.array([[focal_px, 0.0, c[0]], [0.0, focal_px * pixel_aspect, c[1]], [0.0, 0.0, 1.0]])


def pinhole_intrinsics(k) -> np.ndarray:
    """The square-pixel K (3, 3) of the camera with K ``k`` (3, 3): its fx on both axes, its
    principal point (the factory's render of that camera: core.scene.CameraModel); ``k`` itself
    (as float64) when fx = fy."""
    k = check_array("K", k, (3, 3))
    if k[1, 1] == k[0, 0]:
        return k
    out = k.copy()
    out[1, 1] = k[0, 0]
    return out


def project_points(k, cam_from_x, points) -> tuple[np.ndarray, np.ndarray]:
    """Project points (N, 3) of frame x through ``cam_from_x`` (4, 4) and K (3, 3).

    Returns (uv (N, 2) px in the OpenCV pixel convention, depth (N,) mm along the optical axis).
    Points at or behind the camera get NaN pixel coordinates.
    """
    k = check_array("K", k, (3, 3))
    pc = transform_points(cam_from_x, points)
    z = pc[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = (pc @ k.T)[:, :2] / z[:, None]
    uv[z <= 0] = np.nan
    return uv, z


def look_at_cam_from_world(eye, target, up=(0.0, 1.0, 0.0)) -> np.ndarray:
    """OpenCV camera at ``eye`` (3,) looking at ``target`` (3,), image up ~ ``up``: cam_from_world."""
    eye = check_array("eye", eye, (3,))
    z = check_array("target", target, (3,)) - eye
    if np.linalg.norm(z) == 0:
        raise ValueError("look_at: eye and target coincide")
    z /= np.linalg.norm(z)
    down = -check_array("up", up, (3,))
    x = np.cross(down, z)
    if np.linalg.norm(x) < 1e-9:
        raise ValueError("look_at: viewing direction is parallel to up")
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    r = np.stack([x, y, z])  # rows: camera axes expressed in world
    return make_transform(r, -r @ eye)


# Blender's camera looks down its -Z with +Y up; OpenCV's looks down +Z with +Y down.
BLENDER_CAM_FROM_CV_CAM = np.diag([1.0, -1.0, -1.0, 1.0])


def blender_world_from_camera(cam_from_world, scale: float = 1.0) -> np.ndarray:
    """Blender camera object matrix (world_from_blendercam, 4x4) for an OpenCV ``cam_from_world``.

    ``scale`` converts the translation units (0.001 turns mm into Blender metres).
    The one place where the OpenCV/Blender camera conversion lives.
    """
    world_from_cv = invert_transform(cam_from_world)
    out = world_from_cv @ BLENDER_CAM_FROM_CV_CAM  # cv_from_blender == blender_from_cv (diagonal)
    out[:3, 3] *= scale
    return out


def blender_camera_intrinsics(focal_px: float, principal_point, width: int, height: int,
                              sensor_width_mm: float = 36.0) -> dict[str, float]:
    """Blender camera settings that reproduce K for a ``width`` x ``height`` render.

    Uses sensor_fit HORIZONTAL. Blender measures the image plane from the left/bottom edges with
    pixel centres at +0.5, OpenCV puts the first pixel centre at 0: an OpenCV principal point
    (cx, cy) sits at Blender's (cx + 0.5, H - (cy + 0.5)). Shifts are in units of the larger
    image side. Returns lens_mm, sensor_width_mm, shift_x, shift_y.
    """
    if width <= 0 or height <= 0:
        raise ValueError(f"image size must be positive, got {width}x{height}")
    c = check_array("principal_point", principal_point, (2,))
    side = float(max(width, height))
    return {
        "lens_mm": float(focal_px) * sensor_width_mm / width,
        "sensor_width_mm": sensor_width_mm,
        # a positive shift moves Blender's view window right (up): the optical axis, and with
        # it the principal point, lands left of (below) the image centre
        "shift_x": -(c[0] + 0.5 - width / 2.0) / side,
        "shift_y": (c[1] + 0.5 - height / 2.0) / side,
    }


def polygon_area_centroid(poly: np.ndarray) -> tuple[float, np.ndarray]:
    """Signed-area-free area and centroid of a simple polygon (n, 2)."""
    if len(poly) < 3:
        return 0.0, np.full(2, np.nan)
    x, y = poly[:, 0], poly[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    cross = x * yn - xn * y
    a = cross.sum() / 2.0
    if abs(a) < 1e-12:
        return 0.0, np.full(2, np.nan)
    cx = ((x + xn) * cross).sum() / (6 * a)
    cy = ((y + yn) * cross).sum() / (6 * a)
    return abs(float(a)), np.array([cx, cy])


# ----------------------------------------------------------------------------- render canvas

CANVAS_MARGIN_PX = 2        # beyond the farthest source position: the bilinear taps, rounding
CANVAS_MAX_SCALE = 2.0      # a canvas side is at most this many image sides
CANVAS_BORDER_STEP_PX = 4.0  # spacing of the border points whose sources bound the canvas
# |fy / fx - 1| of a camera the square-pixel render is resampled to (docs/configuration.md,
# "A calibration file in a config": why this bound)
MAX_PIXEL_ASPECT_DIFF = 0.05


def _border_pixels(width: int, height: int, step: float) -> np.ndarray:
    """Points (N, 2) along the edges of the image [-0.5, W - 0.5] x [-0.5, H - 0.5], corners included."""
    xs = np.append(np.arange(-0.5, width - 0.5, step), width - 0.5)
    ys = np.append(np.arange(-0.5, height - 0.5, step), height - 0.5)
    return np.concatenate([np.stack([xs, np.full_like(xs, -0.5)], 1),
                           np.stack([xs, np.full_like(xs, height - 0.5)], 1),
                           np.stack([np.full_like(ys, -0.5), ys], 1),
                           np.stack([np.full_like(ys, width - 0.5), ys], 1)])


def _check_folds(lo, hi, focal_px: float, c: np.ndarray, coeffs) -> None:
    """The distortion keeps a positive Jacobian over the canvas (no fold: one source per pixel)."""
    gx, gy = np.meshgrid(np.linspace(lo[0], hi[0], 33), np.linspace(lo[1], hi[1], 33))
    xy = (np.stack([gx.ravel(), gy.ravel()], 1) - c) / focal_px
    j, _ = distortion_jacobian(xy, coeffs)
    if np.min(np.linalg.det(j)) <= 0.0:
        raise ValueError("render canvas: the lens distortion folds over inside the image "
                         "(coefficients too strong for this field of view)")


@lru_cache(maxsize=64)
def _canvas(width: int, height: int, focal_px: float, principal_point: tuple, coeffs: tuple,
            scales: tuple, pixel_aspect: float) -> tuple[int, int, int, int]:
    c = np.asarray(principal_point, dtype=np.float64)
    src = undistort_pixels(_border_pixels(width, height, CANVAS_BORDER_STEP_PX), focal_px, c, coeffs, pixel_aspect)
    pts = np.concatenate([c + (src - c) / s for s in scales])
    lo = np.floor(pts.min(0)).astype(int) - CANVAS_MARGIN_PX
    hi = np.ceil(pts.max(0)).astype(int) + CANVAS_MARGIN_PX
    size = hi - lo + 1
    if np.any(size > CANVAS_MAX_SCALE * np.array([width, height])):
        raise ValueError(f"render canvas: {size[0]}x{size[1]} px for a {width}x{height} image is above "
                         f"{CANVAS_MAX_SCALE:g} times its size (distortion too strong)")
    _check_folds(lo, hi, focal_px, c, coeffs)
    return int(lo[0]), int(lo[1]), int(size[0]), int(size[1])


def render_canvas(width: int, height: int, focal_px: float, principal_point, coeffs,
                  scales=(1.0, 1.0, 1.0), pixel_aspect: float = 1.0) -> tuple[int, int, int, int]:
    """The pinhole render (overscan) a distorted ``width`` x ``height`` image is resampled from.

    Delivered pixel p (fx = ``focal_px``, fy = ``pixel_aspect`` fx) shows the pinhole image (square
    pixels at ``focal_px``, ``principal_point``; ``core.distortion.undistort_pixels``) at
    ``pp + (undistort(p) - pp) / s`` for each channel scale ``s`` of ``scales``; the canvas is the
    smallest pixel-aligned rectangle that holds every such position of the image's border (the
    distortion maps the border to the border: a diffeomorphism, checked to have no fold) plus
    CANVAS_MARGIN_PX. Returns (offset_x, offset_y, canvas_width, canvas_height): canvas pixel
    (i, j) is pinhole pixel (i + offset_x, j + offset_y); its principal point is
    ``principal_point - offset``. Raises ValueError for a lens that folds or needs over
    CANVAS_MAX_SCALE times the image, or a ``pixel_aspect`` beyond MAX_PIXEL_ASPECT_DIFF of 1.
    """
    if not 1.0 - MAX_PIXEL_ASPECT_DIFF <= float(pixel_aspect) <= 1.0 + MAX_PIXEL_ASPECT_DIFF:
        raise ValueError(f"render canvas: pixel aspect (fy / fx) {pixel_aspect} is more than "
                         f"{MAX_PIXEL_ASPECT_DIFF:g} from 1 (MAX_PIXEL_ASPECT_DIFF)")
    c = check_array("principal_point", principal_point, (2,))
    k = tuple(float(v) for v in coeffs_array(coeffs))
    return _canvas(int(width), int(height), float(focal_px), (float(c[0]), float(c[1])), k,
                   tuple(float(s) for s in scales), float(pixel_aspect))
