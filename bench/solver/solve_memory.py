"""Peak memory and time of ``solve_docking`` (identification included) against the markers in the
layout and the detections of one frame, each case in a fresh process.

    python -m bench.solver.solve_memory [--cases NAME,NAME]

Cases: ``layout-N`` a synthetic layout of N markers per section on the radius-300 mm cylinders
(random positions at least 32 mm apart, 12 mm discs), every marker detected once (+ N(0, 0.2) px);
``default-xK`` the factory's default layout (7 + 7) with each detection repeated K times;
``run-F`` a docking run of F frames of the default layout (0.1 px) through ``solve_sequence``
(camera model auto; its covariance's bias field included). Layouts
beyond ``core.layout_file.MAX_MARKERS_PER_SECTION`` and frames beyond
``solver.identify.max_detections`` are refused: their row shows the refusal and what it cost.
Prints one row per case: markers, detections, result, wall time, peak RSS (ru_maxrss of the
child). Single-threaded BLAS.
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys

CASES = ("layout-1", "layout-7", "layout-16", "layout-32", "layout-100", "layout-1000",
         "default-x1", "default-x3", "default-x20", "run-10", "run-40", "run-100", "run-300")

CHILD = r"""
import os, resource, sys, time
import numpy as np
from dockfactory.core.layout import build_layout
from dockfactory.solver import SolverError, solve_docking
from dockfactory.solver.synthetic import default_layout, docking_scene
kind, n = sys.argv[1].split("-")
rng = np.random.default_rng(1)
if kind == "run":   # one docking run of n frames solved at once (shared intrinsics, its bias field)
    from dockfactory.solver import solve_sequence
    from dockfactory.solver.synthetic import docking_run
    run = docking_run(rng, int(n))
    layout = default_layout()
    ids = [m.id for m in layout]
    frames = [(ids, np.vstack([f.uv_a, f.uv_b]) + rng.normal(0, 0.1, (len(ids), 2))) for f in run.frames]
    t = time.perf_counter()
    res = solve_sequence(layout, run.frames[0].image_centre, frames, camera_model="auto")
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"{sys.argv[1]:>12} {len(layout):>8} {len(ids) * int(n):>10} {time.perf_counter() - t:>8.2f} {rss:>9.0f}  "
          f"solved ({res.camera_model}, bias {res.bias_px:.3f} px)")
    sys.exit(0)
from dockfactory.core.layout_file import MAX_MARKERS_PER_SECTION
def pattern(count):
    if count > MAX_MARKERS_PER_SECTION:   # refused before any geometry: a dense grid will do
        return [(20 + 10 * (i // 25), -60 + 5 * (i % 25)) for i in range(count)]
    pts = []
    while len(pts) < count:
        s, phi = rng.uniform(20, 200), rng.uniform(-60, 60)
        if all(np.hypot(s - a, (phi - b) * 5.2) > 32 for a, b in pts):
            pts.append((s, phi))
    return pts
if kind == "layout":
    markers, copies = build_layout(pattern(int(n)), pattern(int(n)), 300.0, 12.0), 1
else:
    markers, copies = default_layout(), int(n[1:])
fits = 2 < len(markers) <= 2 * MAX_MARKERS_PER_SECTION
sc = docking_scene(np.random.default_rng(2), markers=markers) if fits else None
uv = np.vstack([sc.uv_a, sc.uv_b]) if sc is not None else \
    np.random.default_rng(4).uniform([0, 0], [1280, 960], (len(markers), 2))
cls = np.r_[np.zeros(len(uv) // 2, int), np.ones(len(uv) - len(uv) // 2, int)] if sc is None else \
    np.r_[np.zeros(len(sc.uv_a), int), np.ones(len(sc.uv_b), int)]
uv = np.repeat(uv, copies, axis=0) + np.random.default_rng(3).normal(0, 0.2, (len(uv) * copies, 2))
cls = np.repeat(cls, copies)
pp = sc.principal_point if sc is not None else np.array([639.5, 479.5])
t = time.perf_counter()
try:
    solve_docking(markers, pp, detections=(cls, uv), sigma_px=0.2)
    out = "solved"
except SolverError as exc:
    out = "refused: " + str(exc)[:90]
rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
print(f"{sys.argv[1]:>12} {len(markers):>8} {len(uv):>10} {time.perf_counter() - t:>8.2f} {rss:>9.0f}  {out}")
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default=",".join(CASES))
    args = ap.parse_args()
    env = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    print(f"{'case':>12} {'markers':>8} {'detections':>10} {'time s':>8} {'peak MB':>9}  result")
    for case in args.cases.split(","):
        proc = subprocess.run([sys.executable, "-c", CHILD, case], capture_output=True, text=True, env=env)
        print(proc.stdout.strip() or f"{case:>12} failed: {proc.stderr.strip().splitlines()[-1:]}", flush=True)


if __name__ == "__main__":
    main()
