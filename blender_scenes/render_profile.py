"""Render-cost variants for bench/render/render_profile.py: the same scene rendered with one
Cycles or scene setting changed at a time, timed in this process (bpy stays in this package)."""
from __future__ import annotations

import statistics
import time

import bpy

from dockfactory.blender_scenes.frame_update import apply_frame


def plain_material():
    """One plain material, for a view layer's material override."""
    return bpy.data.materials.new("plain")


def variants(h, simple):
    """(name, samples, tweak) rows; a tweak changes the scene and returns its undo (or None)."""
    scene, vl = h.scene, h.scene.view_layers[0]

    def off():
        scene.cycles.use_denoising = False

    def setter(obj, attr, value):
        def tweak():
            off()
            old = getattr(obj, attr)
            setattr(obj, attr, value)
            return lambda: setattr(obj, attr, old)
        return tweak

    def one_light():
        off()
        hidden = list(h.lights.values())[1:]
        for o in hidden:
            o.hide_render = True
        return lambda: [setattr(o, "hide_render", False) for o in hidden]

    def no_passes():
        off()
        vl.use_pass_z = vl.use_pass_object_index = False
        return lambda: (setattr(vl, "use_pass_z", True), setattr(vl, "use_pass_object_index", True))

    return [("2 spp + denoiser", 2, None), ("1 spp + denoiser", 1, None), ("2 spp", 2, off), ("1 spp", 1, off),
            ("4 spp", 4, off), ("2 spp, one plain material", 2, setter(vl, "material_override", simple)),
            ("2 spp, key light only", 2, one_light), ("2 spp, no bounces", 2, setter(scene.cycles, "max_bounces", 0)),
            ("2 spp, light tree", 2, setter(scene.cycles, "use_light_tree", True)),
            ("2 spp, half resolution", 2, setter(scene.render, "resolution_percentage", 50)),
            ("2 spp, no depth/index passes", 2, no_passes)]


def time_renders(h, frames, samples, tweak) -> tuple[float, float]:
    """Median (CPU s, wall s) of rendering ``frames`` with ``tweak`` applied after each frame's update."""
    cpu, wall = [], []
    for f in frames:
        apply_frame(h, f)
        h.scene.cycles.samples = samples
        undo = tweak() if tweak else None
        c0, t0 = time.process_time(), time.perf_counter()
        render_once()
        cpu.append(time.process_time() - c0)
        wall.append(time.perf_counter() - t0)
        if undo:
            undo()
    return statistics.median(cpu), statistics.median(wall)


def render_once() -> None:
    bpy.ops.render.render(write_still=True)
