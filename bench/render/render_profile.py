"""Where a Cycles frame's time goes (issue 13: make 2-spp-quality frames cheaper).

    python -m bench.render.render_profile [--frames 3] [--width 1280] [--height 960] [--threads 2]

Builds the factory's Blender scene once (default config, normal frames, seed 77) and renders the
same frames with one change at a time, printing the median over the frames of the process CPU
seconds and wall seconds of ``bpy.ops.render.render`` (scene sync, BVH, path tracing, denoise,
scratch EXR write). Compare rows of one run: the machine's speed varies by tens of percent
between runs. Variants: samples 1 / 2 / 4 with and without the denoiser; then, denoiser off at
2 spp, every material replaced by one plain material, only the key light, no bounces, the light
tree, half the resolution, and no depth / index passes.

Imports bpy (through dockfactory.blender_scenes): run it on its own, not beside torch.
"""
from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

from dockfactory.blender_scenes.render import BlenderRenderer
from dockfactory.blender_scenes.render_profile import plain_material, time_renders, variants
from dockfactory.core.config import config_from_dict
from dockfactory.generator.random_draws import static_scene
from dockfactory.generator.sampler import frame_plan, sample_frame


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
        simple = plain_material()
        print(f"render profile: {len(frames)} normal frames at {args.width}x{args.height}, {args.threads} threads")
        print(f"{'variant':32s} {'CPU s':>7s} {'wall s':>7s}")
        for name, samples, tweak in variants(h, simple):
            cpu, wall = time_renders(h, frames, samples, tweak)
            print(f"{name:32s} {cpu:7.2f} {wall:7.2f}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
