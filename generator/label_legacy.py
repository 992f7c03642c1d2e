"""Section silhouettes as generators before the silhouette fix drew them: for ``dataset verify``
against a dataset published by such a generator, never for a new label.

Before the fix a section's ``pixels_all`` and ``bbox_obj_px`` were the pixel centres inside the
convex hull of the images of its three end circles (flange and body together), filled by OpenCV
with its 1/16-px vertices: 2.2 % more pixels than the section's image (the section is not convex:
generator/silhouette.py, bench/results/tool_checks/section_silhouette_2026-12-02.txt). The
published paper dataset was labelled that way. A re-render by today's generator labels its
sections correctly, so its label cannot equal the published one byte for byte; verify replaces the
two fields by what this module computes for the same frame and compares again, and says so
(generator.published). Everything else of the label must still match.
"""
from __future__ import annotations

import cv2
import numpy as np

from dockfactory.core.geometry import transform_points
from dockfactory.core.layout import SECTIONS
from dockfactory.core.scene import FrameScene, StaticScene
from dockfactory.generator.labels import distorted_region
from dockfactory.generator.motion import rolling_view

LEGACY_FIELDS = ("pixels_all", "bbox_obj_px")


def hull_points(static: StaticScene, section: str, n: int = 128) -> np.ndarray:
    """Points (3 n, 3) mm in the section frame: its three end circles (flange face, flange back,
    far end), whose convex hull the legacy label took for the section."""
    a = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    sign = -1.0 if section == "A" else 1.0
    rings = []
    for x, r in ((0.0, static.radius_mm + static.flange_height_mm),
                 (sign * static.flange_width_mm, static.radius_mm + static.flange_height_mm),
                 (sign * static.length_mm, static.radius_mm)):
        rings.append(np.stack([np.full(n, x), r * np.sin(a), r * np.cos(a)], axis=1))
    return np.concatenate(rings)


def _filled(mask: np.ndarray) -> tuple[int, list[float] | None]:
    count = int(cv2.countNonZero(mask))
    x, y, bw, bh = cv2.boundingRect(mask)
    return count, (None if count == 0 else [x - 0.5, y - 0.5, x + bw - 0.5, y + bh - 0.5])


def _legacy_pixels(uv: np.ndarray, cam) -> tuple[int, list[float] | None]:
    """(count, box) of the legacy fill of the hull points ``uv`` (pinhole px): the convex hull,
    or with distortion the distorted outline as a polygon."""
    mask = np.zeros((cam.height, cam.width), np.uint8)
    if any(cam.distortion):
        poly = distorted_region(uv, cam)
        if len(poly) >= 3:
            cv2.fillPoly(mask, [np.round(poly * 16).astype(np.int32)], 1, cv2.LINE_8, 4)
    else:
        cv2.fillConvexPoly(mask, cv2.convexHull(np.round(uv * 16).astype(np.int32)), 1, cv2.LINE_8, 4)
    return _filled(mask)


def _hull_uv(frame: FrameScene, static: StaticScene, sec: str) -> np.ndarray | None:
    """The hull points of ``sec`` in pinhole pixels (B's at their row times under a rolling
    shutter that images B moving); None when one is behind the camera."""
    cam, pts = frame.camera, hull_points(static, sec)
    rolling = rolling_view(frame)
    if rolling is not None and sec == "B":
        uv, z, _ = rolling.project(pts)
        return uv if np.all(z > 0) else None
    d_from_s = frame.d_from_b_array() if sec == "B" else np.eye(4)
    cam_pts = transform_points(cam.cam_from_d_array() @ d_from_s, pts)
    if not np.all(cam_pts[:, 2] > 0):
        return None
    return cam_pts[:, :2] / cam_pts[:, 2:] * cam.focal_px + np.asarray(cam.principal_point)


def legacy_section_fields(frame: FrameScene, static: StaticScene) -> dict:
    """{section: (pixels_all, bbox_obj_px) as the legacy label had them, or None when the legacy
    label had neither (part of the section behind the camera)}."""
    out = {}
    for sec in SECTIONS:
        uv = _hull_uv(frame, static, sec)
        out[sec] = None if uv is None else _legacy_pixels(uv, frame.camera)
    return out


def with_legacy_sections(label: dict, fields: dict) -> dict:
    """``label`` (parsed, changed in place and returned) with each section's LEGACY_FIELDS replaced
    by ``fields`` (:func:`legacy_section_fields`)."""
    for rec in label.get("sections", []):
        legacy = fields.get(rec.get("section"))
        for key in LEGACY_FIELDS:
            rec.pop(key, None)
        if legacy is not None:
            rec["pixels_all"], rec["bbox_obj_px"] = legacy
    return label
