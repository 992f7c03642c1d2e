"""The true cameras of a config's test frames, as a bound or a prediction needs them (pure, no
render): what eval.frame_planner and eval.design_predict propagate their noise through."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dockfactory.core.errors import DockfactoryError
from dockfactory.generator.sampler import frame_plan, frame_geometry

__all__ = ["FrameCameras", "cameras_of_test_frames"]


@dataclass(frozen=True)
class FrameCameras:
    """One test frame: ``cam_from_a`` and ``cam_from_b`` (4, 4; A's frame is D), ``focal_px`` (fx),
    ``principal_point`` (2,) px and ``pixel_aspect`` (fy / fx of its delivered image)."""
    cam_from_a: np.ndarray
    cam_from_b: np.ndarray
    focal_px: float
    principal_point: np.ndarray
    pixel_aspect: float = 1.0


def cameras_of_test_frames(cfg, max_frames: int, what: str) -> list[FrameCameras]:
    """The first ``max_frames`` test frames of ``cfg`` (generator.sampler.frame_geometry: where B
    and the camera are in the frames a render of it would draw). DockfactoryError "``what``: the config plans no test frame" when there is
    none; ConfigError when a frame cannot fit its markers."""
    specs = [s for s in frame_plan(cfg) if s.split == "test"][:max_frames]
    if not specs:
        raise DockfactoryError(f"{what}: the config plans no test frame")
    out = []
    for spec in specs:
        d_from_b, camera = frame_geometry(cfg, spec)
        cam = camera.cam_from_d_array()
        out.append(FrameCameras(cam, cam @ np.asarray(d_from_b, dtype=float), float(camera.focal_px),
                                np.asarray(camera.principal_point, dtype=float), float(camera.pixel_aspect)))
    return out
