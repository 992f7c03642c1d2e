"""Centre noise under the disc model (solver.disc_noise) and the scale the Cramer-Rao bound takes.

Each centre the solver used is matched as in :mod:`eval.centre_noise` (error = detected minus the
label's ``outline_centroid_px``) and whitened by the relative covariance T_i of its disc's image
(:func:`solver.disc_noise.noise_shapes` of the label's exact geometry): q_i = e_i^T T_i^-1 e_i,
in px^2 of a disc whose minor semi-axis is ``REFERENCE_RADIUS_PX``.

Why and how: docs/acceptance.md, "Centre noise under the disc model".
"""
from __future__ import annotations

import math
from collections import defaultdict

import numpy as np

from dockfactory.eval.centre_noise import MIN_CONDITION_DETECTIONS, used_centre_matches
from dockfactory.eval.pixel_aspect import delivered_ellipses, label_pixel_aspect
from dockfactory.solver.disc_noise import (
    MINOR_EXPONENT,
    NOISE_FLOOR,
    REFERENCE_RADIUS_PX,
    disc_ellipses,
    noise_shapes,
)

__all__ = ["label_noise_shapes", "student_t_fit", "scale_stats", "disc_noise_block",
           "disc_scales", "frame_noise_px"]

T_DOF_GRID = np.geomspace(0.5, 1000.0, 48)   # the Gaussian limit is tried as well
EM_ITERATIONS = 300


def label_noise_shapes(label: dict, markers) -> np.ndarray | None:
    """(n, 2, 2): relative centre covariance of ``markers`` (label markers) under the label's
    exact camera, in its delivered pixels (each disc's image with K's fy on the rows:
    eval.pixel_aspect.delivered_ellipses); None when the label lacks the disc geometry
    (centre_d_mm, normal_d, diameter_mm) or a disc is not in front of the camera."""
    try:
        cam = np.asarray(label["camera"]["cam_from_d"], dtype=float)
        centres = np.array([m["center_d_mm"] for m in markers], dtype=float).reshape(-1, 3)
        normals = np.array([m["normal_d"] for m in markers], dtype=float).reshape(-1, 3)
        diameters = [float(m["diameter_mm"]) for m in markers]
        focal = float(label["camera"]["focal_px"])
    except (KeyError, TypeError, ValueError):
        return None
    centres = centres @ cam[:3, :3].T + cam[:3, 3]
    if np.any(centres[:, 2] <= 0):
        return None
    ellipses = disc_ellipses(centres, normals @ cam[:3, :3].T, diameters, focal)
    return noise_shapes(delivered_ellipses(ellipses, label_pixel_aspect(label)))


def _t_loglik(q: np.ndarray, nu: float, s2: float) -> float:
    n = q.size
    return (n * (math.lgamma((nu + 2) / 2) - math.lgamma(nu / 2) - math.log(nu * math.pi * s2))
            - (nu + 2) / 2 * float(np.log1p(q / (nu * s2)).sum()))


def student_t_fit(q) -> tuple[float, float]:
    """(s px, nu) of the bivariate Student t fitted by maximum likelihood to whitened squared
    errors ``q`` (n,); nu = inf for the Gaussian limit."""
    q = np.asarray(q, dtype=float)
    s2 = float(q.mean()) / 2.0
    best = (-q.size * math.log(2 * math.pi * s2) - q.sum() / (2 * s2), s2, math.inf)
    for nu in T_DOF_GRID:
        s2 = float(q.mean()) / 2.0
        for _ in range(EM_ITERATIONS):
            new = float(np.mean((nu + 2) * q / (nu + q / s2))) / 2.0
            if abs(new - s2) <= 1e-12 * s2:
                break
            s2 = new
        ll = _t_loglik(q, nu, s2)
        if ll > best[0]:
            best = (ll, s2, float(nu))
    return math.sqrt(best[1]), best[2]


def scale_stats(q) -> dict:
    """n, rms_px (sqrt(mean q / 2)), t_scale_px, t_dof (None: Gaussian) and fisher_px of
    whitened squared errors ``q`` (module docstring); scales None without errors."""
    q = np.asarray(q, dtype=float).reshape(-1)
    if q.size == 0 or not q.mean() > 0:
        return {"n": int(q.size), "rms_px": 0.0 if q.size else None, "t_scale_px": None,
                "t_dof": None, "fisher_px": 0.0 if q.size else None}
    s, nu = student_t_fit(q)
    fisher = s if math.isinf(nu) else s * math.sqrt((nu + 4) / (nu + 2))
    return {"n": int(q.size), "rms_px": math.sqrt(float(q.mean()) / 2.0), "t_scale_px": s,
            "t_dof": None if math.isinf(nu) else nu, "fisher_px": fisher}


def _frame_q(label: dict, dets: list, marker_ids, min_score: float) -> np.ndarray | None:
    """Whitened squared errors (k,) of one frame's used centres (None: no disc geometry)."""
    matches, _ = used_centre_matches(label, dets, marker_ids, min_score)
    if not matches:
        return np.zeros(0)
    shapes = label_noise_shapes(label, [m for m, _ in matches])
    if shapes is None:
        return None
    e = np.array([err for _, err in matches], dtype=float)
    return np.einsum("ni,ni->n", e, np.linalg.solve(shapes, e[:, :, None])[:, :, 0])


def disc_noise_block(ds, poses: dict, detections: dict, min_score: float,
                     splits=("test",)) -> dict | None:
    """The used centres' noise under the disc model on the solved frames of ``splits``: overall
    and per condition (:func:`scale_stats`); None when a label lacks the disc geometry."""
    by_cond = defaultdict(list)
    for fid in ds.frames(splits):
        rec = poses["frames"].get(fid)
        if not rec or rec.get("ok") is not True or fid not in ds.labels:
            continue
        label = ds.labels[fid]
        q = _frame_q(label, detections["frames"].get(fid, []), rec.get("marker_ids"), min_score)
        if q is None:
            return None
        by_cond[label["spec"]["condition"]].append(q)
    per = {c: np.concatenate(v) for c, v in sorted(by_cond.items())}
    every = np.concatenate(list(per.values())) if per else np.zeros(0)
    return {"model": {"minor_exponent": MINOR_EXPONENT, "noise_floor": NOISE_FLOOR,
                      "reference_radius_px": REFERENCE_RADIUS_PX},
            "method": "used centres whitened by their disc's relative covariance "
                      "(solver.disc_noise); bound scale: Fisher-equivalent sigma of a fitted "
                      "bivariate Student t",
            "overall": scale_stats(every), "by_condition": {c: scale_stats(q) for c, q in per.items()}}


def disc_scales(block: dict | None) -> dict | None:
    """{"value": overall fisher_px, "by_condition": {condition: fisher_px}} (conditions with at
    least MIN_CONDITION_DETECTIONS centres), or None without a positive overall scale."""
    overall = (block or {}).get("overall") or {}
    if not overall.get("fisher_px"):
        return None
    return {"value": overall["fisher_px"],
            "by_condition": {c: s["fisher_px"] for c, s in block["by_condition"].items()
                             if s["n"] >= MIN_CONDITION_DETECTIONS and s["fisher_px"]}}


def frame_noise_px(shapes: np.ndarray, scale_px: float) -> float:
    """Per-axis noise (px) averaged over points of relative covariances ``shapes`` (n, 2, 2) at
    the disc model's ``scale_px``: scale sqrt(mean tr T / 2)."""
    return float(scale_px * math.sqrt(np.trace(shapes, axis1=1, axis2=2).mean() / 2.0))
