"""Cost of the camera model (issue 11) on top of Cycles, per frame, at the config's size.

    python -m bench.render.render_camera_model [--config realistic] [--frames 12] [--repeat 3]

What a real camera adds to a frame, measured without Cycles on the config's own frames (the
render canvas painted as tests/pipeline_data.py paints it; painting is not timed):
- post-processing in the render worker: the distortion maps (exact inverse; cached per unit
  within a docking run, so "cold" is a frame without runs), the resampling of colour (per
  channel), depth and index passes with the exact marker edges, the JPEG round trip, and the
  labels through the lens, against the same frame's pinhole post-processing;
- Cycles: the overscan canvas renders more pixels than the image (Cycles' time grows with the
  pixel count): the canvas / image pixel ratio per frame, and that share of a Cycles frame
  (``--cycles-s``, default 2.0 s: README, 1280 x 960 at 1 sample on the 2-core machine).
Wall time and CPU time (all threads of this process: numpy's BLAS may use both cores) are the
median over frames of the best of ``--repeat`` runs.
"""
from __future__ import annotations

import argparse
import dataclasses
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from tests.pipeline_data import painted_passes

from dockfactory.core.camera_chain import capture, lens
from dockfactory.core.config import load_config
from dockfactory.core.resources import shipped_config
from dockfactory.core.scene import NO_DISTORTION
from dockfactory.generator.random_draws import static_scene
from dockfactory.generator.labels import frame_labels, marker_pinhole_outlines
from dockfactory.generator.sampler import frame_plan, sample_frame


def post(frame, static, passes, cold: bool):
    """The worker's post-processing of one frame (frame_output.finish_frame without the writes)."""
    if cold:
        lens._maps.cache_clear()
        lens._channel_tables.cache_clear()
    outlines = () if frame.camera.is_pinhole() else marker_pinhole_outlines(frame, static)
    shot = capture(passes, frame.camera, frame.sensor, outlines)
    return frame_labels(frame, static, shot.passes.index, 0.5, shot.derived, shot.image)


def timed(fn, repeat: int) -> tuple[float, float]:
    best = (np.inf, np.inf)
    for _ in range(repeat):
        w0, c0 = time.perf_counter(), time.process_time()
        fn()
        best = min(best, (time.perf_counter() - w0, time.process_time() - c0))
    return best


def pinhole_of(frame):
    cam = dataclasses.replace(frame.camera, distortion=NO_DISTORTION, aberration_px=(0.0, 0.0), jpeg_quality=0)
    return dataclasses.replace(frame, camera=cam)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--config", default="realistic")
    ap.add_argument("--frames", type=int, default=12)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--cycles-s", type=float, default=2.0)
    args = ap.parse_args()
    path = Path(args.config) if Path(args.config).exists() else shipped_config(args.config)
    cfg = load_config(path)
    static = static_scene(cfg)
    plan = frame_plan(cfg)
    rows = []
    for spec in plan[:: max(1, len(plan) // args.frames)][: args.frames]:
        frame = sample_frame(cfg, spec)
        pin = pinhole_of(frame)
        canvas, image = painted_passes(frame, static), painted_passes(pin, static)
        base = timed(lambda: post(pin, static, image, False), args.repeat)
        cold = timed(lambda: post(frame, static, canvas, True), args.repeat)
        warm = timed(lambda: post(frame, static, canvas, False), args.repeat)
        _, _, wc, hc = frame.camera.canvas()
        rows.append((base, cold, warm, wc * hc / (cfg.image.width * cfg.image.height)))
    med = lambda k, i: statistics.median(r[k][i] for r in rows)  # noqa: E731
    ratio = statistics.median(r[3] for r in rows)
    print(f"camera model cost: {args.config} at {cfg.image.width}x{cfg.image.height}, {len(rows)} frames, "
          f"best of {args.repeat}; load average {os.getloadavg()[0]:.2f}")
    print(f"{'post-processing':38s} {'wall s':>8s} {'cpu s':>8s}")
    print(f"{'pinhole (sensor, labels)':38s} {med(0, 0):8.3f} {med(0, 1):8.3f}")
    print(f"{'real camera, maps computed (no runs)':38s} {med(1, 0):8.3f} {med(1, 1):8.3f}")
    print(f"{'real camera, maps cached (docking run)':38s} {med(2, 0):8.3f} {med(2, 1):8.3f}")
    print(f"camera model on top of the pinhole: {med(1, 0) - med(0, 0):.3f} s wall "
          f"({med(1, 1) - med(0, 1):.3f} s CPU) per frame with the maps computed, "
          f"{med(2, 0) - med(0, 0):.3f} s wall with them cached")
    print(f"overscan: the canvas has {ratio:.3f} x the image's pixels (median; max "
          f"{max(r[3] for r in rows):.3f}): about {(ratio - 1) * args.cycles_s:+.3f} s of a {args.cycles_s:g} s "
          f"Cycles frame")
    return 0


if __name__ == "__main__":
    sys.exit(main())
