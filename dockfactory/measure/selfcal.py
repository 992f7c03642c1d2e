"""Online self-calibration of a stream (``measure --video/--camera --self-calibrate window:N``): the
camera's intrinsics refined over a sliding window of the last N frames with a pose, as ``measure
--self-calibrate sequence`` does for a whole docking run, and frozen on request.

``freeze_after`` F: after F frames solved jointly, the principal point and distortion of the last
joint solve are frozen (``frozen_intrinsics`` in the record): each later frame's identified centres
are undistorted with them and solved alone with the pinhole model around the frozen principal
point (the focal length is still estimated per frame: the solver always estimates it). Freezing
stops the window's cost (a joint solve per frame) and the drift of intrinsics on a long stream.

Why and how: docs/measure.md, "Online self-calibration".
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import numpy as np

from dockfactory.core.distortion import undistort_pixels
from dockfactory.eval.camera_classes import classes_factor
from dockfactory.eval.solve_frames import solve_run
from dockfactory.solver import DockingOptions
from dockfactory.solver.options import DEFAULT_DOCKING

MIN_FRAMES = 3     # frames in the window before a joint solve (fewer barely determine the intrinsics)
MAX_WINDOW = 200   # a joint solve's cost grows with the window


def parse_window(text: str) -> int:
    """N of ``window:N`` (2 <= N <= MAX_WINDOW); ValueError otherwise."""
    head, _, n = text.partition(":")
    if head != "window" or not n.isdigit() or not 2 <= int(n) <= MAX_WINDOW:
        raise ValueError(f"expected window:N with N in [2, {MAX_WINDOW}], got {text!r}")
    return int(n)


@dataclass
class WindowCalibration:
    """``apply(index, frame)`` -> the frame's record after the window's joint solve (the module
    docstring); ``frame`` a measure.Frame solved alone (pinhole), with its ``used_points`` and
    its record's ``camera_class``, which the joint record keeps and whose factor the run gate takes
    (of the window's frames: the largest, eval.camera_classes.classes_factor)."""
    markers: tuple
    window: int
    camera_model: str = "auto"
    freeze_after: int | None = None
    options: DockingOptions = DEFAULT_DOCKING
    frames: deque = field(default_factory=deque)
    joint: int = 0
    frozen: dict | None = None

    def apply(self, index: int, frame) -> dict:
        record = frame.record
        if not record["ok"] or not frame.used_points:
            return record
        if self.frozen is not None:
            return self._frozen(index, frame)
        self.frames.append((str(index), frame.used_points, record["n_detections"],
                            record.get("camera_class", "three-chip")))
        while len(self.frames) > self.window:
            self.frames.popleft()
        if len(self.frames) < MIN_FRAMES:
            return {**record, "self_calibration": f"window of {len(self.frames)} frames: solved alone"}
        keys = [k for k, *_ in self.frames]
        out = solve_run(self.markers, frame.principal_point, keys, {k: {"n_detections": n} for k, _, n, *_ in self.frames},
                        {k: used for k, used, *_ in self.frames}, None, self.camera_model, self.options,
                        classes_factor(c for *_, c in self.frames))[str(index)]
        if not out["ok"]:
            return {**record, "self_calibration": f"window solve failed, solved alone: {out['reason']}"}
        self.joint += 1
        if self.freeze_after is not None and self.joint >= self.freeze_after:
            self.frozen = {"camera_model": out["camera_model"], "focal_px": out["focal_px"], **out["intrinsics"]}
        return {**out, **kept_from_frame(record), "self_calibrated": "window"}

    def _frozen(self, index: int, frame) -> dict:
        """The frame's centres undistorted with the frozen intrinsics, solved alone (pinhole)."""
        fz = self.frozen
        pp = (fz["cx"], fz["cy"])
        ids = list(frame.used_points)
        uv = undistort_pixels(np.array([frame.used_points[i] for i in ids]), fz["focal_px"], pp,
                              [fz.get(k, 0.0) for k in ("k1", "k2", "p1", "p2")] + [0.0])
        key = str(index)
        out = solve_run(self.markers, pp, [key], {key: {"n_detections": frame.record["n_detections"]}},
                        {key: dict(zip(ids, map(tuple, uv)))}, None, "pinhole", self.options,
                        classes_factor([frame.record.get("camera_class", "three-chip")]))[key]
        if not out["ok"]:
            return {**frame.record, "self_calibration": f"frozen-intrinsics solve failed: {out['reason']}"}
        return {**out, **kept_from_frame(frame.record), "camera_model": fz["camera_model"], "frozen_intrinsics": dict(fz),
                "self_calibrated": "frozen"}


def kept_from_frame(record: dict) -> dict:
    """What a frame's own record keeps when a joint record (a window's, a frozen solve's, or
    ``measure --self-calibrate sequence``'s) replaces it: its image size, timings, region of
    interest, ``camera_class`` (eval.camera_classes) and ``notes`` (the decoder's messages and
    the warnings raised measuring it), those it has."""
    return {k: record[k] for k in ("image_size", "timing_ms", "roi", "camera_class", "notes") if k in record}
