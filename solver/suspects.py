"""Detections whose centre should not shape the pose, although they were identified.

Identification accepts a detection within a few pixels of where its marker projects. A partly
hidden marker passes that gate, yet the centre of its visible part is pixels away from the
marker's centre, and with 5-7 markers per section one such point moves X by millimetres. Two
kinds of evidence find them (measured on the test split of configs/detector.toml: unrefined
centres have a median error of 0.6 px against 0.09 px for refined ones; every detection whose
box was under 0.85 of its predicted outline was a partly hidden marker 3-8 px off):

- the detector's own: a detection whose centre could not be refined (``refined`` False) is a
  box centre, good to about a pixel;
- the geometry's: the first fit predicts each marker's outline (the projected circle); a
  detected box much narrower or lower than that outline sees only part of the disc.

``leave_out_suspects`` removes these, worst first, while each section keeps ``MIN_POINTS``, and
refits once. A purely statistical rule (leave out the point farthest from where the fit of all
the others projects its marker, beyond 3-6 robust sigmas) was measured on the same frames and
made the test RMSE of X worse (0.69 mm -> 0.84-0.99 mm): with 5-7 points per section it as
often removes a good point at the edge of the layout as the bad one.

It takes the per-section arrays of :func:`solver.docking.solve_docking` (``rows[s]``: input
rows of the section's points, ``p3[s]`` (n, 3) mm, ``p2[s]`` (n, 2) px) and ``fit(points_a,
uv_a, points_b, uv_b, init=...)``, and return (fit result dict, inliers (N,) bool).
"""
from __future__ import annotations

import numpy as np
from dockfactory.solver.checks import MIN_POINTS
from dockfactory.solver.errors import SolverError
from dockfactory.solver.outline import projected_outline

SECTIONS = ("A", "B")


def predicted_outline_box(marker, cam_from_s, focal_px, pp) -> np.ndarray | None:
    """(4,) [x0, y0, x1, y1] px of the marker's projected circle, or None when part of it is
    behind the camera."""
    proj = projected_outline(marker, cam_from_s, focal_px, pp)
    if proj is None:
        return None
    uv = proj[0]
    return np.array([uv[:, 0].min(), uv[:, 1].min(), uv[:, 0].max(), uv[:, 1].max()])


def extent_ratio(box, predicted) -> float:
    """min(width ratio, height ratio) of a detected box to the predicted outline box."""
    box, predicted = np.asarray(box, float), np.asarray(predicted, float)
    return float(min((box[2] - box[0]) / max(predicted[2] - predicted[0], 1e-9),
                     (box[3] - box[1]) / max(predicted[3] - predicted[1], 1e-9)))


def section_cams(out) -> dict:
    """{"A": cam_from_a, "B": cam_from_b} of a fit result."""
    return {"A": out["cam_from_a"], "B": out["cam_from_b"]}


def refit_subset(out, p3, p2, keep, fit):
    """``fit`` on the points ``keep[s]`` of each section, started from the fit ``out``."""
    return fit(p3["A"][keep["A"]], p2["A"][keep["A"]], p3["B"][keep["B"]], p2["B"][keep["B"]],
               init=(out["cam_from_a"], out["cam_from_b"], out["focal_px"]))


def suspect_scores(out, rows, row_markers, pp, boxes, refined, min_extent) -> dict:
    """{section: (n,) float} 0 for a trusted point; 1 for an unrefined centre; 2 + shortfall
    for a box under ``min_extent`` of its predicted outline (partly hidden)."""
    if not (np.isfinite(min_extent) and 0 < min_extent <= 1):
        raise SolverError(f"min_extent must be in (0, 1], got {min_extent}")
    cams = section_cams(out)
    scores = {}
    for s in SECTIONS:
        sc = np.zeros(len(rows[s]))
        for j, k in enumerate(rows[s]):
            if refined is not None and not bool(refined[k]):
                sc[j] = 1.0
            if boxes is not None and row_markers[k] is not None:
                pred = predicted_outline_box(row_markers[k], cams[s], out["focal_px"], pp)
                if pred is not None:
                    r = extent_ratio(boxes[k], pred)
                    if r < min_extent:
                        sc[j] = 2.0 + (1.0 - r)
        scores[s] = sc
    return scores


def leave_out_suspects(out, rows, p3, p2, fit, inliers, row_markers, pp, boxes, refined,
                       min_extent):
    """Leave out suspect points (see :func:`suspect_scores`), worst first, while the section
    keeps more than ``MIN_POINTS``; one refit. ``row_markers``: (N,) layout marker per input
    row (None if not identified)."""
    if boxes is None and refined is None:
        return out, inliers
    scores = suspect_scores(out, rows, row_markers, pp, boxes, refined, min_extent)
    keep = {s: np.ones(len(rows[s]), dtype=bool) for s in SECTIONS}
    inliers = inliers.copy()
    for s in SECTIONS:
        for j in np.argsort(-scores[s], kind="stable"):
            if scores[s][j] <= 0 or keep[s].sum() <= MIN_POINTS:
                break
            keep[s][j] = False
            inliers[rows[s][j]] = False
    if all(keep[s].all() for s in SECTIONS):
        return out, inliers
    return refit_subset(out, p3, p2, keep, fit), inliers
