"""Detections whose centre should not shape the pose, although they were identified.

``leave_out_suspects`` removes these, worst first, while each section keeps ``MIN_POINTS``, and
refits once. A purely statistical rule (leave out the point farthest from where the fit of all
the others projects its marker) did worse: with 5-7 points per section it as often removes a
good point at the edge of the layout as the bad one.

A box is compared with its predicted outline less the frame's own shortfall (:func:`frame_shortfall`):
a camera chain that shrinks every refined box alike (JPEG, a Bayer mosaic, a white ring) hides
nothing, and only a box short of the others is taken for a partly hidden disc.

Why and how: docs/solver.md, "Suspects".
"""
from __future__ import annotations

import numpy as np

from dockfactory.core.names import SECTIONS
from dockfactory.solver.checks import MIN_POINTS
from dockfactory.solver.joint import JointFit, JointFitter, SectionPoints
from dockfactory.solver.outline import projected_outline, projected_outlines

__all__ = ["predicted_outline_box", "predicted_outline_boxes", "extent_ratio", "frame_shortfall",
           "suspect_scores", "leave_out_suspects", "occlusion_variances"]

SHORTFALL_FROM_FRAME = True   # False: boxes against their outlines as they are (the rule before; for benches)
SHORTFALL_MIN_BOXES = 5       # fewer boxes in a frame: no shortfall taken (a median of fewer is a few boxes' own)


def predicted_outline_box(marker, cam_from_s, focal_px, pp, coeffs=None) -> np.ndarray | None:
    """(4,) [x0, y0, x1, y1] px of the marker's projected circle (``coeffs``: lens distortion
    or None), or None when part of it is behind the camera."""
    proj = projected_outline(marker, cam_from_s, focal_px, pp, coeffs)
    if proj is None:
        return None
    uv = proj[0]
    return np.array([uv[:, 0].min(), uv[:, 1].min(), uv[:, 0].max(), uv[:, 1].max()])


def predicted_outline_boxes(markers, cam_from_s, focal_px, pp, coeffs=None):
    """(boxes (m, 4) px, valid (m,) bool): :func:`predicted_outline_box` of each of ``markers``
    (all of one section frame ``cam_from_s``) in one numpy pass; valid False where the box is
    None."""
    if len(markers) == 0:
        return np.zeros((0, 4)), np.zeros(0, dtype=bool)
    uv, _, valid = projected_outlines(markers, cam_from_s, focal_px, pp, coeffs)
    return np.concatenate([uv.min(axis=1), uv.max(axis=1)], axis=1), valid


def extent_ratio(box, predicted) -> float:
    """min(width ratio, height ratio) of a detected box to the predicted outline box."""
    box, predicted = np.asarray(box, float), np.asarray(predicted, float)
    return float(min((box[2] - box[0]) / max(predicted[2] - predicted[0], 1e-9),
                     (box[3] - box[1]) / max(predicted[3] - predicted[1], 1e-9)))


def _box_pairs(fit: JointFit, points: SectionPoints, pp, boxes, coeffs=None) -> dict:
    """{section: [(j, detected box (4,), predicted outline box (4,))]} of the section's points with
    a marker and a predicted outline (``boxes`` (N, 4) px per input row)."""
    out = {}
    for s in SECTIONS:
        rows = points.rows[s]
        with_marker = [j for j, k in enumerate(rows) if points.markers[k] is not None]
        out[s] = []
        if with_marker:
            pred, valid = predicted_outline_boxes([points.markers[rows[j]] for j in with_marker],
                                                  fit.cams[s], fit.focal_px, pp, coeffs)
            out[s] = [(j, np.asarray(boxes[rows[j]], float), box) for j, box, ok in zip(with_marker, pred, valid) if ok]
    return out


def frame_shortfall(pairs: dict) -> np.ndarray:
    """(2,) px per axis (width, height): the median over the frame's boxes (``pairs``:
    :func:`_box_pairs`) of how much shorter each detected box is than its predicted outline, at
    least 0; zeros with fewer than SHORTFALL_MIN_BOXES boxes or SHORTFALL_FROM_FRAME off. Why:
    the refinement's box of a fully visible disc is shorter than its outline by what the camera
    chain does to the disc's edge, alike for every marker of a frame: 0.2-0.7 px through JPEG,
    1.1-1.5 px for a white ring through JPEG or a Bayer mosaic, against the 1 px of box noise the
    occlusion rule allows (bench/results/fit_gate/README.md, "The boxes' shortfall"); a partly
    hidden disc is short of the others, which the median of a frame's boxes is not."""
    cuts = [(p[2:] - p[:2]) - (d[2:] - d[:2]) for sec in pairs.values() for _, d, p in sec]
    if not SHORTFALL_FROM_FRAME or len(cuts) < SHORTFALL_MIN_BOXES:
        return np.zeros(2)
    return np.maximum(np.median(np.array(cuts), axis=0), 0.0)


def suspect_scores(fit: JointFit, points: SectionPoints, pp, boxes, refined,
                   min_extent, coeffs=None) -> dict:
    """{section: (n,) float} 0 for a trusted point; 1 for an unrefined centre; 2 + shortfall
    for a box under ``min_extent`` of its predicted outline (partly hidden).
    ``boxes`` (N, 4) px or None, ``refined`` (N,) bool or None, per input row."""
    pairs = _box_pairs(fit, points, pp, boxes, coeffs) if boxes is not None else {s: [] for s in SECTIONS}
    short = frame_shortfall(pairs)
    scores = {}
    for s in SECTIONS:
        sc = np.zeros(len(points.rows[s]))
        if refined is not None:
            sc[[not bool(refined[k]) for k in points.rows[s]]] = 1.0
        for j, det, pred in pairs[s]:
            r = extent_ratio(det, np.r_[pred[:2], pred[2:] - short])
            if r < min_extent:
                sc[j] = 2.0 + (1.0 - r)
        scores[s] = sc
    return scores


def leave_out_suspects(fit: JointFit, points: SectionPoints, fitter: JointFitter, inliers,
                       boxes, refined, min_extent):
    """Leave out suspect points (see :func:`suspect_scores`), worst first, while the section
    keeps more than ``MIN_POINTS``; one refit. Returns (fit, inliers (N,) bool)."""
    if boxes is None and refined is None:
        return fit, inliers
    pp, coeffs = (fitter.principal_point, None) if fit.intrinsics is None else \
        (fit.intrinsics.principal_point, fit.intrinsics.coeffs)
    scores = suspect_scores(fit, points, pp, boxes, refined, min_extent, coeffs)
    keep = {s: np.ones(len(points.rows[s]), dtype=bool) for s in SECTIONS}
    inliers = inliers.copy()
    for s in SECTIONS:
        for j in np.argsort(-scores[s], kind="stable"):
            if scores[s][j] <= 0 or keep[s].sum() <= MIN_POINTS:
                break
            keep[s][j] = False
            inliers[points.rows[s][j]] = False
    if all(keep[s].all() for s in SECTIONS):
        return fit, inliers
    return fitter.refit(fit, points, keep), inliers


def occlusion_variances(fit: JointFit, points: SectionPoints, pp, boxes, bias: float,
                        margin_px: float, coeffs=None) -> dict | None:
    """{section: (n_s, 2, 2) px^2} the extra centre variance of each point for a partly hidden
    disc (diagonal: u, v), or None when there is none (no ``boxes``, ``bias`` 0 or no box short
    of its outline).

    A box shorter than the outline ``fit`` predicts for its marker, less the frame's shortfall
    (:func:`frame_shortfall`), by ``cut`` px along an axis sees only part of the disc: the centre
    of the visible part's box is cut / 2 off the disc's centre along that axis, and a centre
    refined on the visible edge (the occluder's edge taken for the disc's) is about as far off.
    The variance added is (``bias`` x max(0, cut - ``margin_px``))^2 per axis: ``margin_px`` is the
    box noise of fully visible markers (both constants measured: results/README.md, "Measurements
    behind the code's constants"; bench/occlusion_constants.py). The cut is a difference of extents, so the pose error the
    partly hidden centre itself puts into ``fit`` hardly moves it."""
    if boxes is None or bias <= 0:
        return None
    pairs = _box_pairs(fit, points, pp, boxes, coeffs)
    short = frame_shortfall(pairs)
    out, any_cut = {}, False
    for s in SECTIONS:
        var = np.zeros((len(points.rows[s]), 2, 2))
        for j, det, pred in pairs[s]:
            cut = (pred[2:] - pred[:2]) - (det[2:] - det[:2]) - short
            sd = bias * np.maximum(cut - margin_px, 0.0)
            var[j] = np.diag(sd * sd)
            any_cut = any_cut or bool(np.any(sd > 0))
        out[s] = var
    return out if any_cut else None
