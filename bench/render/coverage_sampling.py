"""The coverage render's settings side by side: how close each gets to the converged coverage, and at what cost.

    python -m bench.render.coverage_sampling CONFIG [--frames 3] [--truth 1024] \
        [--setting NAME:SAMPLES:THRESHOLD ...] [--geometry] [--out coverage.json]

Renders the first ``--frames`` frames of CONFIG (with label-aware sampling) once per setting in
one render worker each: ``[render] marker_coverage_samples`` = SAMPLES and
``marker_coverage_threshold`` = THRESHOLD (0: every pixel every sample), and once more at
``--truth`` samples without adaptive sampling (the converged coverage). Everything else is the
config's, so the crops and their own sampled coverage are the same in every setting; ``--geometry``
adds the coverage computed from the markers' geometry (generator.coverage_geometry). Per setting,
over the marker pixels the truth puts on an edge (coverage of the disc or ring strictly between
0.001 and 0.999, both classes):

    rms        = RMS of coverage - truth (what the correction leaves of the antialiasing noise);
    sampled    = the same of the crop's own sampled coverage (the noise the correction takes out);
    bias bins  = the mean of coverage - truth by the truth's coverage (a correction that must add
                 no bias needs none here beyond the truth's own);
    coverage_s = the median over frames of the coverage renders' wall seconds per frame.

Compare the seconds of one run only (they share the machine with whatever runs beside them).
Imports no bpy: the renders run in worker processes (generator.worker_pool).
"""
from __future__ import annotations

import argparse
import dataclasses
import glob
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from dockfactory.blender_scenes.crops import crop_path
from dockfactory.core.config import load_config
from dockfactory.core.io import write_json_atomic
from dockfactory.core.scene import to_dict
from dockfactory.generator.render_job import worker_init_request
from dockfactory.generator.coverage_geometry import frame_outlines, region_coverage
from dockfactory.generator.exr import read_class_coverage
from dockfactory.generator.marker_regions import marker_regions
from dockfactory.generator.random_draws import static_scene
from dockfactory.generator.sampler import frame_plan, sample_frame
from dockfactory.generator.worker_pool import WorkerProcess

EDGE = 1e-3
BIAS_BINS = ((EDGE, 0.05), (0.05, 0.3), (0.3, 0.7), (0.7, 0.95), (0.95, 1 - EDGE))
TIMEOUT_S = 1800.0


def parse_setting(text: str) -> tuple[str, int, float]:
    """NAME:SAMPLES:THRESHOLD; ValueError naming the text otherwise."""
    parts = text.split(":")
    if len(parts) != 3:
        raise ValueError(f"--setting {text!r}: expected NAME:SAMPLES:THRESHOLD")
    return parts[0], int(parts[1]), float(parts[2])


def _worker(cfg, root: Path) -> WorkerProcess:
    proc = WorkerProcess(worker_init_request(cfg, root, 2, keep_exr=False), root / "logs" / "worker.log")
    proc.start(TIMEOUT_S)
    return proc


def _scratch_coverage(pid: int, k: int, kind: str) -> list[np.ndarray]:
    """The (h, w, 2) coverage of every region of the worker's ``k``-th frame: of its coverage
    renders ("cov") or of the crops' own samples ("crop"), in region order (the worker's scratch
    folder, generator.render_worker: frame k renders into render{k % 2}.exr)."""
    dirs = [d for base in ("/dev/shm", tempfile.gettempdir()) for d in glob.glob(f"{base}/dockfactory-{pid}-*")]
    if len(dirs) != 1:
        raise RuntimeError(f"worker {pid}: expected one scratch folder, found {dirs}")
    exr, out = str(Path(dirs[0]) / f"render{k % 2}.exr"), []
    while Path(crop_path(exr, len(out), kind)).exists():
        out.append(read_class_coverage(crop_path(exr, len(out), kind)))
    return out


def render_setting(cfg, frames, samples: int, threshold: float, root: Path) -> dict:
    """Each frame rendered at the setting: {"cov": [[region coverage]], "crop": [...], "seconds": [...]}."""
    proc = _worker(cfg, root)
    got = {"cov": [], "crop": [], "seconds": []}
    try:
        for k, frame in enumerate(frames):
            render = dataclasses.replace(frame.render, marker_coverage_samples=samples,
                                         marker_coverage_threshold=threshold, marker_coverage_source="render")
            reply = proc.request({"op": "render", "frame": to_dict(dataclasses.replace(frame, render=render))},
                                 TIMEOUT_S)
            if not reply.get("ok"):
                raise RuntimeError(f"frame {frame.spec.frame_id}: {reply.get('error')}")
            got["seconds"].append(reply["timings_s"]["marker_coverage"])
            got["cov"].append(_scratch_coverage(proc.pid, k, "cov"))
            got["crop"].append(_scratch_coverage(proc.pid, k, "crop"))
    finally:
        proc.close()
    return got


def geometry_setting(cfg, frames, truth: dict) -> dict:
    """The coverage computed from the geometry (generator.coverage_geometry) for the regions the
    worker rendered (the same marker_regions), with the truth run's crops: the rows of
    :func:`render_setting`; seconds: the computation's per frame."""
    static = static_scene(cfg)
    got = {"cov": [], "crop": truth["crop"], "seconds": []}
    for frame in frames:
        t0 = time.perf_counter()
        outlines = frame_outlines(frame, static)
        got["cov"].append([region_coverage(outlines, r, frame.render.filter_width_px)
                           for r in marker_regions(frame, static)])
        got["seconds"].append(time.perf_counter() - t0)
    return got


def compare(got: dict, truth: dict) -> dict:
    """The figures of one setting against the truth (module docstring)."""
    diff, sampled, tval = [], [], []
    for covs, crops, truths in zip(got["cov"], got["crop"], truth["cov"]):
        for c, s, t in zip(covs, crops, truths):
            diff.append((c - t).ravel())
            sampled.append((s - t).ravel())
            tval.append(t.ravel())
    d, s, t = np.concatenate(diff), np.concatenate(sampled), np.concatenate(tval)
    edge = (t > EDGE) & (t < 1 - EDGE)
    bins = []
    for lo, hi in BIAS_BINS:
        m = (t > lo) & (t < hi)
        bins.append({"truth": [lo, hi], "n": int(m.sum()), "mean": float(d[m].mean()),
                     "se": float(d[m].std() / np.sqrt(max(m.sum(), 1)))})
    return {"edge_px": int(edge.sum()), "rms": float(np.sqrt(np.mean(d[edge] ** 2))),
            "sampled_rms": float(np.sqrt(np.mean(s[edge] ** 2))), "bias_bins": bins,
            "coverage_s": float(np.median(got["seconds"])), "seconds": got["seconds"]}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("config")
    ap.add_argument("--frames", type=int, default=3)
    ap.add_argument("--truth", type=int, default=1024)
    ap.add_argument("--setting", action="append", type=parse_setting, default=None)
    ap.add_argument("--geometry", action="store_true",
                    help="a row for the coverage computed from the geometry (no render)")
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    settings = args.setting or [("fixed128", 128, 0.0), ("default", 128, 0.005), ("adaptive256", 256, 0.005)]
    cfg = load_config(args.config)
    frames = [sample_frame(cfg, spec) for spec in frame_plan(cfg)[:args.frames]]
    with tempfile.TemporaryDirectory() as tmp:
        truth = render_setting(cfg, frames, args.truth, 0.0, Path(tmp) / "truth")
        rows = {name: {"samples": n, "threshold": thr,
                       **compare(render_setting(cfg, frames, n, thr, Path(tmp) / name), truth)}
                for name, n, thr in settings}
    if args.geometry:
        rows["geometry"] = {"samples": 0, "threshold": 0.0, **compare(geometry_setting(cfg, frames, truth), truth)}
    print(f"{'setting':12s} {'samples':>7s} {'thresh':>7s} {'edge px':>8s} {'rms':>8s} {'sampled':>8s} {'cov s':>6s}")
    for name, r in rows.items():
        print(f"{name:12s} {r['samples']:7d} {r['threshold']:7.3f} {r['edge_px']:8d} {r['rms']:8.5f} "
              f"{r['sampled_rms']:8.5f} {r['coverage_s']:6.2f}")
    if args.out:
        write_json_atomic(args.out, {"command": " ".join(sys.argv), "config": args.config, "frames": args.frames,
                                     "truth_samples": args.truth, "truth_s": float(np.median(truth["seconds"])),
                                     "settings": rows})
    return 0


if __name__ == "__main__":
    sys.exit(main())
