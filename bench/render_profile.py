"""Where a Cycles frame's time goes (issue 13: make 2-spp-quality frames cheaper).

    python bench/render_profile.py [--frames 3] [--width 1280] [--height 960] [--threads 2]

Builds the factory's Blender scene once (default config, normal frames, seed 77) and renders the
same frames with one change at a time, printing the median over the frames of the process CPU
seconds and wall seconds of ``bpy.ops.render.render`` (scene sync, BVH, path tracing, denoise,
scratch EXR write). Compare rows of one run: the machine's speed varies by tens of percent
between runs. Variants: samples 1 / 2 / 4 with and without the denoiser; then, denoiser off at
2 spp, every material replaced by one plain material, only the key light, no bounces, the light
tree, half the resolution, and no depth / index passes.

Imports bpy: run it on its own, not beside torch.
"""
from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import bpy

from dockfactory.blender_scenes.frame_update import apply_frame
from dockfactory.blender_scenes.render import BlenderRenderer
from dockfactory.core.config import config_from_dict
from dockfactory.generator.draws import static_scene
from dockfactory.generator.sampler import frame_plan, sample_frame


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
        bpy.ops.render.render(write_still=True)
        cpu.append(time.process_time() - c0)
        wall.append(time.perf_counter() - t0)
        if undo:
            undo()
    return statistics.median(cpu), statistics.median(wall)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=3)
    ap.add_argument("--width", type=int, default=1280)
    ap.add_argument("--height", type=int, default=960)
    ap.add_argument("--threads", type=int, default=2)
    args = ap.parse_args()
    data = {"dataset": {"name": "profile", "seed": 77, "frames": 2 * args.frames},
            "conditions": {"normal": 1, "low_light": 0, "occlusion": 0, "glare": 0},
            "render": {"samples": 2, "keep_exr": False}, "export": {"formats": []}}
    cfg = config_from_dict(data, "<bench>")
    frames = [sample_frame(cfg, s) for s in frame_plan(cfg) if s.kind == "main"][:args.frames]
    with tempfile.TemporaryDirectory(prefix="render-profile-") as tmp:
        h = BlenderRenderer(static_scene(cfg), args.width, args.height, args.threads,
                            str(Path(tmp) / "scratch.exr")).handles
        simple = bpy.data.materials.new("plain")
        print(f"render profile: {len(frames)} normal frames at {args.width}x{args.height}, {args.threads} threads")
        print(f"{'variant':32s} {'CPU s':>7s} {'wall s':>7s}")
        for name, samples, tweak in variants(h, simple):
            cpu, wall = time_renders(h, frames, samples, tweak)
            print(f"{name:32s} {cpu:7.2f} {wall:7.2f}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
