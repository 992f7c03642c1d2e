"""Section silhouettes as generators before the silhouette fix drew them: for ``dataset verify``
against a dataset published by such a generator, never for a new label.

Before the fix a section's ``pixels_all`` and ``bbox_obj_px`` were the pixel centres inside the
convex hull of the images of its three end circles (flange and body together), filled by OpenCV
with its 1/16-px vertices: 2.2 % more pixels than the section's image (the section is not convex:
generator/silhouette.py; the measurement: bench/results/tool_checks/README.md). The
published paper dataset was labelled that way. A re-render by today's generator labels its
sections correctly, so its label cannot equal the published one byte for byte; verify replaces the
two fields by what this module computes for the same frame and compares again, and says so
(generator.datasets.published). Everything else of the label must still match.
"""
from __future__ import annotations

from dockfactory.core.cv import cv2
import numpy as np

from dockfactory.core.layout import SECTIONS
from dockfactory.core.scene import FrameScene, StaticScene
from dockfactory.generator.labels import section_uv, distorted_region
from dockfactory.generator.motion import rolling_view
from dockfactory.generator.silhouette import section_silhouette

LEGACY_FIELDS = ("pixels_all", "bbox_obj_px")


def _filled(mask: np.ndarray) -> tuple[int, list[float] | None]:
    count = int(cv2.countNonZero(mask))
    x, y, bw, bh = cv2.boundingRect(mask)
    return count, (None if count == 0 else [x - 0.5, y - 0.5, x + bw - 0.5, y + bh - 0.5])


def _legacy_pixels(uv: np.ndarray, cam) -> tuple[int, list[float] | None]:
    """(count, box) of the legacy fill of the hull points ``uv`` (pinhole px): the convex hull,
    or with distortion (or non-square pixels) the distorted outline as a polygon."""
    mask = np.zeros((cam.height, cam.width), np.uint8)
    if any(cam.distortion) or cam.pixel_aspect != 1.0:
        poly = distorted_region(uv, cam)
        if len(poly) >= 3:
            cv2.fillPoly(mask, [np.round(poly * 16).astype(np.int32)], 1, cv2.LINE_8, 4)
    else:
        cv2.fillConvexPoly(mask, cv2.convexHull(np.round(uv * 16).astype(np.int32)), 1, cv2.LINE_8, 4)
    return _filled(mask)


def legacy_section_fields(frame: FrameScene, static: StaticScene) -> dict:
    """{section: (pixels_all, bbox_obj_px) as the legacy label had them, or None when the legacy
    label had neither (part of the section behind the camera)}."""
    cam, out = frame.camera, {}
    for sec in SECTIONS:   # the hull of its three end circles, B's at their row times under a rolling shutter
        uv = section_uv(section_silhouette(static, sec), sec, cam, cam.cam_from_d_array(), frame.d_from_b_array(),
                         rolling_view(frame))
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
