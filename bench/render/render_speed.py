"""Render speed at 1280 x 960 per condition, and the overhead beyond bare Cycles time.

    python -m bench.render.render_speed [--per-condition 4] [--samples 2] [--denoise fast] [--workers 1]

Renders ``per-condition`` frames of each condition through the real job system (worker process,
scene update, Cycles, EXR read, sensor model, labels, PNG/EXR/JSON writes, hashing) and prints
per condition: seconds per image (wall time of the job divided by frames, and the worker's
per-frame total), the Cycles part (bpy.ops.render.render, which includes writing the scratch
EXR) and the overhead fraction = (per-frame total - Cycles) / Cycles. The first frame of each
worker (scene build, kernel warm-up) is excluded from the per-frame figures. ``lens`` is the
resampling of a real camera's render canvas (0 for the pinhole cameras of this bench; the camera
model's own cost: bench/render/render_camera_model.py).
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import dockfactory

dockfactory.pin_label_arithmetic(os.environ)   # before numpy loads: a render checks it (core.blas)

from dockfactory.core.config import config_from_dict  # noqa: E402
from dockfactory.generator.render_job import JobOptions, run_render  # noqa: E402

CONDITIONS = ("normal", "low_light", "occlusion", "glare")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--per-condition", type=int, default=4)
    ap.add_argument("--samples", type=int, default=None, help="default: the config default")
    ap.add_argument("--denoise", default=None)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--keep-exr", action="store_true")
    ap.add_argument("--width", type=int, default=1280)
    ap.add_argument("--height", type=int, default=960)
    args = ap.parse_args()

    render = {"keep_exr": args.keep_exr}
    if args.samples is not None:
        render["samples"] = args.samples
    if args.denoise is not None:
        render["denoise"] = args.denoise
    n = args.per_condition * len(CONDITIONS)
    data = {"dataset": {"name": "bench", "seed": 99, "frames": n},
            "conditions": {c: 1.0 for c in CONDITIONS}, "render": render,
            "image": {"width": args.width, "height": args.height}}
    if args.width != 1280:
        s = args.width / 1280
        data["camera"] = {"focal_px": [1200 * s, 3000 * s], "margin_px": 48 * s}
    cfg = config_from_dict(data, "<bench>")
    with tempfile.TemporaryDirectory(prefix="render-speed-") as tmp:
        t0 = time.monotonic()
        summary = run_render(cfg, Path(tmp) / "ds", json.dumps(data), JobOptions(workers=args.workers, progress=False))
        wall = time.monotonic() - t0
        labels = {p.stem: json.loads(p.read_text())["spec"]["condition"] for p in (Path(tmp) / "ds" / "labels").glob("*.json")}
        timings = [json.loads(line) for line in (Path(tmp) / "ds" / "logs" / "timings.jsonl").read_text().splitlines()]
    if not summary.ok:
        print(summary.text())
        return 1
    by_cond: dict[str, list] = {}
    for i, t in enumerate(timings):
        if i < args.workers:     # each worker's first frame pays for scene build and warm-up
            continue
        by_cond.setdefault(labels[t["frame_id"]], []).append(t)
    print(f"render speed: {args.width}x{args.height}, samples={cfg.render.samples}, denoise={cfg.render.denoise}, "
          f"max_bounces={cfg.render.max_bounces}, keep_exr={cfg.render.keep_exr}, workers={args.workers}, "
          f"frames={n} (first frame per worker excluded)")
    print("The worker finishes frame k (sensor model, labels, writes) while Cycles renders frame k+1, so a")
    print("frame's post-processing is hidden when Cycles leaves CPU idle; s/image is the throughput.")
    print(f"{'condition':10s} {'n':>3s} {'cycles s':>9s} {'update':>7s} {'read':>6s} {'camera':>6s} {'labels':>10s} "
          f"{'write':>6s} {'post cpu':>9s} {'cycles cpu':>10s}")
    all_t = []
    for cond in CONDITIONS + ("ALL",):
        ts = all_t if cond == "ALL" else by_cond.get(cond, [])
        if cond != "ALL":
            all_t += ts
        if not ts:
            continue
        med = lambda k: statistics.median(t[k] for t in ts)  # noqa: E731
        print(f"{cond:10s} {len(ts):3d} {med('cycles'):9.2f} {med('scene_update'):7.3f} {med('read_exr'):6.3f} {med('camera'):6.3f} "
              f"{med('labels'):10.3f} {med('encode_write'):6.3f} {med('post_cpu'):9.3f} {med('cycles_cpu'):10.2f}")
    steady = [t for i, t in enumerate(timings) if i >= args.workers]
    ends = sorted(t["finished_at"] for t in steady)
    per_image = (ends[-1] - ends[0]) / (len(ends) - 1) if len(ends) > 1 else float("nan")
    cyc = statistics.median(t["cycles"] for t in steady)
    print(f"throughput (steady state, {len(ends)} frames): {per_image:.2f} s/image = {3600 / per_image:.0f} frames/hour; "
          f"median Cycles {cyc:.2f} s/frame; job-system overhead beyond Cycles: {100 * (per_image - cyc) / cyc:+.1f} %")
    print(f"job wall time {wall:.1f} s for {n} frames = {wall / n:.2f} s/image including worker start "
          f"({3600 * n / wall:.0f} frames/hour). Load average now: {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
