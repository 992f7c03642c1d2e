"""Render settings: cost against image quality at the markers.

    python -m bench.render.render_quality [--frames 6] [--variants 1spp,2spp,...] [--keep DIR]

Renders the same normal frames at 1280 x 960 with each variant and prints the Cycles cost
(wall seconds and CPU seconds per frame; CPU seconds are not inflated by other load) and the
per-frame total of the worker (Cycles + EXR read + sensor + labels + writes), and the
error of a fixed, simple sub-pixel marker estimator (colour-weighted centroid of the marker's
chroma above half its peak) against the exact outline centroid of each fully visible marker:
median, 90th percentile and mean (bias) in px. The estimator's own floor shows in the
many-sample reference; what matters is how far a variant is from it.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
from pathlib import Path

import dockfactory

dockfactory.pin_label_arithmetic(os.environ)   # before numpy loads: a render checks it (core.blas)

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from dockfactory.core.config import config_from_dict  # noqa: E402
from dockfactory.generator.render_job import JobOptions, run_render  # noqa: E402

VARIANTS = {
    "1spp": {"samples": 1},
    "2spp": {"samples": 2},
    "2spp-1bounce": {"samples": 2, "max_bounces": 1},
    "2spp-0bounce": {"samples": 2, "max_bounces": 0},
    "3spp-0bounce": {"samples": 3, "max_bounces": 0},
    "adaptive4": {"samples": 4, "adaptive_threshold": 0.1, "adaptive_min_samples": 1},
    "1spp-filter1": {"samples": 1, "filter_width_px": 1.0},
    "1spp-prefast": {"samples": 1, "denoise_prefilter": "fast"},
    "1spp-preacc": {"samples": 1, "denoise_prefilter": "accurate"},
    "1spp-balanced": {"samples": 1, "denoise": "balanced"},
    "16spp-high": {"samples": 16, "denoise": "high", "max_bounces": 4},
    "1spp-off": {"samples": 1, "denoise": "off"},
    "2spp-off": {"samples": 2, "denoise": "off"},
    "3spp-off": {"samples": 3, "denoise": "off"},
    "4spp-off": {"samples": 4, "denoise": "off"},
    "1spp-blue": {"samples": 1, "sampling_pattern": "blue_noise"},
    "2spp-blue": {"samples": 2, "sampling_pattern": "blue_noise"},
    "1spp-blue-off": {"samples": 1, "denoise": "off", "sampling_pattern": "blue_noise"},
    "2spp-blue-off": {"samples": 2, "denoise": "off", "sampling_pattern": "blue_noise"},
    "1spp-blue-med3": {"samples": 1, "denoise": "off", "sampling_pattern": "blue_noise", "post_filter": "median3"},
    "1spp-blue-med5": {"samples": 1, "denoise": "off", "sampling_pattern": "blue_noise", "post_filter": "median5"},
    "1spp-med3": {"samples": 1, "denoise": "off", "post_filter": "median3"},
    "2spp-blue-med3": {"samples": 2, "denoise": "off", "sampling_pattern": "blue_noise", "post_filter": "median3"},
    "1spp-blue-g05": {"samples": 1, "denoise": "off", "sampling_pattern": "blue_noise", "post_filter": "gauss05"},
    "1spp-blue-g07": {"samples": 1, "denoise": "off", "sampling_pattern": "blue_noise", "post_filter": "gauss07"},
    "1spp-blue-g10": {"samples": 1, "denoise": "off", "sampling_pattern": "blue_noise", "post_filter": "gauss10"},
    "2spp-blue-g05": {"samples": 2, "denoise": "off", "sampling_pattern": "blue_noise", "post_filter": "gauss05"},
    "adaptive8-off": {"samples": 8, "denoise": "off", "adaptive_threshold": 0.05, "adaptive_min_samples": 1},
}


def marker_centroid_errors(root: Path) -> np.ndarray:
    errs = []
    for lab_path in sorted((root / "labels").glob("*.json")):
        lab = json.loads(lab_path.read_text())
        img = cv2.imread(str(root / "images" / f"{lab['frame_id']}.png")).astype(float)
        for m in lab["markers"]:
            if m["visibility"] != 2 or m["visible_fraction"] < 0.99:
                continue
            u, v = m["center_px"]
            rad = int(np.sqrt(m["area_px"] / np.pi)) + 6
            x0, y0 = int(u) - rad, int(v) - rad
            patch = img[y0:y0 + 2 * rad + 1, x0:x0 + 2 * rad + 1]
            b, g, r = patch[..., 0], patch[..., 1], patch[..., 2]
            score = (r - np.maximum(g, b)) if m["section"] == "A" else (b - np.maximum(g, r))
            w = np.clip(score - 0.5 * score.max(), 0, None)
            ys, xs = np.mgrid[0:patch.shape[0], 0:patch.shape[1]]
            c = np.array([(w * xs).sum() / w.sum() + x0, (w * ys).sum() / w.sum() + y0])
            errs.append(c - np.array(m["outline_centroid_px"]))
    return np.array(errs)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=6)
    ap.add_argument("--variants", default=",".join(VARIANTS))
    ap.add_argument("--keep", type=Path, default=None, help="keep each variant's dataset under this folder")
    args = ap.parse_args()
    print(f"render quality: {args.frames} normal frames at 1280x960 per variant")
    print(f"{'variant':14s} {'wall s':>7s} {'cpu s':>7s} {'total s':>7s} {'n':>4s} {'median px':>10s} {'p90 px':>7s} {'bias x':>7s} {'bias y':>7s}")
    for name in args.variants.split(","):
        render = {**VARIANTS[name], "keep_exr": False}
        data = {"dataset": {"name": "quality", "seed": 77, "frames": args.frames},
                "conditions": {"normal": 1, "low_light": 0, "occlusion": 0, "glare": 0},
                "render": render, "export": {"formats": []}}
        cfg = config_from_dict(data, "<bench>")
        with tempfile.TemporaryDirectory(prefix="render-quality-") as tmp:
            root = args.keep / name if args.keep else Path(tmp) / "ds"
            summary = run_render(cfg, root, json.dumps(data), JobOptions(progress=False))
            if not summary.ok:
                print(summary.text())
                return 1
            rows = [json.loads(l) for l in (root / "logs" / "timings.jsonl").read_text().splitlines()][1:]
            e = marker_centroid_errors(root)
        d = np.hypot(e[:, 0], e[:, 1])
        wall = statistics.median(r["cycles"] for r in rows)
        cpu = statistics.median(r["cycles_cpu"] for r in rows)
        total = statistics.median(r["total"] for r in rows)
        print(f"{name:14s} {wall:7.2f} {cpu:7.2f} {total:7.2f} {len(d):4d} {np.median(d):10.3f} "
              f"{np.percentile(d, 90):7.3f} {e[:, 0].mean():+7.3f} {e[:, 1].mean():+7.3f}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
