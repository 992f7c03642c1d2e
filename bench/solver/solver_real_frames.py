"""The solver on real detections of rendered frames, before / after a change of the solver.

Reads frames straight from a dataset folder (it may still be rendering: every frame with a label
and an image counts), detects the markers with shipped weights once (cached in ``--detections``),
then solves every frame as ``dockfactory solve`` does (pinhole, principal point at the image
centre, the weights' noise card as sigma floor) with the installed solver and, with
``--solver-src DIR`` (a folder holding ``solver/``, e.g. ``git archive <commit> solver | tar -x
-C DIR``), with that one too. Prints, per solver and per condition, the RMS errors of X, Y (mm)
and alpha (deg) against the labels, the RMS of the z-scores (error / reported std) and the
failures, then every frame whose X moved by more than 0.05 mm between the two.

Run: python -m bench.solver.solver_real_frames DATASET [--splits test,val] [--weights W]
     [--detections CACHE.json] [--solver-src DIR] [--threads 2]
"""
from __future__ import annotations

import os

import dockfactory

dockfactory.pin_label_arithmetic(os.environ)   # before numpy loads: labels as the command computes them

import argparse
import json
import sys
from pathlib import Path

import numpy as np


AXES = (("x_mm", "X mm"), ("y_mm", "Y mm"), ("alpha_deg", "alpha deg"))


def frame_ids(root: Path, splits: set[str]) -> list[str]:
    """Frames with a label and an image, of the given splits, in id order."""
    out = []
    for path in sorted((root / "labels").glob("*.json")):
        if (root / "images" / f"{path.stem}.png").is_file():
            if json.loads(path.read_text())["spec"]["split"] in splits:
                out.append(path.stem)
    return out


def detect_frames(root: Path, ids, weights: str, cache: Path, threads: int) -> dict:
    """{frame id: detections} (the detector's dicts), cached per frame in ``cache``."""
    done = json.loads(cache.read_text()) if cache.is_file() else {}
    todo = [f for f in ids if f not in done]
    if todo:
        import cv2
        import torch

        from dockfactory.core.io import write_json_atomic
        from dockfactory.detector.infer import MarkerDetector
        torch.set_num_threads(threads)
        det = MarkerDetector(weights)
        done["_noise_px"] = det.centre_noise_px
        for k, fid in enumerate(todo):
            img = cv2.cvtColor(cv2.imread(str(root / "images" / f"{fid}.png")), cv2.COLOR_BGR2RGB)
            done[fid] = det.detect(img)
            if k % 50 == 49:
                write_json_atomic(cache, done)
        write_json_atomic(cache, done)
    return done


def solve_all(root: Path, ids, dets: dict) -> dict:
    """{frame id: (condition, errors (3,), stds (3,)) or (condition, None, reason)} with the
    currently imported ``dockfactory.solver``."""
    from dockfactory.core.config import load_config
    from dockfactory.core.names import MIN_SCORE
    from dockfactory.eval.solve_frames import detection_arrays, docking_options, lens_prior_for
    from dockfactory.solver import SolverError, solve_docking
    config = load_config(root / "config.toml")
    markers = config.markers_layout()
    options = docking_options(dets.get("_noise_px"), lens_prior_for(config))
    out = {}
    for fid in ids:
        label = json.loads((root / "labels" / f"{fid}.json").read_text())
        cond, w, h = label["spec"]["condition"], label["image"]["width"], label["image"]["height"]
        cls, uv, boxes, refined = detection_arrays(dets[fid], MIN_SCORE)
        try:
            res = solve_docking(markers, ((w - 1) / 2, (h - 1) / 2), detections=(cls, uv), boxes=boxes,
                                refined=refined, options=options)
        except SolverError as exc:
            out[fid] = (cond, None, type(exc).__name__)
            continue
        truth = label["pose_b_in_d"]
        err = np.array([getattr(res, k) - truth[k] for k, _ in AXES])
        out[fid] = (cond, err, np.array([res.std[k] for k, _ in AXES]))
    return out


def summary_lines(name: str, solved: dict) -> list[str]:
    lines = [f"{name}:"]
    conds = sorted({c for c, _, _ in solved.values()})
    for cond in ["all"] + conds:
        rows = [(e, s) for c, e, s in solved.values() if e is not None and cond in ("all", c)]
        failed = sum(1 for c, e, _ in solved.values() if e is None and cond in ("all", c))
        if not rows:
            continue
        err = np.array([e for e, _ in rows])
        z = err / np.array([s for _, s in rows])
        rms, zrms = np.sqrt((err ** 2).mean(axis=0)), np.sqrt((z ** 2).mean(axis=0))
        cells = "  ".join(f"{label} {r:7.3f} (z {q:4.2f})" for (_, label), r, q in zip(AXES, rms, zrms))
        lines.append(f"  {cond:<10} n {len(rows):4d} failed {failed}  RMS {cells}  max |X| {np.abs(err[:, 0]).max():.2f}")
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dataset", type=Path)
    ap.add_argument("--splits", default="test,val")
    ap.add_argument("--weights", default="models/yolov5s_se_markers.pt")
    ap.add_argument("--detections", type=Path, default=Path("out/solver_real_frames_dets.json"))
    ap.add_argument("--solver-src", type=Path)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--worst", type=int, default=5, help="list the frames of largest |X error| (installed solver)")
    args = ap.parse_args(argv)
    ids = frame_ids(args.dataset, set(args.splits.split(",")))
    dets = detect_frames(args.dataset, ids, args.weights, args.detections, args.threads)
    print(f"{len(ids)} frames of splits {args.splits} in {args.dataset}; detections {args.detections}")
    new = solve_all(args.dataset, ids, dets)
    results = {"installed solver": new}
    if args.solver_src is not None:
        from bench.solver.solve_speed import use_solver_source
        for name in [m for m in sys.modules if m.startswith("dockfactory.solver") or m.startswith("dockfactory.eval")]:
            del sys.modules[name]
        use_solver_source(args.solver_src.resolve())
        results[f"solver of {args.solver_src}"] = solve_all(args.dataset, ids, dets)
    for name, solved in results.items():
        print("\n".join(summary_lines(name, solved)))
    worst = sorted((f for f in ids if new[f][1] is not None), key=lambda f: -abs(new[f][1][0]))[:args.worst]
    print("largest |X error| (installed solver):")
    for fid in worst:
        c, e, sd = new[fid]
        print(f"  {fid} {c:<10} X {e[0]:+.2f} mm (std {sd[0]:.2f}), Y {e[1]:+.2f} mm (std {sd[1]:.2f}), "
              f"alpha {e[2]:+.3f} deg (std {sd[2]:.3f})")
    if len(results) == 2:
        old = results[f"solver of {args.solver_src}"]
        for fid in ids:
            (c, e1, s1), (_, e0, s0) = new[fid], old[fid]
            if e1 is None or e0 is None or abs(e1[0] - e0[0]) > 0.05:
                print(f"  {fid} {c:<10} X error {_fmt(e0, s0)} -> {_fmt(e1, s1)}")
    return 0


def _fmt(err, std) -> str:
    return std if err is None else f"{err[0]:+.2f} mm (std {std[0]:.2f})"


if __name__ == "__main__":
    raise SystemExit(main())
