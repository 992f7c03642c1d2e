"""Section B moving during the exposure (pure numpy): the frame's motion draws, B's pose at a
time, and where a rolling shutter images each point of B.

Time t (seconds here, ms in configs and labels) runs from the middle of the exposure: B at t = 0
is the frame's ``d_from_b``, and B at t is ``d_from_b`` translated by ``velocity * t`` (constant
velocity in D, no rotation; ``core.scene.MotionParams``).

A global shutter exposes every row over [-E/2, E/2] (labels: B at t = 0); a rolling shutter (readout R)
exposes each row of the render canvas at its own time t(v), and a point of B is imaged where its projection
at its own row's time lands (a fixed point, solved by Newton's method).

Why and how: docs/motion.md, "Global and rolling shutter".
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dockfactory.core.config import ConfigError, MotionConfig
from dockfactory.core.geometry import check_array, pinhole_intrinsics, transform_points
from dockfactory.core.scene import FrameScene, MotionParams, vec
from dockfactory.generator.random_draws import STREAM_FRAME_ISP, STREAM_FRAME_MOTION, rng_for, uniform

FIXED_POINT_TOL_PX = 1e-6    # Newton stops once a step moves no image point by more than this
FIXED_POINT_MAX_STEPS = 30
SWEEP_STEPS = 9              # instants across an exposure window for the swept boxes


def frame_motion(motion: MotionConfig, exposure_time_ms: tuple[float, float], seed: int,
                 index: int) -> MotionParams | None:
    """The motion of frame ``index`` (``FrameSpec.index``): None without [motion] (nothing is
    drawn). B's velocity in D (mm/s) comes from the frame's own STREAM_FRAME_MOTION stream of the
    dataset ``seed`` (the closing speed toward A, then the Y and Z components); the exposure (ms)
    is the frame's draw from [sensor] ``exposure_time_ms``, the first draw of its STREAM_FRAME_ISP
    stream (the colour chain's exposure time, when there is one)."""
    if not motion.enabled:
        return None
    rng = rng_for(seed, STREAM_FRAME_MOTION, index)
    velocity = (0.0 - uniform(rng, motion.velocity_mm_s), uniform(rng, motion.velocity_y_mm_s),
                uniform(rng, motion.velocity_z_mm_s))
    exposure_ms = uniform(rng_for(seed, STREAM_FRAME_ISP, index), exposure_time_ms)
    return MotionParams(vec(velocity), exposure_ms, motion.rolling_shutter_ms)


def row_time_s(rows, canvas_height: int, readout_s: float) -> np.ndarray:
    """Exposure centre (s from mid-exposure) of canvas rows ``rows`` (any shape; OpenCV pixel
    rows, top = 0, continuous) of a rolling shutter reading ``canvas_height`` rows in
    ``readout_s``: readout * ((row + 1) / height - 1/2)."""
    if canvas_height < 1 or not readout_s >= 0:
        raise ValueError(f"need canvas_height >= 1 and readout_s >= 0, got {canvas_height}, {readout_s}")
    return readout_s * ((np.asarray(rows, dtype=np.float64) + 1.0) / canvas_height - 0.5)


@dataclass(frozen=True, eq=False)
class MovingB:
    """Section B as a frame's camera sees it in motion.

    ``k``: (3, 3) the render's pinhole K (square pixels: ``CameraModel.pinhole_k``);
    ``cam_from_d``, ``d_from_b``: (4, 4), B at mid-exposure; ``velocity_mm_s``: (3,) in D; ``exposure_s``, ``readout_s`` (>= 0): as ``MotionParams``;
    ``row_offset``: pinhole row of canvas row 0 (canvas row = pinhole row - row_offset);
    ``canvas_height`` (>= 1): rows the rolling shutter reads. Arrays are checked (shape, finite)
    and stored as float64; bad values raise ValueError.
    """
    k: np.ndarray
    cam_from_d: np.ndarray
    d_from_b: np.ndarray
    velocity_mm_s: np.ndarray
    exposure_s: float
    readout_s: float
    row_offset: float
    canvas_height: int

    def __post_init__(self):
        for name, shape in (("k", (3, 3)), ("cam_from_d", (4, 4)), ("d_from_b", (4, 4)), ("velocity_mm_s", (3,))):
            object.__setattr__(self, name, check_array(name, getattr(self, name), shape))
        timing_ok = self.exposure_s >= 0 and self.readout_s >= 0 and self.canvas_height >= 1
        if not (timing_ok and np.isfinite(self.row_offset)):
            raise ValueError(f"bad timing: exposure_s {self.exposure_s}, readout_s {self.readout_s}, "
                             f"row_offset {self.row_offset}, canvas_height {self.canvas_height}")

    def project(self, points_b, offset_s: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Where the canvas images points ``points_b`` (N, 3) mm of B's frame at ``offset_s`` from
        the exposure centre of the row that images each: (uv (N, 2) pinhole px, depth (N,) mm,
        time (N,) s from mid-exposure). The time solves t = row_time(v(t)) + offset_s, v(t) the
        point's pinhole row at t (a global shutter: t = offset_s). NaN pixels behind the camera;
        ValueError when the fixed point does not converge."""
        x0 = transform_points(self.cam_from_d @ self.d_from_b, points_b)
        w = self.cam_from_d[:3, :3] @ self.velocity_mm_s
        t = np.full(len(x0), float(offset_s))
        if self.readout_s > 0:
            t = self._solve(x0, w, t)
        xc = x0 + t[:, None] * w
        z = xc[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            uv = (xc @ self.k.T)[:, :2] / z[:, None]
        uv[z <= 0] = np.nan
        return uv, z, t

    def row_rate(self, points_b) -> float:
        """The largest |d(row time)/dt| of points ``points_b`` (N, 3) mm of B over the shutter: the
        share of a row's readout delay that their image's vertical motion covers. Below 1 every
        point is imaged exactly once and Newton's method converges."""
        x0 = transform_points(self.cam_from_d @ self.d_from_b, points_b)
        w = self.cam_from_d[:3, :3] @ self.velocity_mm_s
        half = (self.exposure_s + self.readout_s) / 2
        worst = 0.0
        for t in np.linspace(-half, half, 5):
            xc = x0 + t * w
            dv_dt = self.k[1, 1] * (w[1] * xc[:, 2] - xc[:, 1] * w[2]) / xc[:, 2] ** 2
            worst = max(worst, float(np.max(np.abs(dv_dt))) * self.readout_s / self.canvas_height)
        return worst

    def _row_time(self, v: np.ndarray) -> np.ndarray:
        return row_time_s(v - self.row_offset, self.canvas_height, self.readout_s)

    def _solve(self, x0: np.ndarray, w: np.ndarray, offset: np.ndarray) -> np.ndarray:
        """Newton on g(t) = t - row_time(v(t)) - offset, per point in front of the camera (x0: (N, 3)
        camera-frame points at t = 0, w: (3,) their velocity, mm/s); the others keep ``offset``."""
        (fx, _, _), (_, fy, cy) = self.k[0], self.k[1]
        rate = self.readout_s / self.canvas_height            # s per row
        out = offset.copy()
        ok = x0[:, 2] > 0
        x0, t = x0[ok], offset[ok].copy()
        for _ in range(FIXED_POINT_MAX_STEPS):
            xc = x0 + t[:, None] * w
            z2 = xc[:, 2] ** 2
            du_dt = fx * (w[0] * xc[:, 2] - xc[:, 0] * w[2]) / z2
            dv_dt = fy * (w[1] * xc[:, 2] - xc[:, 1] * w[2]) / z2
            v = fy * xc[:, 1] / xc[:, 2] + cy
            step = (t - self._row_time(v) - offset[ok]) / (1.0 - rate * dv_dt)
            t = t - step
            if np.all(np.abs(step) * np.hypot(du_dt, dv_dt) <= FIXED_POINT_TOL_PX):
                out[ok] = t
                return out
        raise ValueError("rolling shutter: the row-time fixed point did not converge (B crosses the rows "
                         "faster than the shutter reads them)")


def moving_b(frame: FrameScene) -> MovingB | None:
    """The frame's :class:`MovingB`; None for a frame without motion."""
    m = frame.motion
    if m is None:
        return None
    cam = frame.camera
    _, oy, _, hc = cam.canvas()
    return MovingB(cam.pinhole_k(), cam.cam_from_d_array(), frame.d_from_b_array(), np.array(m.velocity_mm_s),
                   m.exposure_ms / 1000.0, m.readout_ms / 1000.0, float(oy), int(hc))


def rolling_view(frame: FrameScene) -> MovingB | None:
    """The frame's :class:`MovingB` when its rolling shutter images B moving (B's labels then need
    row times), else None (B's labels are those of its ``d_from_b``)."""
    m = frame.motion
    return moving_b(frame) if m is not None and m.readout_ms > 0 and m.moves() else None


def label_rolling_view(label: dict) -> MovingB | None:
    """:func:`rolling_view` of the frame a label describes (its camera, ``d_from_b`` and ``motion``
    record): what consumers that reproject a label's geometry (exports) must use for B."""
    m, cam = label.get("motion"), label["camera"]
    if not m or not m["rolling_shutter_ms"] > 0 or not m["shutter_ms"] > 0 or not any(m["velocity_d_mm_s"]):
        return None
    return MovingB(pinhole_intrinsics(cam["K"]), np.asarray(cam["cam_from_d"], dtype=np.float64),
                   np.asarray(label["d_from_b"], dtype=np.float64), np.asarray(m["velocity_d_mm_s"], dtype=np.float64),
                   m["exposure_ms"] / 1000.0, m["rolling_shutter_ms"] / 1000.0,
                   float(cam["render_canvas"]["offset_px"][1]), int(m["canvas_rows"]))


MAX_ROW_RATE = 0.5   # a frame whose B crosses rows faster than half the readout's pace is refused


def check_rolling(frame: FrameScene, points_b) -> None:
    """Raise ConfigError when the frame's rolling shutter cannot image B's points ``points_b``
    (N, 3) mm once each: their rows move at more than MAX_ROW_RATE of the readout's pace."""
    rolling = rolling_view(frame)
    if rolling is None:
        return
    rate = rolling.row_rate(points_b)
    if not rate < MAX_ROW_RATE:
        raise ConfigError(f"[motion] rolling_shutter_ms: frame {frame.spec.frame_id}: B's image crosses rows at "
                          f"{rate:.2f} of the readout's pace (limit {MAX_ROW_RATE}); lower the speeds or the readout")


def exposure_offsets(mb: MovingB, steps: int = SWEEP_STEPS) -> np.ndarray:
    """``steps`` instants (s) across a row's exposure window, from its start to its end."""
    return np.linspace(-mb.exposure_s / 2, mb.exposure_s / 2, steps)
