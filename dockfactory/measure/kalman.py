"""A display filter for the stream path of measure: a constant-velocity Kalman filter on X, Y and
alpha, one independent two-state filter (value, rate) per component.

It smooths what an operator watches; it never replaces a measurement: the stream writes the raw
per-frame pose beside the filtered one (dockfactory.measure.stream). Its inputs are each frame's
pose and its 1-sigma standard deviations (the solver's covariance) as the measurement noise, and
the time between frames; a frame without a pose only predicts. Process noise: a white
acceleration of spectral density ``accel`` per component (mm^2/s^3 for X and Y, deg^2/s^3 for
alpha): how fast an operator may change the motion of B. Units follow the pose (mm, deg, s).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

FILTERED = ("x_mm", "y_mm", "alpha_deg")
DEFAULT_ACCEL = {"x_mm": 100.0, "y_mm": 100.0, "alpha_deg": 1.0}   # (mm or deg)^2 / s^3: a hand-driven B
MIN_STD = 1e-6   # a floor on the measurement's standard deviation (a zero one would freeze the filter)


@dataclass
class _Axis:
    """The state (value, rate) and its 2x2 covariance of one component; None until its first value."""
    accel: float
    x: np.ndarray | None = None
    p: np.ndarray | None = None

    def predict(self, dt: float) -> None:
        if self.x is None or dt <= 0:
            return
        f = np.array([[1.0, dt], [0.0, 1.0]])
        q = self.accel * np.array([[dt ** 3 / 3, dt ** 2 / 2], [dt ** 2 / 2, dt]])
        self.x = f @ self.x
        self.p = f @ self.p @ f.T + q

    def update(self, z: float, std: float) -> None:
        r = max(std, MIN_STD) ** 2
        if self.x is None:   # the first value: the rate is unknown (a wide prior)
            self.x = np.array([z, 0.0])
            self.p = np.diag([r, 1e6])
            return
        s = self.p[0, 0] + r
        k = self.p[:, 0] / s
        self.x = self.x + k * (z - self.x[0])
        self.p = self.p - np.outer(k, self.p[0, :])


class PoseKalman:
    """``step(t_s, pose, std)`` -> the filtered X, Y, alpha and their rates at time ``t_s``
    (seconds, non-decreasing). ``pose``/``std``: dicts holding at least :data:`FILTERED`, or None
    for a frame without a pose (prediction only). Returns None before the first pose."""

    def __init__(self, accel: dict | None = None):
        accel = {**DEFAULT_ACCEL, **(accel or {})}
        if any(not (np.isfinite(v) and v > 0) for v in accel.values()):
            raise ValueError(f"Kalman process noise must be finite and > 0, got {accel}")
        self.axes = {name: _Axis(float(accel[name])) for name in FILTERED}
        self.t: float | None = None

    def step(self, t_s: float, pose: dict | None, std: dict | None) -> dict | None:
        dt = 0.0 if self.t is None else t_s - self.t
        if dt < 0:
            raise ValueError(f"Kalman filter: time went backwards ({self.t} s -> {t_s} s)")
        self.t = t_s
        for name, axis in self.axes.items():
            axis.predict(dt)
            if pose is not None:
                axis.update(float(pose[name]), float(std[name]))
        if any(a.x is None for a in self.axes.values()):
            return None
        out = {name: float(a.x[0]) for name, a in self.axes.items()}
        out.update({f"std_{name}": float(np.sqrt(a.p[0, 0])) for name, a in self.axes.items()})
        out.update({f"rate_{name}_per_s": float(a.x[1]) for name, a in self.axes.items()})
        return out
