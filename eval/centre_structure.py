"""The centres' correlated structure, measured, and the pose bound under it.

The bound of eval.evaluate.frame_bound treats a frame's centres as independent, each with its
disc's covariance C_i = s^2 T_i. Detected centres are not (each marker has its own noise; a
frame's centres share errors, which partly fall where the pose does not see them), so a pose can
be better than that bound without beating any bound. This module measures the structure M of the
whitened centre errors T_i^-1/2 e_i over (marker id, axis) on frames the verdict does not use
(train and val; else the test split cross-fitted in two halves), shrunk toward its diagonal by the
Ledoit-Wolf intensity of the same samples (no tuned figure) with a mean diagonal of 1, and bounds a
frame under Sigma_ij = s^2 T_i^1/2 M_ij T_j^1/2: the Cramer-Rao bound and the expected covariance
of the fit weighted by C_i^-1 alone, as the solver's (solver.crb.crb_d_from_b_structured).

Why and how: docs/acceptance.md, "The bound under the centres' measured structure".
"""
from __future__ import annotations

import numpy as np

from dockfactory.core.names import COMPONENTS, POSE_KEYS
from dockfactory.eval.centre_noise import used_centre_matches
from dockfactory.eval.centre_noise_disc import label_noise_shapes
from dockfactory.eval.pixel_aspect import label_pixel_aspect, square_pixel_covariances
from dockfactory.solver import SolverError
from dockfactory.solver.crb import crb_d_from_b_structured

__all__ = ["STRUCTURE_SPLITS", "MIN_STRUCTURE_FRAMES", "MIN_PAIR_FRAMES", "FULLY_VISIBLE",
           "whitened_centre_errors", "structure_moments", "measure_structure", "structured_frame_bound"]

STRUCTURE_SPLITS = ("train", "val")   # frames the verdict does not use
MIN_STRUCTURE_FRAMES = 30             # fewer: no structure is measured (the report says so)
MIN_PAIR_FRAMES = 10                  # a moment over fewer frames is not kept (off-diagonal 0, diagonal 1)
FULLY_VISIBLE = 0.99                  # only whole markers measure it (a hidden edge is another error)
PD_FLOOR = 1e-3                       # smallest eigenvalue kept, of a unit mean diagonal


def sqrt_spd(t: np.ndarray) -> np.ndarray:
    """The symmetric square root of a symmetric positive definite (2, 2) matrix."""
    w, v = np.linalg.eigh(t)
    return (v * np.sqrt(w)) @ v.T


def whitened_centre_errors(label: dict, dets: list[dict], min_score: float) -> dict[str, np.ndarray]:
    """{marker id: T^-1/2 e (2,)} of the frame's fully visible markers matched to a refined detection
    scoring at least ``min_score`` (eval.centre_noise.used_centre_matches); {} without disc geometry."""
    ids = [m["id"] for m in label["markers"]
           if m.get("in_frame", True) and m.get("visible_fraction", 0.0) >= FULLY_VISIBLE]
    refined = [d for d in dets if d.get("refined", True)]
    matches, _ = used_centre_matches(label, refined, ids, min_score)
    shapes = label_noise_shapes(label, [m for m, _ in matches]) if matches else None
    if shapes is None:
        return {}
    return {m["id"]: np.linalg.solve(sqrt_spd(t), e) for (m, e), t in zip(matches, shapes)}


def _pairwise(samples: list[dict[str, np.ndarray]], ids: list[str]) -> tuple[np.ndarray, ...]:
    """(mean products, their sampling variances, counts), each (2n, 2n) over (marker id, axis)."""
    slot = {k: i for i, k in enumerate(ids)}
    total, total2, count = (np.zeros((2 * len(ids),) * 2) for _ in range(3))
    for frame in samples:
        v, ok = np.zeros(2 * len(ids)), np.zeros(2 * len(ids), bool)
        for k, w in frame.items():
            v[2 * slot[k]:2 * slot[k] + 2], ok[2 * slot[k]:2 * slot[k] + 2] = w, True
        prod = np.outer(v, v)
        total += prod
        total2 += prod ** 2
        count += np.outer(ok, ok)
    n = np.maximum(count, 1)
    mean = total / n
    return mean, np.maximum(total2 / n - mean ** 2, 0.0) / n, count


def structure_moments(samples: list[dict[str, np.ndarray]], ids: list[str]) -> tuple[np.ndarray, float]:
    """(M (2n, 2n), shrinkage): the normalised, shrunk second moments of whitened errors ``samples``
    (one {marker id: (2,)} per frame) over ``ids`` (module docstring); a moment seen in fewer than
    MIN_PAIR_FRAMES frames is left out (diagonal 1, off-diagonal 0)."""
    mean, var, count = _pairwise(samples, ids)
    kept = count >= MIN_PAIR_FRAMES
    kept_off = kept & ~np.eye(len(kept), dtype=bool)
    diag = np.where(np.diag(kept), np.diag(mean), np.nan)
    diag = np.where(np.isnan(diag), np.nanmean(diag) if np.any(~np.isnan(diag)) else 1.0, diag)
    off = np.where(kept_off, mean, 0.0)
    shrink = float(np.clip((var * kept_off).sum() / max(float((off ** 2).sum()), 1e-300), 0.0, 1.0))
    for lam in np.linspace(shrink, 1.0, 21):
        m = np.diag(diag) + (1.0 - lam) * off
        m /= np.diag(m).mean()
        if np.linalg.eigvalsh(m).min() > PD_FLOOR:
            return m, float(lam)
    return m, 1.0


def _frame_samples(ds, detections: dict, splits, min_score: float) -> dict[str, dict[str, np.ndarray]]:
    """{frame id: whitened errors} of every frame of ``splits`` with a matched centre (plan order),
    each divided by its (split, condition)'s RMS."""
    groups: dict[tuple, dict] = {}
    for fid in ds.frames(splits):
        if fid not in ds.labels:
            continue
        label = ds.labels[fid]
        w = whitened_centre_errors(label, detections["frames"].get(fid, []), min_score)
        if w:
            groups.setdefault((label["spec"]["split"], label["spec"]["condition"]), {})[fid] = w
    out = {}
    for frames in groups.values():
        rms = float(np.sqrt(np.mean([np.mean(np.square(v)) for f in frames.values() for v in f.values()])))
        out.update({fid: {k: v / rms for k, v in f.items()} for fid, f in frames.items()} if rms > 0 else {})
    return {fid: out[fid] for fid in ds.frames(splits) if fid in out}


def _fold(samples: list[dict[str, np.ndarray]]) -> dict:
    """One measured structure: frames, ids, moments, shrinkage, mean_abs_correlation."""
    ids = sorted({k for f in samples for k in f})
    m, lam = structure_moments(samples, ids)
    d = np.sqrt(np.diag(m))
    off = ~np.eye(len(d), dtype=bool)
    corr = np.abs(m / np.outer(d, d))[off]
    return {"frames": len(samples), "ids": ids, "moments": m.tolist(), "shrinkage": lam,
            "mean_abs_correlation": float(corr.mean()) if corr.size else 0.0}


def measure_structure(ds, detections: dict, min_score: float, splits=STRUCTURE_SPLITS) -> dict:
    """The centres' structure (module docstring) measured where the verdict cannot see it.

    On the frames of ``splits`` when at least MIN_STRUCTURE_FRAMES have a matched centre: one
    fold used for every frame. Else on the test split cross-fitted: its frames in two halves
    (alternating in plan order), each frame bounded by the structure of the half it is not in
    (``use``: frame id -> fold). Returns {"source", "folds": [fold], "use"?} (a fold: "frames",
    "ids", "moments" (2n x 2n list), "shrinkage", "mean_abs_correlation"), or {"source",
    "reason"} when neither has enough frames."""
    samples = _frame_samples(ds, detections, splits, min_score)
    if len(samples) >= MIN_STRUCTURE_FRAMES:
        return {"source": "/".join(splits), "folds": [_fold(list(samples.values()))]}
    test = _frame_samples(ds, detections, ("test",), min_score)
    halves = [[f for k, f in enumerate(test) if k % 2 == h] for h in (0, 1)]
    if min(len(h) for h in halves) < MIN_STRUCTURE_FRAMES:
        return {"source": "none", "reason": f"{len(samples)} frames of {'/'.join(splits)} and {len(test)} test "
                                            f"frames with matched centres: fewer than {MIN_STRUCTURE_FRAMES} (a half)"}
    folds = [_fold([test[f] for f in h]) for h in halves]
    return {"source": "test, cross-fitted in two halves", "folds": folds,
            "use": {f: 1 - h for h in (0, 1) for f in halves[h]}}


def _frame_covariance(label: dict, order: list[dict], fold: dict, scale_px: float):
    """((2N, 2N) px^2 Sigma in the square-pixel pinhole, (N, 2, 2) the fit's weight shapes) under a
    measured ``fold``, or None without disc geometry."""
    shapes = label_noise_shapes(label, order)
    if shapes is None:
        return None
    slot = {k: i for i, k in enumerate(fold["ids"])}
    moments = np.asarray(fold["moments"])
    roots = [sqrt_spd(t) for t in shapes]
    n = len(order)
    sigma = np.zeros((2 * n, 2 * n))
    for a in range(n):
        for b in range(n):
            sa, sb = slot.get(order[a]["id"]), slot.get(order[b]["id"])
            block = (moments[2 * sa:2 * sa + 2, 2 * sb:2 * sb + 2] if sa is not None and sb is not None
                     else np.eye(2) * (a == b))
            sigma[2 * a:2 * a + 2, 2 * b:2 * b + 2] = roots[a] @ block @ roots[b]
    aspect = label_pixel_aspect(label)
    unsquare = np.tile([1.0, 1.0 / aspect], n)   # S^-1 Sigma S^-1, S = diag(1, fy / fx) per point
    return scale_px ** 2 * sigma * np.outer(unsquare, unsquare), square_pixel_covariances(shapes, aspect)


def structured_frame_bound(label: dict, marker_ids, structure: dict, scale_px: float) -> dict | None:
    """{"bound": {component: std}, "fit": {component: std}} of a frame's pose (mm, deg) under the
    measured ``structure`` (:func:`measure_structure`) at the disc model's ``scale_px``: the
    Cramer-Rao bound and the weighted fit's expected std; None without a measured structure, with
    fewer than 4 used markers a section, without disc geometry, or a singular problem."""
    if not structure.get("folds") or not scale_px or not scale_px > 0:
        return None
    fold = structure["folds"][structure.get("use", {}).get(label["frame_id"], 0)]
    by_id = {m["id"]: m for m in label["markers"]}
    ids = [i for i in (marker_ids or []) if i in by_id]
    order = [by_id[i] for i in ids if by_id[i]["section"] == "A"] + [by_id[i] for i in ids if by_id[i]["section"] == "B"]
    n_a = sum(m["section"] == "A" for m in order)
    if n_a < 4 or len(order) - n_a < 4:
        return None
    cov = _frame_covariance(label, order, fold, scale_px)
    if cov is None:
        return None
    pts = np.array([m["center_section_mm"] for m in order], dtype=float)
    cam_from_d = np.asarray(label["camera"]["cam_from_d"], dtype=float)
    try:
        bound, fit = crb_d_from_b_structured(pts[:n_a], cam_from_d, pts[n_a:], cam_from_d @ np.asarray(label["d_from_b"]),
                                             label["camera"]["focal_px"], label["camera"]["principal_point"], *cov)
    except SolverError:
        return None
    return {"bound": {c: bound.std[POSE_KEYS[c]] for c in COMPONENTS},
            "fit": {c: fit.std[POSE_KEYS[c]] for c in COMPONENTS}}
