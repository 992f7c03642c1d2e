"""Matching a detection to its labelled marker, for the bench studies on rendered datasets
(shared by the topics: ``from bench.marker_match import nearest_marker``)."""
from __future__ import annotations

import numpy as np


def nearest_marker(det: dict, markers: list[dict], max_px: float):
    """(centre error (2,) px, marker): the marker of ``det``'s class whose label
    ``outline_centroid_px`` is nearest the detection's ``center_px``, within ``max_px``; or None."""
    centre, best = np.asarray(det["center_px"], dtype=float), None
    for m in markers:
        if m["class_id"] != det["class_id"]:
            continue
        err = centre - np.asarray(m["outline_centroid_px"], dtype=float)
        if np.hypot(*err) < max_px and (best is None or np.hypot(*err) < np.hypot(*best[0])):
            best = (err, m)
    return best
