"""Exact per-frame labels (pure numpy): projections, boxes, visibility from the index pass.

Pixel convention (OpenCV): the centre of the top-left pixel is (0, 0); the image spans
[-0.5, W - 0.5] x [-0.5, H - 0.5]. Boxes are [x0, y0, x1, y1] in that continuous frame.

Every position is in the delivered image of K (fy = pixel aspect fx): the render's pinhole projection
(square pixels at fx) through the unit's lens and pixel aspect (``core.distortion``), analytically:
centres, the dense marker outlines (and so boxes, areas, ``outline_centroid_px``), section silhouettes.

With [motion] (``generator.motion``, docs/motion.md) ``d_from_b`` is B at mid-exposure. A global
shutter's labels are B's at mid-exposure; a rolling shutter's place every point of B (centres,
outline points, silhouette points) where its own row's exposure time images it. The index pass
samples every pixel at one instant of its exposure window, so visibility and the visible box
come from a sample of the blurred marker; ``bbox_swept_px`` bounds the blur.
"""
from __future__ import annotations

from dockfactory.core.cv import cv2
import numpy as np

from dockfactory.core.distortion import COEFF_NAMES, coeffs_array, distort_pixels
from dockfactory.core.geometry import (
    pinhole_intrinsics,
    polygon_area_centroid,
    pose_components,
    project_points,
    transform_points,
)
from dockfactory.core.layout import SECTION_PASS_INDEX, SECTIONS, Marker, marker_outline
from dockfactory.core.names import MIN_CHROMA
from dockfactory.core.scene import FrameScene, StaticScene, to_dict
from dockfactory.generator.motion import MovingB, exposure_offsets, moving_b, rolling_view
from dockfactory.generator.silhouette import mask_pixels, outlines_mask, silhouette_parts

LABEL_FORMAT = "dockfactory.label/1"
DISTORTION_MODEL = ("opencv: Brown-Conrady on normalised coordinates, coefficients (k1, k2, p1, p2, k3) "
                    "as cv2.projectPoints takes them")
DENSIFY_PX = 1.0   # a region's outline is resampled to this spacing before it is distorted


def image_px(uv: np.ndarray, k: np.ndarray, coeffs) -> np.ndarray:
    """Delivered-image pixels (N, 2) of pinhole pixels ``uv`` (N, 2) (the render's: square at
    fx, ``core.geometry.pinhole_intrinsics``) of the camera with K ``k`` (3, 3) and lens
    distortion ``coeffs`` (OpenCV order); ``uv`` itself for square pixels without distortion."""
    c = coeffs_array(coeffs)
    aspect = float(k[1, 1] / k[0, 0])
    if not np.any(c) and aspect == 1.0:
        return uv
    return distort_pixels(uv, float(k[0, 0]), k[:2, 2], c, aspect)


def ideal_px(uv: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Pixels (N, 2) of K ``k`` (3, 3) alone (no distortion: fy on the rows) of the render's
    pinhole pixels ``uv`` (N, 2) (``core.geometry.pinhole_intrinsics``); ``uv`` itself for square
    pixels."""
    if k[1, 1] == k[0, 0]:
        return uv
    out = np.array(uv, dtype=np.float64)
    out[:, 1] = k[1, 2] + (out[:, 1] - k[1, 2]) * (k[1, 1] / k[0, 0])
    return out


def marker_outline_px(marker: Marker, k: np.ndarray, coeffs, cam_from_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The marker disc's edge in the delivered image of the camera with K ``k`` (3, 3) and lens
    ``coeffs``: (uv (n, 2) px, depth (n,) mm), the dense outline (``layout.OUTLINE_POINTS``)
    projected by the render's pinhole and distorted point by point. NaN where behind the camera."""
    uv, z = project_points(pinhole_intrinsics(k), cam_from_s, marker_outline(marker))
    return image_px(uv, k, coeffs), z


def marker_pinhole_outlines(frame: FrameScene, static: StaticScene) -> list[tuple[int, np.ndarray]]:
    """(pass index, outline (n, 2) in the camera's pinhole pixels) of every marker in front of the
    camera: what the render canvas shows before the lens (``camera_chain.lens.refine_marker_edges``).
    While B moves, B's markers under a rolling shutter with no exposure time have their row-time
    outline, and blurred ones (exposure time > 0) none: their index-pass edges are the ones Cycles
    sampled."""
    cam = frame.camera
    k, cam_from_d, d_from_b = cam.pinhole_k(), cam.cam_from_d_array(), frame.d_from_b_array()
    rolling = rolling_view(frame)
    blurred = frame.motion is not None and frame.motion.moves() and frame.motion.exposure_ms > 0
    out = []
    for m in static.markers:
        if m.section == "B" and blurred:
            continue
        if m.section == "B" and rolling is not None:
            uv, z, _ = rolling.project(marker_outline(m))
        else:
            uv, z = project_points(k, cam_from_d @ (d_from_b if m.section == "B" else np.eye(4)), marker_outline(m))
        if np.all(z > 0):
            out.append((m.pass_index, uv))
    return out


def densify(poly: np.ndarray, step: float) -> np.ndarray:
    """The closed polygon (n, 2) with points added so no edge is longer than ``step``."""
    nxt = np.roll(poly, -1, axis=0)
    counts = np.maximum(1, np.ceil(np.hypot(*(nxt - poly).T) / step).astype(int))
    t = np.concatenate([np.arange(c) / c for c in counts])
    start = np.repeat(poly, counts, axis=0)
    return start + t[:, None] * (np.repeat(nxt, counts, axis=0) - start)


def distorted_region(uv: np.ndarray, cam) -> np.ndarray:
    """The delivered-image outline (M, 2) of the convex pinhole region spanned by ``uv`` (N, 2):
    its hull is clipped to the render canvas (which holds the source of every delivered pixel,
    and where the distortion is one to one), densified to DENSIFY_PX and distorted."""
    hull = uv[cv2.convexHull(uv.astype(np.float32), returnPoints=False).ravel()]
    ox, oy, wc, hc = cam.canvas()
    clipped = clip_polygon(hull, ox - 0.5, oy - 0.5, ox + wc - 0.5, oy + hc - 0.5)
    if len(clipped) < 3:
        return np.zeros((0, 2))
    return image_px(densify(clipped, DENSIFY_PX), cam.k(), cam.distortion)


def clip_polygon(poly: np.ndarray, x0, y0, x1, y1) -> np.ndarray:
    """Sutherland-Hodgman clip of polygon (n, 2) to the rectangle [x0, x1] x [y0, y1]."""
    out = np.asarray(poly, dtype=np.float64)
    for axis, bound, keep_greater in ((0, x0, True), (0, x1, False), (1, y0, True), (1, y1, False)):
        if len(out) == 0:
            break
        inside = out[:, axis] >= bound if keep_greater else out[:, axis] <= bound
        nxt = np.roll(out, -1, axis=0)
        nxt_in = np.roll(inside, -1)
        pts = []
        for p, q, pin, qin in zip(out, nxt, inside, nxt_in):
            if pin:
                pts.append(p)
            if pin != qin:
                t = (bound - p[axis]) / (q[axis] - p[axis])
                pts.append(p + t * (q - p))
        out = np.array(pts).reshape(-1, 2)
    return out


def part_outlines(parts_uv: list[np.ndarray], cam) -> list[np.ndarray]:
    """The delivered-image outlines (M, 2) of convex solids from their pinhole points ``parts_uv``
    (each (N, 2)): each one's convex hull, through ``cam``'s lens (:func:`distorted_region`) when it
    has distortion (the image of a convex solid is then no longer convex) or non-square pixels."""
    k = cam.k()
    if any(cam.distortion) or k[1, 1] != k[0, 0]:
        return [distorted_region(uv, cam) for uv in parts_uv]
    return [uv[cv2.convexHull(uv.astype(np.float32), returnPoints=False).ravel()] for uv in parts_uv]


def _bbox(points: np.ndarray) -> list[float]:
    return [float(points[:, 0].min()), float(points[:, 1].min()),
            float(points[:, 0].max()), float(points[:, 1].max())]


class IndexStats:
    """Pixel counts and boxes per value of an object-index pass, computed in one pass.

    ``index``: (H, W) int. Values 0..255 are counted; boxes are kept for the sparse values
    (markers, below 200) and for the union of each section's values.
    """

    def __init__(self, index: np.ndarray):
        self.shape = index.shape
        small = np.clip(index, 0, 255).astype(np.uint8)
        self.counts = np.bincount(small.ravel(), minlength=256)
        marker_mask = (small > 0) & (small < 200)
        ys, xs = np.nonzero(marker_mask)
        vals = small[ys, xs]
        self._pix = {int(v): (xs[vals == v], ys[vals == v]) for v in np.unique(vals)}
        self.small = small

    def chroma(self, value: int, image: np.ndarray, section: str) -> float | None:
        """Median marker-colour excess over the value's pixels in ``image`` (H, W, 3) uint8 RGB:
        red minus the larger of green and blue for A, blue minus the larger of red and green for B,
        in [0, 1]. None when the marker has no visible pixel."""
        if value not in self._pix:
            return None
        xs, ys = self._pix[value]
        px = image[ys, xs].astype(np.float32) / 255.0
        r, g, b = px[:, 0], px[:, 1], px[:, 2]
        c = r - np.maximum(g, b) if section == "A" else b - np.maximum(r, g)
        return float(np.median(c))

    def box(self, value: int) -> list[float] | None:
        if value not in self._pix:
            return None
        xs, ys = self._pix[value]
        return [float(xs.min()) - 0.5, float(ys.min()) - 0.5, float(xs.max()) + 0.5, float(ys.max()) + 0.5]

    def union_box(self, values) -> list[float] | None:
        lut = np.zeros(256, np.uint8)
        lut[list(values)] = 1
        x, y, w, h = cv2.boundingRect(lut[self.small])
        return None if w == 0 else [x - 0.5, y - 0.5, x + w - 0.5, y + h - 0.5]


def _projected_outline(outline_uv: np.ndarray, outline_z: np.ndarray, bounds) -> tuple[float, np.ndarray, np.ndarray]:
    """(full area px^2, centroid (2,) px, outline clipped to ``bounds`` (M, 2) px) of a projected
    marker outline; zero area, NaN centroid and an empty outline when part of it is behind the camera."""
    if not np.all(outline_z > 0):
        return 0.0, np.full(2, np.nan), np.zeros((0, 2))
    full_area, outline_centroid = polygon_area_centroid(outline_uv)
    inside = (outline_uv[:, 0].min() >= bounds[0] and outline_uv[:, 1].min() >= bounds[1]
              and outline_uv[:, 0].max() <= bounds[2] and outline_uv[:, 1].max() <= bounds[3])
    clipped = outline_uv if inside else clip_polygon(outline_uv, *bounds)
    return full_area, outline_centroid, clipped


def _marker_geometry(m, k: np.ndarray, coeffs, cam_from_d: np.ndarray, d_from_b: np.ndarray, bounds,
                     rolling: MovingB | None = None) -> dict:
    """The geometric part of a marker's label (projection, boxes, areas; no visibility), in the
    delivered image of K ``k`` (through the lens distortion ``coeffs``); a marker of B under the
    rolling shutter ``rolling`` with every point at its own row's time."""
    d_from_s = d_from_b if m.section == "B" else np.eye(4)
    centre_d = transform_points(d_from_s, np.array([m.center_mm]))[0]
    normal_d = d_from_s[:3, :3] @ np.asarray(m.normal)
    if rolling is not None and m.section == "B":
        pinhole, depth, _ = rolling.project(np.array([m.center_mm]))
        outline_pinhole, outline_z, _ = rolling.project(marker_outline(m))
        outline_uv = image_px(outline_pinhole, k, coeffs)
    else:
        pinhole, depth = project_points(pinhole_intrinsics(k), cam_from_d, centre_d[None])
        outline_uv, outline_z = marker_outline_px(m, k, coeffs, cam_from_d @ d_from_s)
    centre = image_px(pinhole, k, coeffs)[0]
    in_frame = bool(depth[0] > 0 and bounds[0] <= centre[0] <= bounds[2] and bounds[1] <= centre[1] <= bounds[3])
    full_area, outline_centroid, clipped = _projected_outline(outline_uv, outline_z, bounds)
    area_in_frame = full_area if len(clipped) == len(outline_uv) and full_area > 0 else polygon_area_centroid(clipped)[0]
    return {
        "id": m.id, "section": m.section, "class_id": m.class_id, "pass_index": m.pass_index,
        "center_section_mm": list(m.center_mm), "center_d_mm": centre_d.tolist(),
        "normal_d": normal_d.tolist(), "diameter_mm": m.diameter_mm,
        "center_px": centre.tolist(), "center_pinhole_px": ideal_px(pinhole, k)[0].tolist(),
        "depth_mm": float(depth[0]),
        "outline_centroid_px": outline_centroid.tolist(),
        "bbox_px": _bbox(clipped) if len(clipped) else None,
        "bbox_unclipped_px": _bbox(outline_uv) if np.all(outline_z > 0) else None,
        "in_frame": in_frame, "area_px": full_area, "area_in_frame_px": area_in_frame,
    }


def _clamped_box(points: np.ndarray, bounds) -> list[float] | None:
    """The box of ``points`` (N, 2) clamped to ``bounds``; None when it misses them or a point is NaN."""
    if not np.all(np.isfinite(points)):
        return None
    x0, y0, x1, y1 = _bbox(points)
    box = [max(x0, bounds[0]), max(y0, bounds[1]), min(x1, bounds[2]), min(y1, bounds[3])]
    return box if box[0] <= box[2] and box[1] <= box[3] else None


def _add_marker_motion(rec: dict, m, mb: MovingB, k: np.ndarray, coeffs, bounds) -> None:
    """Add a moving B marker's ``time_ms`` (its centre's exposure centre, from mid-exposure),
    ``blur_px`` (its centre's image path from the start to the end of that exposure) and
    ``bbox_swept_px`` (the box its outline sweeps over the exposure, within the image) to ``rec``,
    in the delivered image of K ``k`` with lens ``coeffs``."""
    offsets = exposure_offsets(mb)
    centre, outline = np.array([m.center_mm]), marker_outline(m)
    _, _, t = mb.project(centre)
    ends = [image_px(mb.project(centre, off)[0], k, coeffs)[0] for off in (offsets[0], offsets[-1])]
    swept = np.concatenate([image_px(mb.project(outline, off)[0], k, coeffs) for off in offsets])
    rec["time_ms"] = float(t[0]) * 1000.0
    rec["blur_px"] = (ends[1] - ends[0]).tolist()
    rec["bbox_swept_px"] = _clamped_box(swept, bounds)


def _add_marker_visibility(rec: dict, m, stats: IndexStats, image: np.ndarray | None,
                           visible_threshold: float, min_chroma: float) -> None:
    """Add the index pass's visibility (and, with ``image``, chroma and legibility) to ``rec``."""
    visible = int(stats.counts[m.pass_index])
    area_in_frame = rec["area_in_frame_px"]
    frac = min(1.0, visible / area_in_frame) if area_in_frame > 0 else 0.0
    rec["visible_pixels"] = visible
    rec["visible_fraction"] = frac
    rec["bbox_visible_px"] = stats.box(m.pass_index)
    rec["visibility"] = 0 if not rec["in_frame"] else (2 if frac >= visible_threshold else 1)
    if image is not None:
        chroma = stats.chroma(m.pass_index, image, m.section)
        rec["chroma"] = chroma
        rec["legible"] = chroma is not None and chroma >= min_chroma


def section_uv(pts: np.ndarray, sec: str, cam, cam_from_d: np.ndarray, d_from_b: np.ndarray,
                rolling: MovingB | None) -> np.ndarray | None:
    """Points ``pts`` (M, 3) mm of section ``sec`` in pinhole pixels (M, 2) (B's at their row times
    under the rolling shutter ``rolling``); None when one of them is behind the camera."""
    if rolling is not None and sec == "B":
        uv, z, _ = rolling.project(pts)
        return uv if np.all(z > 0) else None
    d_from_s = d_from_b if sec == "B" else np.eye(4)
    cam_pts = transform_points(cam_from_d @ d_from_s, pts)
    if not np.all(cam_pts[:, 2] > 0):
        return None
    return cam_pts[:, :2] / cam_pts[:, 2:] * cam.focal_px + np.asarray(cam.principal_point)


def _section_label(sec: str, static: StaticScene, cam, cam_from_d: np.ndarray, d_from_b: np.ndarray,
                   stats: IndexStats | None, rolling: MovingB | None = None) -> dict:
    """A section's label: its silhouette's pixels and box (generator.silhouette: the pixel centres
    inside the image of the flange or of the body; absent when part of the section is behind the
    camera), and with the index pass its visible part."""
    parts_uv = [section_uv(pts, sec, cam, cam_from_d, d_from_b, rolling) for pts in silhouette_parts(static, sec)]
    rec = {"section": sec, "pass_index": SECTION_PASS_INDEX[sec]}
    if all(uv is not None for uv in parts_uv):
        mask = outlines_mask(part_outlines(parts_uv, cam), cam.width, cam.height)
        rec["pixels_all"], rec["bbox_obj_px"] = mask_pixels(mask)
    if stats is not None:
        ids = [SECTION_PASS_INDEX[sec]] + [m.pass_index for m in static.markers if m.section == sec]
        rec["pixels_visible"] = int(stats.counts[ids].sum())
        rec["bbox_visible_px"] = stats.union_box(ids)
        rec["visible_fraction"] = (min(1.0, rec["pixels_visible"] / rec["pixels_all"])
                                   if rec.get("pixels_all") else 0.0)
    return rec


def sensor_record(sensor) -> dict:
    """The label's sensor: the sampled parameters; a colour camera's chain (CFA, EMVA 1288 figures,
    ISP) under "chain", absent for the three-chip model."""
    out = to_dict(sensor)
    if out.get("chain") is None:
        out.pop("chain", None)
    return out


def _sampled_record(frame: FrameScene) -> dict:
    return {
        "lights": [to_dict(light) for light in frame.lights],
        "props": [to_dict(p) for p in frame.props],
        "appearance": to_dict(frame.appearance),
        "sensor": sensor_record(frame.sensor),
        "glare_kind": frame.glare_kind,
        "render_seed": frame.render_seed,
        "render": to_dict(frame.render),
    }


MOTION_POSE_TIME = ("d_from_b is B at the middle of the exposure (t = 0); B at t seconds is d_from_b with "
                    "velocity_d_mm_s * t added to its translation (B does not turn)")
MOTION_ROW_TIME = ("row v of the render canvas (OpenCV rows, top = 0: the pinhole row less "
                   "camera.render_canvas.offset_px[1]; a pinhole camera's image row) is exposed over "
                   "[t(v) - exposure_ms / 2, t(v) + exposure_ms / 2] ms, t(v) = rolling_shutter_ms * "
                   "((v + 1) / canvas_rows - 1/2); a point of B is labelled where its own row's t images it "
                   "(center_d_mm and normal_d stay B's at t = 0)")
MOTION_PIXELS = ("centres, outlines, boxes, areas and silhouettes are geometry: B at t = 0 (global shutter) or each "
                 "point at its row's t (rolling shutter); visible_pixels, visible_fraction and bbox_visible_px come "
                 "from the index pass, which samples each pixel at one instant of its exposure window (its expected "
                 "pixel count is the marker's area); bbox_swept_px bounds a B marker's outline over its exposure")


def motion_record(frame: FrameScene, mb: MovingB) -> dict:
    """The label's motion: B's velocity, the shutter timing, B at shutter open and close, and what
    the labels mean under blur and a rolling shutter (MOTION_POSE_TIME, MOTION_ROW_TIME, MOTION_PIXELS)."""
    m = frame.motion
    half_s = m.shutter_ms() / 2000.0
    d_from_b = frame.d_from_b_array()
    return {"velocity_d_mm_s": list(m.velocity_mm_s), "exposure_ms": m.exposure_ms,
            "rolling_shutter_ms": m.readout_ms, "shutter": "rolling_top_first" if m.readout_ms > 0 else "global",
            "shutter_ms": m.shutter_ms(), "canvas_rows": mb.canvas_height,
            "d_from_b_open": m.d_from_b_at(d_from_b, -half_s).tolist(),
            "d_from_b_close": m.d_from_b_at(d_from_b, half_s).tolist(),
            "pose_time": MOTION_POSE_TIME, "row_time": MOTION_ROW_TIME, "pixels": MOTION_PIXELS}


def camera_record(cam) -> dict:
    """The label's camera: K (its principal point), pose, and the unit's lens: distortion in
    OpenCV's order, chromatic aberration, depth of field, JPEG quality, the render canvas."""
    ox, oy, wc, hc = cam.canvas()
    scales = cam.channel_scales()
    dof = None if cam.f_number <= 0 else {
        "f_number": cam.f_number, "focus_distance_mm": cam.focus_distance_mm, "focal_mm": cam.focal_mm(),
        "aperture_mm": cam.focal_mm() / cam.f_number}
    return {"K": cam.k().tolist(), "focal_px": cam.focal_px, "principal_point": list(cam.principal_point),
            "cam_from_d": cam.cam_from_d_array().tolist(), "look_at_mm": list(cam.look_at_mm),
            "distance_mm": cam.distance_mm, "unit": cam.unit, "distortion": list(cam.distortion),
            "distortion_names": list(COEFF_NAMES), "distortion_model": DISTORTION_MODEL,
            "aberration_px": {"red": cam.aberration_px[0], "blue": cam.aberration_px[1]},
            "aberration_scale": {"red": scales[0], "blue": scales[2]},
            "sensor_width_mm": cam.sensor_width_mm, "depth_of_field": dof,
            "jpeg_quality": cam.jpeg_quality or None,
            **({"jpeg_subsampling": cam.jpeg_subsampling} if cam.jpeg_quality else {}),
            "render_canvas": {"offset_px": [ox, oy], "width": wc, "height": hc}}


def frame_labels(frame: FrameScene, static: StaticScene, index: np.ndarray | None,
                 visible_threshold: float, derived: dict | None = None, image: np.ndarray | None = None,
                 min_chroma: float = MIN_CHROMA) -> dict:
    """The label record of one frame.

    ``index``: (H, W) int object-index pass, or None before rendering (visibility then unknown).
    ``derived``: values computed while rendering (e.g. the auto exposure scale).
    ``image``: (H, W, 3) uint8 RGB final image; with the index pass it gives each marker's
    ``chroma`` and ``legible`` (chroma >= ``min_chroma``: the disc's colour is not washed out by
    glare or lost in the dark). Geometric visibility stays in ``visibility``.
    A frame with motion also has ``motion`` (:func:`motion_record`) and, per marker of B, its
    ``time_ms``, ``blur_px`` and ``bbox_swept_px``; without motion the label has none of them.
    """
    cam = frame.camera
    w, h = cam.width, cam.height
    k = cam.k()
    cam_from_d = cam.cam_from_d_array()
    d_from_b = frame.d_from_b_array()
    stats = None
    if index is not None:
        if index.shape != (h, w):
            raise ValueError(f"index pass is {index.shape}, expected {(h, w)}")
        stats = IndexStats(index)
    bounds = (-0.5, -0.5, w - 0.5, h - 0.5)
    mb, rolling = moving_b(frame), rolling_view(frame)
    markers = []
    for m in static.markers:
        rec = _marker_geometry(m, k, cam.distortion, cam_from_d, d_from_b, bounds, rolling)
        if mb is not None and m.section == "B":
            _add_marker_motion(rec, m, mb, k, cam.distortion, bounds)
        if stats is not None:
            _add_marker_visibility(rec, m, stats, image, visible_threshold, min_chroma)
        markers.append(rec)
    sections = [_section_label(sec, static, cam, cam_from_d, d_from_b, stats, rolling) for sec in SECTIONS]
    return {
        "format": LABEL_FORMAT,
        "frame_id": frame.spec.frame_id,
        "spec": to_dict(frame.spec),
        "conditions": [frame.spec.condition] + ([frame.glare_kind] if frame.glare_kind != "none" else []),
        "image": {"width": w, "height": h, "pixel_convention": "opencv: (0,0) is the centre of the top-left pixel"},
        "camera": camera_record(cam),
        "d_from_b": d_from_b.tolist(),
        "pose_b_in_d": pose_components(d_from_b),
        **({"motion": motion_record(frame, mb)} if mb is not None else {}),
        "markers": markers,
        "sections": sections,
        "sampled": _sampled_record(frame),
        "derived": derived or {},
    }
