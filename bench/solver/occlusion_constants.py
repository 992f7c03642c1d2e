"""The two measured constants of the solver's occlusion rule, on any split of a labelled dataset.

``solver.suspects.occlusion_variances`` adds (0.5 x max(0, cut - 1 px))^2 of centre variance per
axis to a detection whose box is ``cut`` px shorter than its disc's outline. Both figures were
measured on the test + val frames of the paper dataset; this script measures them on any split
(for example the train frames, which evaluate nothing) from a detections file and the labels:

- the box noise of fully visible markers (visible fraction >= 0.99): robust std and 99.9th
  percentile of the cut in u and v (the rule's 1 px margin);
- the error along a cut of partly hidden markers (visible fraction < 0.95, cut > 1 px): median
  and 10-90 % of |centre error along the axis| / cut (the rule's 0.5).

The cut here is the label's outline box less the detection's box (the solver uses the outline
its pose predicts). Only refined detections at score >= 0.25 count, each matched to the nearest
marker of its class within 8 px.

Run: python -m bench.solver.occlusion_constants DATASET DETECTIONS.json [--splits train]
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from bench.marker_match import nearest_marker

MATCH_PX = 8.0
MIN_SCORE = 0.25


def frame_cuts(label: dict, dets: list[dict]):
    """Yield (visible fraction, cut (2,), centre error (2,)) of each matched refined detection."""
    markers = [m for m in label["markers"] if m["in_frame"] and m.get("visible_pixels", 0) > 0]
    for det in dets:
        if not det.get("refined") or det["score"] < MIN_SCORE:
            continue
        hit = nearest_marker(det, markers, MATCH_PX)
        if hit is None:
            continue
        err, m = hit
        outline, box = np.asarray(m["bbox_px"]), np.asarray(det["bbox_px"])
        yield m["visible_fraction"], (outline[2:] - outline[:2]) - (box[2:] - box[:2]), err


def collect(root: Path, frames: dict, splits: set[str]) -> tuple[np.ndarray, np.ndarray]:
    """(cuts of fully visible markers (n, 2), error / cut ratios of partly hidden ones)."""
    full, ratios = [], []
    for fid, dets in sorted(frames.items()):
        label = json.loads((root / "labels" / f"{fid}.json").read_text())
        if label["spec"]["split"] not in splits:
            continue
        for visible, cut, err in frame_cuts(label, dets):
            if visible >= 0.99:
                full.append(cut)
            elif visible < 0.95:
                ratios += [abs(err[ax]) / cut[ax] for ax in (0, 1) if cut[ax] > 1.0]
    return np.asarray(full).reshape(-1, 2), np.asarray(ratios)


def robust_std(x: np.ndarray) -> float:
    return float(1.4826 * np.median(np.abs(x - np.median(x))))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("dataset", type=Path)
    ap.add_argument("detections", type=Path, help="DETS.json of dockfactory detect (--split all)")
    ap.add_argument("--splits", default="train", help="comma-separated (default: train)")
    args = ap.parse_args()
    splits = set(args.splits.split(","))
    full, ratios = collect(args.dataset, json.loads(args.detections.read_text())["frames"], splits)
    if not len(full) or not len(ratios):
        raise SystemExit(f"{args.detections}: no fully visible or no partly hidden refined markers in splits {sorted(splits)}")
    p999 = np.percentile(full, 99.9, axis=0)
    print(f"splits {','.join(sorted(splits))}: {len(full)} fully visible refined markers: box cut robust std "
          f"u {robust_std(full[:, 0]):.3f} v {robust_std(full[:, 1]):.3f} px, 99.9th percentile u {p999[0]:.2f} v {p999[1]:.2f} px")
    lo, hi = np.percentile(ratios, [10, 90])
    print(f"  partly hidden (visible < 0.95), cut > 1 px: {len(ratios)} axis cuts, |error along the axis| / cut "
          f"median {np.median(ratios):.2f}, 10-90 % {lo:.2f}-{hi:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
