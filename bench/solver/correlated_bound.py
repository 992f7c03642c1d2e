"""What the measured structure of the centre errors does to the pose's expected RMSE.

The Cramer-Rao bound that ``dockfactory evaluate`` prints treats the centres of a frame as
independent, each with the disc noise model's covariance C_i = s^2 T_i (solver.disc_noise). The
centre errors of real detections are not quite that: each marker of the layout has its own
variance relative to the model, and the errors of one frame are correlated. This study measures
both on the frames of one split (default train: they evaluate nothing) and predicts, on the frames
of another (default test), the covariance of the solver's weighted fit (weights C_i^-1) under the
measured structure: the sandwich A^-1 J^T W Sigma W J A^-1 (A = J^T W J, J the Jacobian at the
true poses, Sigma_ij = T_i^1/2 M_ij T_j^1/2 with M the measured second moments of the whitened
errors T_i^-1/2 e_i over (marker id, axis), normalised to a mean variance of 1 so that the scale
stays the model's). It prints, per pose component, the measured RMSE, the independent bound (the
evaluate run's ``crb_*``) and the prediction with the measured structure, both as ratios.

Inputs: the acceptance run's folder (``detections.json``, ``poses.json``, ``eval/frames.csv``, as
``bench/paper/paper.sh accept_s`` writes them). Centres: refined detections at score >= 0.25 matched
within 3 px to a marker at least 99 % visible; frames of one condition (default normal).

Run: python -m bench.solver.correlated_bound DATASET[+DATASET] RUN_DIR[+RUN_DIR] [--measure-split train] [--eval-split test]
     [--condition normal]
"""
from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path

import numpy as np
from bench.marker_match import nearest_marker

from dockfactory.core.names import COMPONENTS
from dockfactory.eval.centre_noise_disc import label_noise_shapes
from dockfactory.eval.centre_structure import sqrt_spd, structured_frame_bound
from dockfactory.eval.evaluate import frame_bound

IDS = [f"{s}{i}" for s in "AB" for i in range(7)]
SLOT = {k: i for i, k in enumerate(IDS)}
MATCH_PX = 3.0


def whitened_errors(label: dict, dets: list[dict]) -> dict:
    """{marker id: T^-1/2 (centre - outline centroid)} of the matched refined detections."""
    markers = [m for m in label["markers"] if m["in_frame"] and m.get("visible_fraction", 0) >= 0.99]
    out = {}
    for det in dets:
        if not det.get("refined") or det["score"] < 0.25:
            continue
        best = nearest_marker(det, markers, MATCH_PX)
        shape = None if best is None else label_noise_shapes(label, [best[1]])
        if shape is not None and best[1]["id"] in SLOT:
            out[best[1]["id"]] = np.linalg.solve(sqrt_spd(shape[0]), best[0])
    return out


def measured_moments(roots: list[Path], frames: list[dict], split: str, condition: str) -> tuple[np.ndarray, int]:
    """(28, 28) second moments of the whitened errors over (marker id, axis), pairwise over the
    frames where both are present, pooled over the datasets ``roots`` (each with its detections'
    ``frames``), normalised to a mean diagonal of 1; the frame count."""
    total, count, n = np.zeros((28, 28)), np.zeros((28, 28)), 0
    for root, by_frame in zip(roots, frames):
        for fid, dets in sorted(by_frame.items()):
            label = json.loads((root / "labels" / f"{fid}.json").read_text())
            if label["spec"]["split"] != split or label["spec"]["condition"] != condition:
                continue
            v = np.full(28, np.nan)
            for k, w in whitened_errors(label, dets).items():
                v[2 * SLOT[k]:2 * SLOT[k] + 2] = w
            ok = ~np.isnan(v)
            total += np.outer(np.where(ok, v, 0), np.where(ok, v, 0))
            count += np.outer(ok, ok)
            n += 1
    m = total / np.maximum(count, 1)
    return m / np.diag(m).mean(), n


def frame_stds(label: dict, ids: list[str], moments: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(independent bound, the weighted fit's std under the measured structure, the bound under
    it) of the 6 pose components, in the model's relative units (unit scale): evaluate's own
    bound (eval.evaluate.frame_bound) and eval.centre_structure.structured_frame_bound."""
    ind = frame_bound(label, ids, 1.0, disc_scale_px=1.0)
    got = structured_frame_bound(label, ids, {"folds": [{"ids": IDS, "moments": moments}]}, 1.0)
    return tuple(np.array([d[c] for c in COMPONENTS]) for d in (ind, got["fit"], got["bound"]))


def frame_rows(roots: list[Path], runs: list[Path], moments: np.ndarray, split: str, condition: str) -> np.ndarray:
    """(frames, 6, 5): per solved frame of ``split`` and ``condition`` of every run and pose
    component, its error, the run's bound, and the independent, structured-fit and structured
    bound stds at unit scale (:func:`frame_stds`)."""
    stats = []
    for root, run in zip(roots, runs):
        poses = json.loads((run / "poses.json").read_text())["frames"]
        for r in csv.DictReader((run / "eval" / "frames.csv").open()):
            if r["split"] != split or r["condition"] != condition or r["ok"] != "True":
                continue
            label = json.loads((root / "labels" / f"{r['frame_id']}.json").read_text())
            ind, fit, bound = frame_stds(label, poses[r["frame_id"]]["marker_ids"], moments)
            stats.append([[float(r[f"err_{c}"]), float(r[f"crb_{c}"]), ind[k], fit[k], bound[k]]
                          for k, c in enumerate(COMPONENTS)])
    return np.asarray(stats)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("dataset", help="dataset folder, or several joined by + (pooled)")
    ap.add_argument("run", help="acceptance run folder (detections.json, poses.json, eval/frames.csv); "
                                "several joined by +, one per dataset")
    ap.add_argument("--measure-split", default="train")
    ap.add_argument("--eval-split", default="test")
    ap.add_argument("--condition", default="normal")
    args = ap.parse_args()
    roots, runs = [Path(p) for p in args.dataset.split("+")], [Path(p) for p in args.run.split("+")]
    if len(roots) != len(runs):
        raise SystemExit(f"{len(roots)} datasets and {len(runs)} runs: give one run per dataset")
    dets = [json.loads((run / "detections.json").read_text())["frames"] for run in runs]
    moments, n = measured_moments(roots, dets, args.measure_split, args.condition)
    s = frame_rows(roots, runs, moments, args.eval_split, args.condition)
    if not n or not len(s):
        raise SystemExit(f"{args.run}: no {args.condition} frames of split {args.measure_split!r} or {args.eval_split!r}")
    rms = np.sqrt((s ** 2).mean(axis=0))  # (6, 5); columns 2-4 at unit scale: rescale to the run's
    print(f"structure measured on {n} {args.measure_split} {args.condition} frames; "
          f"{len(s)} {args.eval_split} {args.condition} frames")
    print("bound: the run's (independent centres); fit: the solver's weighted fit under the measured structure;")
    print("bound*: the Cramer-Rao bound under the measured structure. Ratios: RMSE / each.")
    print(f"{'':6s} {'RMSE':>8s} {'bound':>8s} {'ratio':>6s} {'fit':>8s} {'ratio':>6s} {'bound*':>8s} {'ratio':>6s}")
    for k, c in enumerate(COMPONENTS):
        fit, bound = (rms[k, 1] * rms[k, j] / rms[k, 2] for j in (3, 4))
        print(f"{c:6s} {rms[k, 0]:8.4f} {rms[k, 1]:8.4f} {rms[k, 0] / rms[k, 1]:6.3f} {fit:8.4f} "
              f"{rms[k, 0] / fit:6.3f} {bound:8.4f} {rms[k, 0] / bound:6.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
