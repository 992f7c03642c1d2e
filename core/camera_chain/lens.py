"""The lens stage of the camera chain: the render canvas -> the delivered image's geometry.

The pinhole render (an overscan canvas, ``CameraModel.canvas``, square pixels at ``focal_px``) is
resampled into the delivered image through the exact inverse of the unit's distortion and pixel
aspect (``distortion_maps``), each colour channel through its own magnification (lateral
chromatic aberration, ``channel_maps``): colour bilinear, depth and object index nearest, the
markers' edges in the index pass by their exact outlines (``resample_passes``). Radiance stays
scene-linear; the labels are resampled with the image.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

from dockfactory.core.cv import cv2
import numpy as np

from dockfactory.core.distortion import distort_pixels, undistort_normalized
from dockfactory.core.scene import CameraModel


@dataclass
class RenderPasses:
    """The passes of a render, or of the delivered image after the lens."""
    rgb: np.ndarray    # (H, W, 3) float32 linear
    depth_mm: np.ndarray  # (H, W) float32, planar depth in mm (inf where nothing was hit)
    index: np.ndarray  # (H, W) int32 object index (0 = not a marker)


# The exact inverse of the distortion is computed (Newton, core.distortion) on a grid of this
# spacing and upsampled with separable Catmull-Rom: within 5e-4 px of the exact inverse at every
# pixel for the lenses of the realistic ranges (3e-4 px measured at the corners of k1 = -0.15,
# k2 = -0.05 at 1200 px; tests/generator/test_camera_units.py), near the float32 precision of the map and
# far below cv2.remap's 1/32 px interpolation steps.
MAP_GRID_PX = 8


def _catmull_rom(t: np.ndarray) -> np.ndarray:
    """Weights (N, 4) of the nodes i - 1 .. i + 2 at fractional positions ``t`` (N,) in [0, 1)."""
    t2, t3 = t * t, t * t * t
    return 0.5 * np.stack([-t3 + 2 * t2 - t, 3 * t3 - 5 * t2 + 2, -3 * t3 + 4 * t2 + t, t3 - t2], axis=-1)


def _upsample_rows(a: np.ndarray, n: int) -> np.ndarray:
    """Rows 0..n-1 (n, W) float32 from rows ``a`` (nodes, W) at -MAP_GRID_PX, 0, MAP_GRID_PX, ...
    (Catmull-Rom, polyphase: output rows r, r + step, ... share one set of weights)."""
    step = MAP_GRID_PX
    out = np.empty((n, a.shape[1]), np.float32)
    for r in range(min(step, n)):
        m = len(range(r, n, step))
        w = _catmull_rom(np.array([r / step]))[0].astype(np.float32)
        out[r::step] = w[0] * a[0:m] + w[1] * a[1:m + 1] + w[2] * a[2:m + 2] + w[3] * a[3:m + 3]
    return out


@lru_cache(maxsize=2)
def _maps(width: int, height: int, focal_px: float, pp: tuple, coeffs: tuple, offset: tuple, aspect: float):
    """(map_x, map_y) of :func:`distortion_maps` from its camera's numbers (:func:`_key`)."""
    gx = np.arange(-MAP_GRID_PX, width + 2 * MAP_GRID_PX, MAP_GRID_PX, dtype=np.float64)
    gy = np.arange(-MAP_GRID_PX, height + 2 * MAP_GRID_PX, MAP_GRID_PX, dtype=np.float64)
    xd = np.stack(np.meshgrid((gx - pp[0]) / focal_px, (gy - pp[1]) / (focal_px * aspect)), axis=-1).reshape(-1, 2)
    if aspect == 1.0:
        disp = (undistort_normalized(xd, coeffs) - xd) * focal_px
    else:   # the render's rows are at focal_px, the delivered image's at focal_px * aspect
        disp = undistort_normalized(xd, coeffs) * focal_px - xd * np.array([focal_px, focal_px * aspect])
    disp = disp.reshape(len(gy), len(gx), 2).astype(np.float32)
    full = [_upsample_rows(np.ascontiguousarray(_upsample_rows(disp[..., c].T, width).T), height) for c in (0, 1)]
    map_x = full[0] + (np.arange(width, dtype=np.float32) - np.float32(offset[0]))
    map_y = full[1] + (np.arange(height, dtype=np.float32)[:, None] - np.float32(offset[1]))
    map_x.flags.writeable = map_y.flags.writeable = False
    return map_x, map_y


def _key(cam: CameraModel) -> tuple:
    ox, oy, _, _ = cam.canvas()
    return (cam.width, cam.height, float(cam.focal_px), tuple(map(float, cam.principal_point)),
            tuple(map(float, cam.distortion)), (ox, oy), float(cam.pixel_aspect))


def distortion_maps(cam: CameraModel) -> tuple[np.ndarray, np.ndarray]:
    """(map_x, map_y), each (H, W) float32: for every delivered pixel, the position in the render
    canvas (its pixel convention; square pixels at the camera's focal_px) of the undistorted point
    it shows (the green channel), the pixel aspect taken out. Cached (read-only arrays): the
    frames of a docking run share one."""
    return _maps(*_key(cam))


def _scaled(maps, centre, s: float):
    if s == 1.0:
        return maps
    inv, cx, cy = np.float32(1.0 / s), np.float32(centre[0]), np.float32(centre[1])
    return cx + (maps[0] - cx) * inv, cy + (maps[1] - cy) * inv


def channel_maps(cam: CameraModel) -> list[tuple[np.ndarray, np.ndarray]]:
    """The red, green and blue channels' maps: the green one magnified about the principal point
    by 1 / scale (a channel whose image is larger by ``scale`` looks nearer the centre)."""
    ox, oy, _, _ = cam.canvas()
    centre = (cam.principal_point[0] - ox, cam.principal_point[1] - oy)
    return [_scaled(distortion_maps(cam), centre, s) for s in cam.channel_scales()]


@lru_cache(maxsize=2)
def _channel_tables(key: tuple, scales: tuple) -> list:
    """The colour channels' maps of a camera, kept for the frames of a docking run."""
    centre = (key[3][0] - key[5][0], key[3][1] - key[5][1])
    return [_scaled(_maps(*key), centre, s) for s in scales]


OCCLUDER_GAP_MM = 3.0   # a source pixel this much nearer than a marker's own pixels covers it
_TAPS = np.array([[0, 0], [1, 0], [0, 1], [1, 1]])


def _inside_convex(poly: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """(M,) bool: points ``pts`` (M, 2) inside the convex polygon ``poly`` (N, 2), either
    orientation: each point is tested against the one edge its angle about the centroid falls on."""
    c = poly.mean(axis=0)
    ang = np.arctan2(poly[:, 1] - c[1], poly[:, 0] - c[0])
    order = np.argsort(ang)
    ang, poly = ang[order], poly[order]
    i = np.searchsorted(ang, np.arctan2(pts[:, 1] - c[1], pts[:, 0] - c[0])) % len(poly)
    a, b = poly[i - 1], poly[i]
    return (b[:, 0] - a[:, 0]) * (pts[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (pts[:, 0] - a[:, 0]) >= 0


def _window(cam: CameraModel, poly: np.ndarray):
    """Delivered pixels around the distorted image of outline ``poly`` (N, 2, pinhole px): slices."""
    uv = distort_pixels(poly, cam.focal_px, cam.principal_point, cam.distortion, cam.pixel_aspect)
    x0, y0 = np.floor(uv.min(0)).astype(int) - 2
    x1, y1 = np.ceil(uv.max(0)).astype(int) + 3
    x0, y0, x1, y1 = max(0, x0), max(0, y0), min(cam.width, x1), min(cam.height, y1)
    return None if x1 <= x0 or y1 <= y0 else (slice(y0, y1), slice(x0, x1))


def refine_marker_edges(index: np.ndarray, canvas: RenderPasses, cam: CameraModel, outlines) -> None:
    """Decide the delivered index pass's marker edges by the exact outlines (in place).

    Nearest resampling tests the source pixel nearest to a delivered pixel's source position u,
    which moves a marker's pixels coherently by up to half a pixel. Where u's four source pixels
    hold a marker and something behind it, the marker's exact pinhole outline decides instead
    (``outlines``: (pass index, convex outline (N, 2) in the camera's pinhole px)); where one of
    them is nearer than the marker by OCCLUDER_GAP_MM (an occluder's edge) the nearest pixel stays.
    """
    mx, my = distortion_maps(cam)
    ox, oy, wc, hc = cam.canvas()
    for value, poly in outlines:
        win = _window(cam, poly)
        if win is None:
            continue
        u = np.stack([mx[win], my[win]], axis=-1).astype(np.float64)
        base = np.clip(np.floor(u).astype(int), 0, [wc - 2, hc - 2])
        tx, ty = base[..., None, 0] + _TAPS[:, 0], base[..., None, 1] + _TAPS[:, 1]
        taps, depth = canvas.index[ty, tx], canvas.depth_mm[ty, tx]
        has = taps == value
        ref = np.where(has, depth, np.inf).min(axis=-1, keepdims=True)
        front = (~has & (depth < ref - OCCLUDER_GAP_MM)).any(axis=-1)
        decide = has.any(axis=-1) & ~has.all(axis=-1) & ~front
        if not decide.any():
            continue
        inside = _inside_convex(np.asarray(poly) - (ox, oy), u[decide])
        frac = u[decide][:, None, :] - np.stack([tx[decide], ty[decide]], axis=-1)
        dist = np.where(has[decide], np.inf, (frac ** 2).sum(axis=-1))
        behind = taps[decide][np.arange(len(dist)), dist.argmin(axis=-1)]
        sub = index[win]
        sub[decide] = np.where(inside, value, behind)


def resample_passes(passes: RenderPasses, cam: CameraModel, outlines=()) -> RenderPasses:
    """The stage: the delivered (distorted, aberrated) passes of a canvas render.

    Colour bilinear per channel, depth and object index nearest (the green channel's map), the
    markers' edges in the index pass by their exact outlines (:func:`refine_marker_edges`).

    Parameters
    ----------
    passes : RenderPasses
        The render of ``cam.canvas()``: colour (Hc, Wc, 3) scene-linear, depth (mm), index.
    cam : CameraModel
        The frame's camera.
    outlines : sequence of (int, (N, 2) float64)
        (index-pass value, convex outline in the camera's pinhole px) of the markers.

    Returns
    -------
    RenderPasses
        The passes of the delivered image, (H, W); a pinhole camera's ``passes`` as they are.

    Raises
    ------
    ValueError
        ``passes`` not of the camera's canvas size.
    """
    if cam.is_pinhole():
        return passes
    _, _, wc, hc = cam.canvas()
    if passes.rgb.shape[:2] != (hc, wc):
        raise ValueError(f"render is {passes.rgb.shape[1]}x{passes.rgb.shape[0]}, the camera's canvas {wc}x{hc}")
    linear = _channel_tables(_key(cam), cam.channel_scales())
    rgb = np.asarray(passes.rgb, dtype=np.float32)
    if any(cam.aberration_px):   # each channel through its own map, into planes (no merge copy)
        planes = np.empty((3, cam.height, cam.width), np.float32)
        for c, (m1, m2) in enumerate(linear):
            cv2.remap(cv2.extractChannel(rgb, c), m1, m2, cv2.INTER_LINEAR, dst=planes[c],
                      borderMode=cv2.BORDER_REPLICATE)
        rgb = np.moveaxis(planes, 0, -1)
    else:   # one map for the three channels
        rgb = cv2.remap(rgb, *linear[1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    both = cv2.merge([np.asarray(passes.depth_mm, dtype=np.float32), passes.index.astype(np.float32)])
    depth, index = cv2.split(cv2.remap(both, *linear[1], cv2.INTER_NEAREST, borderMode=cv2.BORDER_REPLICATE))
    index = np.rint(index).astype(np.int32)
    refine_marker_edges(index, passes, cam, outlines)
    return RenderPasses(rgb=rgb, depth_mm=depth, index=index)
