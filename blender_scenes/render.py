"""The adapter's API to the render worker: build the Blender scene once, render frame after frame.

Only this package imports bpy; the worker process (``dockfactory.generator.render_worker``) drives
it through :class:`BlenderRenderer` and post-processes the EXR without bpy.
"""
from __future__ import annotations

import time

import bpy

from dockfactory.blender_scenes.frame_update import apply_frame, scene_state
from dockfactory.blender_scenes.scene_builder import build_scene
from dockfactory.core.scene import FrameScene, StaticScene


def blender_version() -> str:
    return bpy.app.version_string


class BlenderRenderer:
    """One Blender scene built from a static description, updated and rendered per frame."""

    def __init__(self, static: StaticScene, width: int, height: int, threads: int, exr_path: str):
        self.handles = build_scene(static, width, height, threads, exr_path)

    def render(self, frame: FrameScene, exr_path: str) -> dict[str, float]:
        """Render ``frame`` into the multilayer EXR ``exr_path``; wall seconds of each phase."""
        t0 = time.perf_counter()
        self.handles.scene.render.filepath = exr_path
        apply_frame(self.handles, frame)
        t1 = time.perf_counter()
        bpy.ops.render.render(write_still=True)
        return {"scene_update": t1 - t0, "cycles": time.perf_counter() - t1}

    def state(self, frame: FrameScene) -> dict:
        """Apply ``frame`` without rendering; the Blender state a render would read (see
        :func:`~dockfactory.blender_scenes.frame_update.scene_state`)."""
        apply_frame(self.handles, frame)
        return scene_state(self.handles)
