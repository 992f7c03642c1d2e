"""The evaluation's "camera model" block: the same test frames (the same detections, or the same
oracle centres) solved four ways, the paper's pinhole beside self-calibration per frame and per
docking run, and the reference of a calibrated camera (each frame's centres undistorted with its
label's true intrinsics, the principal point given; the focal length still estimated), with the
error of each pose and of the intrinsics each assumes or estimates against the truth in the
labels (principal point, k1, k2, focal length), and each pose RMSE over the reference's (what
self-calibration costs against a calibrated camera)."""
from __future__ import annotations

from collections import Counter

import numpy as np

from dockfactory.core.names import MIN_SCORE
from dockfactory.eval.pose_metrics import error_stats, pose_error
from dockfactory.eval.solve_frames import has_docking_runs, solve_dataset

# (name, camera model, self-calibration, solved through the labels' true camera)
MODES = (("pinhole (paper)", "pinhole", None, False), ("self-calibrated per frame", "auto", "frame", False),
         ("self-calibrated per docking run", "auto", "sequence", False),
         ("true intrinsics per frame (reference)", "pinhole", None, True),
         ("true intrinsics per docking run (reference)", "pinhole", "sequence", True))
# the reference each solve's RMSE is divided by: the same frames, solved the same way (alone, or
# as one run sharing the camera's pose relative to A), through the true camera
REFERENCE_OF = {"pinhole (paper)": MODES[3][0], "self-calibrated per frame": MODES[3][0],
                "self-calibrated per docking run": MODES[4][0], MODES[3][0]: MODES[3][0], MODES[4][0]: MODES[4][0]}
POSE_COMPONENTS = ("x", "y", "alpha")


def _stats(values) -> dict:
    s = error_stats(values)
    return {k: s[k] for k in ("n", "mean", "rmse", "p95")}


def _intrinsics_errors(rec: dict, label: dict, centre) -> dict:
    """Estimated (or assumed: the image centre, no distortion) minus true intrinsics."""
    cam = label["camera"]
    intr = rec.get("intrinsics") or {}
    if rec.get("true_camera"):
        dist = (cam.get("distortion") or [0.0] * 5) + [0.0] * 5
        intr = {"cx": cam["principal_point"][0], "cy": cam["principal_point"][1], "k1": dist[0], "k2": dist[1]}
    true_pp = np.array(cam["principal_point"], dtype=float)
    est_pp = np.array([intr.get("cx", centre[0]), intr.get("cy", centre[1])], dtype=float)
    dist = (cam.get("distortion") or [0.0] * 5) + [0.0] * 5
    return {"pp_px": float(np.hypot(*(est_pp - true_pp))), "k1": intr.get("k1", 0.0) - dist[0],
            "k2": intr.get("k2", 0.0) - dist[1], "focal_pct": 100.0 * (rec["focal_px"] / cam["focal_px"] - 1.0)}


def mode_block(ds, poses: dict) -> dict:
    labels = {f: ds.labels[f] for f in poses["frames"]}
    centre = poses["principal_point"]
    ok = {f: {**r, "true_camera": poses.get("true_camera", False)} for f, r in poses["frames"].items() if r["ok"]}
    errs = [pose_error(r["pose"], labels[f]["pose_b_in_d"]) for f, r in ok.items()]
    intr = [_intrinsics_errors(r, labels[f], centre) for f, r in ok.items()]
    return {"n_frames": len(poses["frames"]), "n_solved": len(ok),
            "models_chosen": dict(Counter(r.get("camera_model", "pinhole") for r in ok.values())),
            "pose": {c: _stats([e[c] for e in errs]) for c in POSE_COMPONENTS},
            "intrinsics_error": {k: _stats([e[k] for e in intr]) for k in ("pp_px", "k1", "k2", "focal_pct")}}


def camera_models_block(ds, detections: dict | None, sigma_px: float, min_score: float = MIN_SCORE) -> dict:
    """Per mode (MODES): its solve of the test split and the block of :func:`mode_block`; the
    per-docking-run modes only for a dataset with docking runs (without, no frames share a camera)."""
    out = {}
    runs = has_docking_runs(ds)
    for name, model, calib, true_camera in MODES:
        if calib == "sequence" and not runs:
            continue
        src = {"detections": detections, "min_score": min_score} if detections is not None else \
              {"oracle_sigma_px": float(sigma_px)}
        poses = solve_dataset(ds, ("test",), camera_model=model, self_calibrate=calib,
                              true_camera=true_camera, **src)
        out[name] = {"camera_model": model, "self_calibrate": calib, **mode_block(ds, poses)}
    for name, block in out.items():
        ref = out[REFERENCE_OF[name]]["pose"]
        block["rmse_over_reference"] = {c: (block["pose"][c]["rmse"] / ref[c]["rmse"]
                                            if block["pose"][c].get("rmse") and ref[c].get("rmse") else None)
                                        for c in POSE_COMPONENTS}
    return out
