"""Is the solver's covariance honest? Standard scores of the pose error (pure numpy).

Per solved frame and component c: z_c = (estimate - truth)_c / sqrt(C[k, k]), with C the 6 x 6
``covariance`` of the pose record over ``POSE_NAMES`` (X, Y, Z mm; alpha, beta, gamma deg: the
units of the error, :func:`eval.pose_metrics.pose_error`) and k the index of c's name there. If
the covariance describes the error, z is standard normal: RMS z 1 and 95.45 % of |z| within 2.
RMS z above 1 means the reported std is too small (users gating on it accept too much).
"""
from __future__ import annotations

import math
from collections import defaultdict

import numpy as np

from dockfactory.core.names import COMPONENTS, POSE_KEYS, POSE_NAMES
from dockfactory.generator.datasets.folder import DatasetError

WITHIN = 2.0                                        # "within 2 sigma"
ROBUST_SCALE = 1.4826                               # median |z| of N(0, 1) is 1 / 1.4826
EXPECTED = {"rms_z": 1.0, "robust_z": 1.0,
            "within_2sigma": math.erf(WITHIN / math.sqrt(2.0))}   # N(0, 1): 0.9545

__all__ = ["WITHIN", "EXPECTED", "reported_std", "standard_scores", "z_stats", "calibration_block"]


def reported_std(covariance, where: str = "covariance") -> dict:
    """{component: std or None} from a pose record's covariance (6, 6) over POSE_NAMES; None
    where the variance is not a finite positive number. A covariance of another shape is bad
    input (DatasetError naming ``where``)."""
    try:
        cov = np.asarray(covariance, dtype=float)
    except (TypeError, ValueError):
        raise DatasetError(f"{where}: expected a 6 x 6 matrix of numbers") from None
    if cov.shape != (6, 6):
        raise DatasetError(f"{where}: expected a 6 x 6 matrix over {', '.join(POSE_NAMES)}, "
                           f"got shape {cov.shape}")
    var = np.diag(cov)
    return {c: (float(np.sqrt(var[k])) if np.isfinite(var[k]) and var[k] > 0 else None)
            for c, k in ((c, POSE_NAMES.index(POSE_KEYS[c])) for c in COMPONENTS)}


def standard_scores(err: dict, std: dict) -> dict:
    """{component: error / std or None}; ``err`` and ``std`` dicts over COMPONENTS, same units."""
    return {c: (err[c] / std[c] if std.get(c) else None) for c in COMPONENTS}


def z_stats(z) -> dict:
    """n, rms_z, robust_z (1.4826 x median |z|: the core's width, blind to a few outliers),
    mean_z, within_2sigma (fraction of |z| <= 2) and max_abs_z of scores (n,) (None skipped)."""
    v = np.asarray([x for x in z if x is not None], dtype=float)
    if v.size == 0:
        return {"n": 0, "rms_z": None, "robust_z": None, "mean_z": None, "within_2sigma": None,
                "max_abs_z": None}
    a = np.abs(v)
    return {"n": int(v.size), "rms_z": float(np.sqrt(np.mean(v ** 2))),
            "robust_z": float(ROBUST_SCALE * np.median(a)), "mean_z": float(v.mean()),
            "within_2sigma": float(np.mean(a <= WITHIN)), "max_abs_z": float(a.max())}


def calibration_block(rows: list[dict]) -> dict:
    """z statistics of the solved rows (keys ``z_<c>``): overall and per condition, the values
    a calibrated covariance gives (``expected``) and how many solved rows lack a usable std of
    some component (no covariance in the record, or a variance that is not positive)."""
    ok = [r for r in rows if r.get("ok")]
    by_cond = defaultdict(list)
    for r in ok:
        by_cond[r["condition"]].append(r)
    return {"overall": {c: z_stats([r.get(f"z_{c}") for r in ok]) for c in COMPONENTS},
            "by_condition": {cond: {c: z_stats([r.get(f"z_{c}") for r in rs]) for c in COMPONENTS}
                             for cond, rs in sorted(by_cond.items())},
            "expected": dict(EXPECTED),
            "without_std": sum(any(r.get(f"z_{c}") is None for c in COMPONENTS) for r in ok)}
