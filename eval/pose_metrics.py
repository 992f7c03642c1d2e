"""Pose error statistics (pure numpy): MSE, RMSE, bias, spread, percentiles, repeatability."""
from __future__ import annotations

import numpy as np

from dockfactory.eval.acceptance import COMPONENTS, POSE_KEYS


def wrap_deg(a):
    return (np.asarray(a, dtype=float) + 180.0) % 360.0 - 180.0


def pose_error(est: dict, true: dict) -> dict[str, float]:
    """est - true per component (x, y, z mm; alpha, beta, gamma deg, wrapped)."""
    out = {}
    for c in COMPONENTS:
        d = est[POSE_KEYS[c]] - true[POSE_KEYS[c]]
        out[c] = float(wrap_deg(d)) if c in ("alpha", "beta", "gamma") else float(d)
    return out


def error_stats(errors) -> dict:
    """Statistics of signed errors (n,): n, mse, rmse, mean (bias), std, p95 and max of |e|."""
    e = np.asarray(errors, dtype=float)
    if e.size == 0:
        return {"n": 0, "mse": None, "rmse": None, "mean": None, "std": None, "p95": None, "max": None}
    a = np.abs(e)
    return {"n": int(e.size), "mse": float(np.mean(e ** 2)), "rmse": float(np.sqrt(np.mean(e ** 2))),
            "mean": float(e.mean()), "std": float(e.std(ddof=1)) if e.size > 1 else 0.0,
            "p95": float(np.percentile(a, 95)), "max": float(a.max())}


def repeatability(groups: dict) -> dict:
    """Spread of repeated estimates of static poses.

    ``groups``: pose key -> list of estimate dicts (x, y, ... per capture). Per pose: the
    standard deviation of each component over its captures; pooled: sqrt(sum of squared
    deviations from each pose's mean / sum(n_i - 1)), the pooled RMS spread ("rmse") and its
    square ("mse").
    """
    per_pose = []
    ss = {c: 0.0 for c in COMPONENTS}
    dof = 0
    for key, ests in sorted(groups.items()):
        if len(ests) < 2:
            continue
        row = {"pose": key, "captures": len(ests)}
        for c in COMPONENTS:
            v = np.array([e[c] for e in ests], dtype=float)
            dev = v - v.mean()
            ss[c] += float((dev ** 2).sum())
            row[c] = float(np.sqrt((dev ** 2).sum() / (len(v) - 1)))
        dof += len(ests) - 1
        per_pose.append(row)
    pooled = {c: ({"rmse": float(np.sqrt(ss[c] / dof)), "mse": float(ss[c] / dof)} if dof else
                  {"rmse": None, "mse": None}) for c in COMPONENTS}
    return {"per_pose": per_pose, "pooled": pooled, "dof": dof}
