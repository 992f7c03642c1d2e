"""The adapter's API to the render worker: build the Blender scene once, render frame after frame.

Only this package imports bpy; the worker process (``dockfactory.generator.render_worker``) drives
it through :class:`BlenderRenderer` and post-processes the EXR without bpy.
"""
from __future__ import annotations

import time

import bpy

from dockfactory.blender_scenes.crops import render_coverage, render_crops
from dockfactory.blender_scenes.frame_update import apply_frame, scene_state
from dockfactory.blender_scenes.scene_builder import build_scene
from dockfactory.core.scene import FrameScene, StaticScene


def blender_version() -> str:
    return bpy.app.version_string


GPU_BACKENDS = ("OPTIX", "CUDA", "HIP")   # Cycles' GPU backends, in the order they are preferred


def gpu_devices() -> dict[str, list[str]]:
    """Cycles' GPU devices on this machine by backend ({"CUDA": ["NVIDIA ..."], ...}; empty: none
    usable), found through the Cycles add-on's preferences."""
    prefs = bpy.context.preferences.addons["cycles"].preferences
    found = {}
    for backend in GPU_BACKENDS:
        try:
            prefs.compute_device_type = backend
        except TypeError:   # a backend this Blender build does not have
            continue
        prefs.refresh_devices()
        names = [d.name for d in prefs.devices if d.type == backend]
        if names:
            found[backend] = names
    return found


def use_device(scene, device: str) -> str:
    """Render ``scene`` on ``device`` ("cpu", or "gpu": every device of the first backend of
    :data:`GPU_BACKENDS` that has one, the CPU left out); returns what it chose, e.g. "CUDA:
    NVIDIA L4". RuntimeError when "gpu" finds none (the job checks that before it starts)."""
    if device == "cpu":
        scene.cycles.device = "CPU"
        return "CPU"
    found = gpu_devices()
    if device != "gpu" or not found:
        raise RuntimeError(f"render device {device!r}: " + ("no usable GPU (Cycles finds no OptiX, CUDA or HIP "
                                                              "device)" if device == "gpu" else "unknown"))
    backend = next(b for b in GPU_BACKENDS if b in found)
    prefs = bpy.context.preferences.addons["cycles"].preferences
    prefs.compute_device_type = backend
    prefs.refresh_devices()
    for d in prefs.devices:
        d.use = d.type == backend
    scene.cycles.device = "GPU"
    return f"{backend}: {', '.join(found[backend])}"


class BlenderRenderer:
    """One Blender scene built from a static description, updated and rendered per frame, on
    ``device`` (:func:`use_device`)."""

    def __init__(self, static: StaticScene, width: int, height: int, threads: int, exr_path: str,
                 device: str = "cpu"):
        self.handles = build_scene(static, width, height, threads, exr_path)
        self.device = use_device(self.handles.scene, device)

    def render(self, frame: FrameScene, exr_path: str, regions=(), computed=None) -> tuple[dict[str, float], list[tuple]]:
        """Render ``frame`` into the multilayer EXR ``exr_path``, then its marker ``regions``
        (label-aware sampling, :func:`~dockfactory.blender_scenes.crops.render_crops`) into one
        cropped EXR each, and with ``marker_coverage_samples`` each region's coverage: the array
        ``computed`` (a callable taking the crops' paths) gives for it, rendered into a coverage
        EXR where it gives None (or where there is no ``computed``). Returns (wall seconds of
        each phase, (colour path, coverage path or array or None) in region order)."""
        t0 = time.perf_counter()
        self.handles.scene.render.filepath = exr_path
        apply_frame(self.handles, frame)
        t1 = time.perf_counter()
        bpy.ops.render.render(write_still=True)
        t2 = time.perf_counter()
        colour = render_crops(self.handles.scene, frame, regions, exr_path) if regions else []
        t3 = time.perf_counter()
        timings = {"scene_update": t1 - t0, "cycles": t2 - t1, "marker_crops": t3 - t2}
        cover = [None] * len(colour)
        if colour and frame.render.marker_coverage_samples:
            cover = list(computed(colour)) if computed is not None else cover
            t4 = time.perf_counter()
            need = [i for i, c in enumerate(cover) if c is None]
            paths = render_coverage(self.handles.scene, frame, [regions[i] for i in need], exr_path) if need else []
            for i, path in zip(need, paths):
                cover[i] = path
            timings["marker_coverage_geometry"] = t4 - t3
            timings["marker_coverage"] = time.perf_counter() - t4
        return timings, list(zip(colour, cover))

    def state(self, frame: FrameScene) -> dict:
        """Apply ``frame`` without rendering; the Blender state a render would read (see
        :func:`~dockfactory.blender_scenes.frame_update.scene_state`)."""
        apply_frame(self.handles, frame)
        return scene_state(self.handles)
