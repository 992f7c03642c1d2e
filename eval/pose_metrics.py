"""Pose error statistics (pure numpy): the gate statistics' values (eval.gate_statistic), bias, spread,
percentiles, repeatability."""
from __future__ import annotations

import numpy as np

from dockfactory.eval.acceptance import COMPONENTS, POSE_KEYS
from dockfactory.eval.gate_statistic import error_values, spread_values, summary_fields


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
    """Statistics of signed errors (n,): the fields of eval.gate_statistic ``summary_fields`` in
    that order: n, every gate statistic's value (eval.gate_statistic ``error_values``: rmse, mse,
    p95 of |e|, ...), and the errors' own moments: mean (bias), std (ddof 1; 0 for one error) and
    max of |e|. None each (n 0) for no errors."""
    e = np.asarray(errors, dtype=float)
    if e.size == 0:
        own = {"n": 0, "mean": None, "std": None, "max": None}
    else:
        own = {"n": int(e.size), "mean": float(e.mean()), "std": float(e.std(ddof=1)) if e.size > 1 else 0.0,
               "max": float(np.abs(e).max())}
    fields = {**own, **error_values(e)}
    return {k: fields[k] for k in summary_fields() if k in fields}


def repeatability(groups: dict) -> dict:
    """Spread of repeated estimates of static poses.

    ``groups``: pose key -> list of estimate dicts (x, y, ... per capture). Per pose (two or more
    captures): the standard deviation of each component over its captures; pooled: per component
    the spread of every statistic that can gate estimation (eval.gate_statistic ``spread_values``:
    "rmse" the pooled RMS spread sqrt(sum of squared deviations from each pose's mean / sum(n_i -
    1)), "mse" its square, ...), None each without a degree of freedom; ``dof`` = sum(n_i - 1).
    """
    per_pose, values, dof = [], {c: [] for c in COMPONENTS}, 0
    for key, ests in sorted(groups.items()):
        if len(ests) < 2:
            continue
        row = {"pose": key, "captures": len(ests)}
        for c in COMPONENTS:
            v = np.array([e[c] for e in ests], dtype=float)
            values[c].append(v)
            row[c] = float(np.sqrt(((v - v.mean()) ** 2).sum() / (len(v) - 1)))
        dof += len(ests) - 1
        per_pose.append(row)
    pooled = {c: spread_values(values[c]) for c in COMPONENTS}
    return {"per_pose": per_pose, "pooled": pooled, "dof": dof}
