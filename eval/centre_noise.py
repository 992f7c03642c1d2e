"""Centre noise of the detections the solver used, against the exact image centroid (pixels).

The noise that shapes a pose is that of the centres its fit used. For every solved frame of the
measured splits these are the markers of the pose record's ``marker_ids`` (the fit's inliers;
suspects it left out are in ``rejected_ids`` and not measured). A poses file names markers, not
detection rows, so each used marker is matched to a detection of its class scoring at least
``min_score``, nearest first and one detection per marker, and its error is the detected centre
minus the exact centroid of the marker's image (label ``outline_centroid_px``: what a perfect
detector measures; the solver itself corrects the perspective offset to the projected centre).

Why and how: docs/acceptance.md, "Centre noise".
"""
from __future__ import annotations

import math
from collections import defaultdict

import numpy as np

GATE_RADIUS_FRACTION = 0.5
FALLBACK_GATE_PX = 3.0
ROBUST_SCALE = 1.4826              # MAD -> std of a Gaussian
MIN_CONDITION_DETECTIONS = 30      # a condition's own sigma needs this many detections

__all__ = ["GATE_RADIUS_FRACTION", "FALLBACK_GATE_PX", "MIN_CONDITION_DETECTIONS", "gate_px",
           "used_centre_matches", "used_centre_errors", "noise_stats", "centre_noise_block", "condition_sigmas", "used_sigma",
           "DEFAULT_SIGMA_PX"]


def gate_px(marker: dict) -> float:
    """Match gate (px) of a label marker: GATE_RADIUS_FRACTION x its apparent radius."""
    area = marker.get("area_px")
    if area is None or not area > 0:
        return FALLBACK_GATE_PX
    return GATE_RADIUS_FRACTION * math.sqrt(area / math.pi)


def used_centre_matches(label: dict, dets: list[dict], marker_ids, min_score: float):
    """([(label marker, error (2,) px)] of the used markers matched inside their gate, detected
    minus ``outline_centroid_px``, nearest first; number of used markers without a detection
    inside it)."""
    used = set(marker_ids or ())
    marks = [m for m in label["markers"] if m["id"] in used]
    dets = [d for d in dets if d.get("score", 1.0) >= min_score]
    pairs = []
    for i, m in enumerate(marks):
        centroid = m.get("outline_centroid_px") or m["center_px"]
        for j, d in enumerate(dets):
            if d["class_id"] == m["class_id"]:
                e = np.subtract(d["center_px"], centroid)
                dist = float(np.hypot(*e))
                if dist <= gate_px(m):
                    pairs.append((dist, i, j, e))
    pairs.sort(key=lambda p: p[0])
    taken_m, taken_d, matches = set(), set(), []
    for _, i, j, e in pairs:
        if i not in taken_m and j not in taken_d:
            taken_m.add(i)
            taken_d.add(j)
            matches.append((marks[i], e))
    return matches, len(marks) - len(matches)


def used_centre_errors(label: dict, dets: list[dict], marker_ids, min_score: float):
    """(errors (k, 2) px, detected minus ``outline_centroid_px``, of the used markers matched
    inside their gate; number of used markers without a detection inside it)."""
    matches, missed = used_centre_matches(label, dets, marker_ids, min_score)
    return np.array([e for _, e in matches], dtype=float).reshape(-1, 2), missed


def noise_stats(errors) -> dict:
    """Per-axis noise of centre errors ``errors`` (n, 2) px: n, rms_px, robust_px (pooled over
    both axes), rms_axis_px, robust_axis_px, mean_px ([x, y]) and median_radial_px."""
    e = np.asarray(errors, dtype=float).reshape(-1, 2)
    if e.shape[0] == 0:
        return {"n": 0, "rms_px": None, "robust_px": None, "rms_axis_px": None,
                "robust_axis_px": None, "mean_px": None, "median_radial_px": None}
    dev = np.abs(e - np.median(e, axis=0))
    return {"n": int(e.shape[0]), "rms_px": float(np.sqrt(np.mean(e ** 2))),
            "robust_px": float(ROBUST_SCALE * np.median(dev)),
            "rms_axis_px": np.sqrt(np.mean(e ** 2, axis=0)).tolist(),
            "robust_axis_px": (ROBUST_SCALE * np.median(dev, axis=0)).tolist(),
            "mean_px": e.mean(axis=0).tolist(),
            "median_radial_px": float(np.median(np.hypot(e[:, 0], e[:, 1])))}


def centre_noise_block(ds, poses: dict, detections: dict, min_score: float,
                       splits=("test",)) -> dict:
    """The centre noise of the detections the solver used on the solved frames of ``splits``
    (``ds`` an opened Dataset; ``poses``, ``detections`` the parsed files): overall and per
    condition (:func:`noise_stats`), with the gate, the frames measured and ``outside_gate``."""
    by_cond, frames, outside = defaultdict(list), 0, 0
    for fid in ds.frames(splits):
        rec = poses["frames"].get(fid)
        if not rec or rec.get("ok") is not True or fid not in ds.labels:
            continue
        label = ds.labels[fid]
        errs, missed = used_centre_errors(label, detections["frames"].get(fid, []),
                                          rec.get("marker_ids"), min_score)
        frames += 1
        outside += missed
        by_cond[label["spec"]["condition"]].append(errs)
    per = {c: np.concatenate(v) for c, v in sorted(by_cond.items())}
    every = np.concatenate(list(per.values())) if per else np.zeros((0, 2))
    return {"method": "detections the solver used (pose record marker_ids, matched by class, "
                      "nearest first) minus the label's outline_centroid_px",
            "gate": {"radius_fraction": GATE_RADIUS_FRACTION, "radius": "sqrt(area_px / pi)",
                     "fallback_px": FALLBACK_GATE_PX},
            "splits": list(splits), "frames": frames, "outside_gate": outside,
            "overall": noise_stats(every), "by_condition": {c: noise_stats(e) for c, e in per.items()}}


def condition_sigmas(block: dict | None, key: str = "rms_px") -> dict:
    """{condition: sigma px} of the conditions with at least MIN_CONDITION_DETECTIONS measured
    detections (the others take the overall sigma)."""
    if not block:
        return {}
    return {c: s[key] for c, s in block["by_condition"].items()
            if s["n"] >= MIN_CONDITION_DETECTIONS and s[key] is not None and s[key] > 0}


DEFAULT_SIGMA_PX = 0.1   # neither detections nor an oracle noise to take it from


def used_sigma(block: dict | None, oracle_sigma_px=None, poses_oracle_sigma_px=None) -> dict:
    """The centre noise the bounds, the oracle and the camera sweeps use: {"name", "value" (px
    per axis), "n" (detections it was measured on), "source", "by_condition" ({condition:
    px}, the per-frame bound's sigma where a condition has MIN_CONDITION_DETECTIONS)}.

    The RMS of :func:`centre_noise_block` (the second moment is what a least-squares fit
    propagates); without measured detections the oracle noise the poses were made with (0 is a
    valid level: ``oracle_sigma_px`` first, then the poses file's), else DEFAULT_SIGMA_PX."""
    overall = (block or {}).get("overall") or {}
    if overall.get("n") and overall.get("rms_px") is not None:
        return {"name": "rms_px", "value": overall["rms_px"], "n": overall["n"],
                "source": "RMS per axis of the centre error of the detections the solver used",
                "by_condition": condition_sigmas(block)}
    for value, what in ((oracle_sigma_px, "the oracle noise given to evaluate"),
                        (poses_oracle_sigma_px, "the oracle noise the poses were made with")):
        if value is not None:
            return {"name": "oracle_sigma_px", "value": float(value), "n": 0, "source": what,
                    "by_condition": {}}
    return {"name": "default", "value": DEFAULT_SIGMA_PX, "n": 0,
            "source": "no detections to measure it on and no oracle noise: assumed",
            "by_condition": {}}
