"""The common offset of a section's detected centres in a frame, measured on labelled frames.

The centre errors of one section's markers in a frame share a part: each colour's centres move
together through the lens (lateral chromatic aberration), a Bayer sensor and its demosaic, a JPEG's
chroma, the blur of the section's depth. A common shift of one section's centres is what its pose
absorbs without a residual: it moves X and Y of the relative pose and no fit's residuals can show
it. The solver carries it as a prior (solver.options.DockingOptions.section_shift_px) that has to
be measured on other labelled frames of the camera class than the ones it is judged on.

Why and how: docs/acceptance.md, "Measuring the section shift".
"""
from __future__ import annotations

import math

import numpy as np

from dockfactory.core.names import MIN_SCORE
from dockfactory.eval.centre_noise import used_centre_matches
from dockfactory.eval.solve_frames import solve_dataset

MIN_SECTION_MARKERS = 3
MIN_GROUPS = 10   # sections a split must give before its measured shift replaces the card's

__all__ = ["MIN_SECTION_MARKERS", "MIN_GROUPS", "section_groups", "section_shift_stats", "section_shift_block",
           "measure_section_shift", "split_section_shift"]


def section_groups(label: dict, dets: list[dict], marker_ids, min_score: float) -> list[np.ndarray]:
    """The matched centre errors (k, 2) px of each section (class id 0: A, 1: B) of one frame
    that has at least MIN_SECTION_MARKERS of them (:func:`used_centre_matches`)."""
    matches, _ = used_centre_matches(label, dets, marker_ids, min_score)
    out = []
    for cls in (0, 1):
        e = np.array([err for m, err in matches if m["class_id"] == cls], dtype=float).reshape(-1, 2)
        if e.shape[0] >= MIN_SECTION_MARKERS:
            out.append(e)
    return out


def section_shift_stats(groups) -> dict:
    """{"groups", "shift_axis_px" [x, y] (the shift's std per axis, module docstring),
    "mean_axis_px" [x, y] (the mean section offset), "section_mean_rms_px" [x, y] (RMS of the
    section means, noise included)}; shift None without a group."""
    groups = [np.asarray(g, dtype=float).reshape(-1, 2) for g in groups]
    groups = [g for g in groups if g.shape[0] >= MIN_SECTION_MARKERS]
    if not groups:
        return {"groups": 0, "shift_axis_px": None, "mean_axis_px": None, "section_mean_rms_px": None}
    means = np.array([g.mean(axis=0) for g in groups])
    noise = np.array([g.var(axis=0, ddof=1) / g.shape[0] for g in groups])
    shift2 = np.maximum(np.mean(means ** 2 - noise, axis=0), 0.0)
    return {"groups": len(groups), "shift_axis_px": [float(math.sqrt(v)) for v in shift2],
            "mean_axis_px": means.mean(axis=0).tolist(),
            "section_mean_rms_px": np.sqrt(np.mean(means ** 2, axis=0)).tolist()}


def section_shift_block(ds, poses: dict, detections: dict, min_score: float, splits=("test",)) -> dict:
    """:func:`section_shift_stats` over the solved frames of ``splits`` (``ds`` an opened
    Dataset, ``poses`` and ``detections`` the parsed files), the frames' markers being those
    each pose record used (``marker_ids``)."""
    groups = []
    for fid in ds.frames(splits):
        rec = poses["frames"].get(fid)
        if not rec or rec.get("ok") is not True or fid not in ds.labels:
            continue
        groups += section_groups(ds.labels[fid], detections["frames"].get(fid, []), rec.get("marker_ids"),
                                 min_score)
    return {"splits": list(splits), **section_shift_stats(groups)}


def measure_section_shift(ds, detections: dict, splits=("test",), min_score: float = MIN_SCORE) -> dict:
    """:func:`section_shift_block` of ``detections`` on ``splits`` of the opened dataset ``ds``,
    each frame solved alone with the pinhole model and no shift (the markers a fit uses)."""
    poses = solve_dataset(ds, splits, detections=detections, min_score=min_score, section_shift_px=(0.0, 0.0))
    return section_shift_block(ds, poses, detections, min_score, splits)


def split_section_shift(ds, detections: dict, split: str = "val", min_groups: int = MIN_GROUPS) -> dict | None:
    """:func:`measure_section_shift` of ``split`` when ``detections`` cover its frames and they give
    at least ``min_groups`` sections, else None: a dataset's own val frames are labelled frames of
    its camera class that the judge does not score (eval.solve_frames.solve_dataset's
    ``section_shift_px``); the block names the split."""
    frames = [f for f in ds.frames((split,)) if f in detections.get("frames", {})]
    if not frames:
        return None
    block = measure_section_shift(ds, detections, (split,))
    return block if block["groups"] >= min_groups else None
