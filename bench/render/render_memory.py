"""Resident memory of a render worker over a long run (Blender is known to leak in long runs).

    python -m bench.render.render_memory [--frames 300] [--recycle-after 100] [--width 1280]

Renders ``frames`` frames with one worker recycled every ``recycle-after`` frames (use a large
value to see the growth of a single process) and prints the worker's RSS after the first frame,
then every 50 frames, its maximum, and the growth per 100 frames (least-squares slope).
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import dockfactory

dockfactory.pin_label_arithmetic(os.environ)   # before numpy loads: a render checks it (core.blas)

import numpy as np  # noqa: E402

from dockfactory.core.config import config_from_dict  # noqa: E402
from dockfactory.generator.render_job import JobOptions, run_render  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--recycle-after", type=int, default=100)
    ap.add_argument("--width", type=int, default=1280)
    ap.add_argument("--samples", type=int, default=None)
    args = ap.parse_args()
    s = args.width / 1280
    data = {"dataset": {"name": "memory", "seed": 5, "frames": args.frames},
            "image": {"width": args.width, "height": int(960 * s)},
            "camera": {"focal_px": [1200 * s, 3000 * s], "margin_px": 48 * s},
            "render": {"keep_exr": False, **({"samples": args.samples} if args.samples else {})},
            "export": {"formats": []}}
    cfg = config_from_dict(data, "<bench>")
    with tempfile.TemporaryDirectory(prefix="render-memory-") as tmp:
        t0 = time.monotonic()
        summary = run_render(cfg, Path(tmp) / "ds", json.dumps(data),
                             JobOptions(recycle_after=args.recycle_after, progress=True))
        wall = time.monotonic() - t0
        rows = [json.loads(l) for l in (Path(tmp) / "ds" / "logs" / "timings.jsonl").read_text().splitlines()]
    rss = np.array([r["rss_mb"] for r in rows])
    print(f"render memory: {args.frames} frames at {args.width}x{int(960 * s)}, worker recycled every "
          f"{args.recycle_after} frames, wall {wall:.0f} s, failed {len(summary.failed)}")
    for i in [0] + list(range(49, len(rss), 50)):
        print(f"  after frame {i + 1:4d}: RSS {rss[i]:7.1f} MB")
    print(f"  max RSS {rss.max():.1f} MB, min {rss.min():.1f} MB")
    for start in range(0, len(rss), args.recycle_after):
        seg = rss[start:start + args.recycle_after]
        if len(seg) > 10:
            slope = np.polyfit(np.arange(len(seg)), seg, 1)[0]
            print(f"  frames {start + 1}-{start + len(seg)}: growth {100 * slope:+.1f} MB per 100 frames "
                  f"(from {seg[0]:.1f} to {seg[-1]:.1f} MB)")
    return 0 if summary.ok else 1


if __name__ == "__main__":
    sys.exit(main())
