"""Where a render's pose RMSE above the converged reference's comes from: per component, the
candidate's RMSE over the reference's, the RMS of the per-frame difference d = e_cand - e_ref
over the reference's RMSE, their correlation, the ratio d alone would give if uncorrelated
(sqrt(1 + (rms d / rmse ref)^2)), and the frames that add most to the candidate's sum of squares
(with each frame's centre RMS in both renders).

    python -m bench.render.pose_gap REFERENCE CANDIDATE [--out FILE.json]

Both are renders of the same config and frames (bench/render/marker_sampling.py's scenes), each one
dataset or several pooled as ``DIR+DIR2`` (that bench's ``measure_pooled``); their detections are
cached beside them as that bench caches them.
"""
from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from bench.render.marker_sampling import measure_pooled
from dockfactory.core.io import write_json_atomic

COMPS = ("x", "y", "alpha")


def _centre_rms(errs) -> float:
    e = np.asarray(errs, dtype=float).reshape(-1, 2)
    return float(np.sqrt(np.mean(np.sum(e ** 2, axis=1)))) if len(e) else float("nan")


def pose_gap(ref: dict, cand: dict, top: int = 6) -> dict:
    """The figures of the module docstring for two ``measure`` results (frames both solved)."""
    common = sorted(set(ref["rows"]) & set(cand["rows"]))
    out = {"frames": len(common)}
    for c in COMPS:
        er = np.array([ref["rows"][f][f"err_{c}"] for f in common])
        ec = np.array([cand["rows"][f][f"err_{c}"] for f in common])
        d, gain = ec - er, ec ** 2 - er ** 2
        r_ref = float(np.sqrt(np.mean(er ** 2)))
        rel = float(np.sqrt(np.mean(d ** 2))) / r_ref
        out[c] = {"rmse_ref": r_ref, "rmse_cand": float(np.sqrt(np.mean(ec ** 2))), "d_over_ref": rel,
                  "corr_ref_d": float(np.corrcoef(er, d)[0, 1]), "uncorrelated_ratio": math.sqrt(1 + rel * rel),
                  "top": [{"frame": common[i], "ref": float(er[i]), "cand": float(ec[i]),
                           "share": float(gain[i] / gain.sum()) if gain.sum() else float("nan"),
                           "centre_rms_ref_cand": [_centre_rms(ref["centres"][common[i]]),
                                                   _centre_rms(cand["centres"][common[i]])]}
                          for i in np.argsort(-gain)[:top]]}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("reference")
    ap.add_argument("candidate")
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args()
    gap = pose_gap(measure_pooled(args.reference, None), measure_pooled(args.candidate, None))
    for c in COMPS:
        g = gap[c]
        print(f"{c}: ratio {g['rmse_cand'] / g['rmse_ref']:.2f}, rms d / rmse ref {g['d_over_ref']:.2f}, "
              f"corr {g['corr_ref_d']:+.2f} (uncorrelated: {g['uncorrelated_ratio']:.2f}); top frames "
              + ", ".join(f"{t['frame']} ({t['share']:.2f})" for t in g["top"][:3]))
    if args.out:
        write_json_atomic(args.out, {"reference": str(args.reference), "candidate": str(args.candidate), **gap})


if __name__ == "__main__":
    main()
