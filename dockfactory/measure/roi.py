"""Region-of-interest tracking for the stream path of measure: between full-frame detections, the
detector sees only a window around where the markers were in the previous frame.

The window's size is fixed at each full-frame detection (the markers' boxes, grown by ``margin``
of their extent on each side and at least ``pad_px``, rounded up to ``step_px``), so the network
sees one input shape (ONNX Runtime builds one session per shape) while the window follows the
markers' centre. A full frame is detected again every ``refresh`` frames, when the previous
frame had no detections, and whenever the window finds fewer detections than the last full frame
did or one touches its border (the caller then detects the full frame for that frame: no marker
is lost to the window). Corners are even (a Bayer pattern keeps its phase). Pixels: OpenCV's.
"""
from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass
class RoiTracker:
    """``region()`` -> the window (x0, y0, x1, y1) to detect in, or None for the full frame;
    ``lost(detections, roi)`` -> whether that window's detections call for the full frame;
    ``update(detections, roi)`` after each frame with what was detected (``roi`` None: full)."""
    width: int
    height: int
    refresh: int = 10
    margin: float = 0.25
    pad_px: int = 48
    step_px: int = 64
    min_score: float = 0.0
    size: tuple | None = None
    centre: tuple | None = None
    expected: int = 0
    since_full: int = 0

    def __post_init__(self):
        if self.refresh < 1 or self.width < 2 or self.height < 2:
            raise ValueError(f"RoiTracker: refresh >= 1 and a frame of 2x2 or more, got {self}")

    def _scored(self, detections) -> list:
        return [d for d in detections if d.get("score", 1.0) >= self.min_score]

    def region(self) -> tuple | None:
        if self.size is None or self.centre is None or self.since_full >= self.refresh - 1:
            return None
        w, h = self.size
        x0 = int(min(max(self.centre[0] - w / 2, 0), self.width - w)) // 2 * 2
        y0 = int(min(max(self.centre[1] - h / 2, 0), self.height - h)) // 2 * 2
        return x0, y0, min(x0 + w, self.width), min(y0 + h, self.height)

    def lost(self, detections, roi: tuple) -> bool:
        dets = self._scored(detections)
        if len(dets) < self.expected:
            return True
        x0, y0, x1, y1 = roi
        edge = 2.0
        return any((b[0] - x0 < edge and x0 > 0) or (b[1] - y0 < edge and y0 > 0)
                   or (x1 - b[2] < edge and x1 < self.width) or (y1 - b[3] < edge and y1 < self.height)
                   for b in (d["bbox_px"] for d in dets))

    def update(self, detections, roi: tuple | None) -> None:
        dets = self._scored(detections)
        if not dets:
            self.size = self.centre = None
            return
        u0 = min(d["bbox_px"][0] for d in dets)
        v0 = min(d["bbox_px"][1] for d in dets)
        u1 = max(d["bbox_px"][2] for d in dets)
        v1 = max(d["bbox_px"][3] for d in dets)
        self.centre = ((u0 + u1) / 2, (v0 + v1) / 2)
        if roi is None:
            self.expected, self.since_full = len(dets), 0
            grow = [max(self.margin * (u1 - u0), self.pad_px), max(self.margin * (v1 - v0), self.pad_px)]
            w = min(self.width, self.step_px * math.ceil((u1 - u0 + 2 * grow[0]) / self.step_px))
            h = min(self.height, self.step_px * math.ceil((v1 - v0 + 2 * grow[1]) / self.step_px))
            self.size = (w // 2 * 2, h // 2 * 2)
        else:
            self.since_full += 1
