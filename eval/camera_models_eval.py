"""The evaluation's "camera model" block: the same test frames (the same detections, or the same
oracle centres) solved three ways, the paper's pinhole beside self-calibration per frame and per
docking run, with the error of each pose and of the intrinsics each assumes or estimates against
the truth in the labels (principal point, k1, k2, focal length)."""
from __future__ import annotations

from collections import Counter

import numpy as np

from dockfactory.core.names import MIN_SCORE
from dockfactory.eval.pose_metrics import error_stats, pose_error
from dockfactory.eval.solve_frames import solve_dataset

MODES = (("pinhole (paper)", "pinhole", None), ("self-calibrated per frame", "auto", "frame"),
         ("self-calibrated per docking run", "auto", "sequence"))
POSE_COMPONENTS = ("x", "y", "alpha")


def _stats(values) -> dict:
    s = error_stats(values)
    return {k: s[k] for k in ("n", "mean", "rmse", "p95")}


def _intrinsics_errors(rec: dict, label: dict, centre) -> dict:
    """Estimated (or assumed: the image centre, no distortion) minus true intrinsics."""
    cam = label["camera"]
    intr = rec.get("intrinsics") or {}
    true_pp = np.array(cam["principal_point"], dtype=float)
    est_pp = np.array([intr.get("cx", centre[0]), intr.get("cy", centre[1])], dtype=float)
    dist = (cam.get("distortion") or [0.0] * 5) + [0.0] * 5
    return {"pp_px": float(np.hypot(*(est_pp - true_pp))), "k1": intr.get("k1", 0.0) - dist[0],
            "k2": intr.get("k2", 0.0) - dist[1], "focal_pct": 100.0 * (rec["focal_px"] / cam["focal_px"] - 1.0)}


def mode_block(ds, poses: dict) -> dict:
    labels = {f: ds.labels[f] for f in poses["frames"]}
    centre = poses["principal_point"]
    ok = {f: r for f, r in poses["frames"].items() if r["ok"]}
    errs = [pose_error(r["pose"], labels[f]["pose_b_in_d"]) for f, r in ok.items()]
    intr = [_intrinsics_errors(r, labels[f], centre) for f, r in ok.items()]
    return {"n_frames": len(poses["frames"]), "n_solved": len(ok),
            "models_chosen": dict(Counter(r.get("camera_model", "pinhole") for r in ok.values())),
            "pose": {c: _stats([e[c] for e in errs]) for c in POSE_COMPONENTS},
            "intrinsics_error": {k: _stats([e[k] for e in intr]) for k in ("pp_px", "k1", "k2", "focal_pct")}}


def camera_models_block(ds, detections: dict | None, sigma_px: float, min_score: float = MIN_SCORE) -> dict:
    """Per mode (MODES): its solve of the test split and the block of :func:`mode_block`."""
    out = {}
    for name, model, calib in MODES:
        src = {"detections": detections, "min_score": min_score} if detections is not None else \
              {"oracle_sigma_px": float(sigma_px)}
        poses = solve_dataset(ds, ("test",), camera_model=model, self_calibrate=calib, **src)
        out[name] = {"camera_model": model, "self_calibrate": calib, **mode_block(ds, poses)}
    return out
