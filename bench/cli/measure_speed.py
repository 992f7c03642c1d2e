"""Speed of ``dockfactory measure`` end to end (issue 11 targets: >= 15 frames/s on 2 cores;
identification + solve <= 15 ms median per frame).

    python -m bench.cli.measure_speed IMAGES... --layout LAYOUT.json [--threads 2] [--camera-model M]
        [--self-calibrate frame|sequence] [--json OUT.json]

e.g. the test split of a dataset rendered from configs/detector.toml:
    python -m bench.cli.measure_speed out/detector/images --layout out/detector/layout.json
Prints frames/s (wall, after the model is loaded; images read, detected, solved, overlays and
files written) and the per-frame medians of detection and identification + solve.
"""
from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time

import dockfactory

dockfactory.set_app_environment(os.environ)   # as the dockfactory command runs, before numpy loads

TARGETS = {"frames_per_s": 15.0, "solve_ms": 15.0}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("images", nargs="+")
    p.add_argument("--layout", required=True)
    p.add_argument("--weights")
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--camera-model")
    p.add_argument("--self-calibrate", choices=("frame", "sequence"))
    p.add_argument("--backend", default="auto", choices=("auto", "torch", "onnx"))
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--overlay-size", type=float, default=0.5, help="0: no overlays")
    p.add_argument("--json")
    args = p.parse_args()
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
    import torch
    torch.set_num_threads(args.threads)
    import json

    from dockfactory.core.resources import shipped_weights
    from dockfactory.measure.images import MeasureOptions, measure
    opts = MeasureOptions(args.backend, args.workers, args.overlay_size or None)
    print(f"load average before: {os.getloadavg()[0]:.2f}; torch threads {args.threads}")
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        head = measure(args.images, args.layout, args.weights or shipped_weights(), tmp,
                       camera_model=args.camera_model, self_calibrate=args.self_calibrate, options=opts)
        total = time.perf_counter() - t0
        with open(os.path.join(tmp, "measurements.json")) as fh:
            recs = json.load(fh)["images"]
    det = [r["timing_ms"]["detect"] for r in recs if "timing_ms" in r]
    sol = [r["timing_ms"]["solve"] for r in recs if "timing_ms" in r]
    res = {"images": head["images_total"], "with_pose": head["images_with_pose"], "frames_per_s": head["frames_per_s"],
           "wall_s_including_model_load": round(total, 2), "detect_ms_median": statistics.median(det),
           "solve_ms_median": statistics.median(sol), "solve_ms_p90": sorted(sol)[int(0.9 * (len(sol) - 1))],
           "camera_model": head["camera_model"], "self_calibrate": head["self_calibrate"],
           "backend": head["backend"], "workers": head["workers"], "overlay_size": head["overlay_size"]}
    ok = lambda c: "met" if c else "NOT met"  # noqa: E731
    print(f"{res['images']} images, {res['with_pose']} with a pose ({res['camera_model']} camera); backend "
          f"{res['backend']}, {res['workers']} workers, overlays {res['overlay_size'] or 'off'}")
    print(f"end to end: {res['frames_per_s']:.2f} frames/s [target >= {TARGETS['frames_per_s']:.0f}: "
          f"{ok(res['frames_per_s'] >= TARGETS['frames_per_s'])}]")
    print(f"detection: median {res['detect_ms_median']:.1f} ms; identification + solve: median "
          f"{res['solve_ms_median']:.1f} ms, p90 {res['solve_ms_p90']:.1f} ms [target <= {TARGETS['solve_ms']:.0f}: "
          f"{ok(res['solve_ms_median'] <= TARGETS['solve_ms'])}]")
    print(f"load average after: {os.getloadavg()[0]:.2f}")
    if args.json:
        from dockfactory.core.io import write_json_atomic
        write_json_atomic(args.json, res)


if __name__ == "__main__":
    main()
