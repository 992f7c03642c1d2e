"""Fingerprints of a label that another CPU's Cycles must reproduce (``dataset verify --manifest``).

Fingerprint v1 (``label_geometry_sha256``) is the sha256 of the label without the image
measurements. Fingerprint v2 is the sha256 of the label without the image measurements and the
index-pass fields (``label_core_sha256``), plus the index-pass numbers themselves
(``index_measurements``), compared within ``INDEX_TOLERANCE_PX``. Classes decided from those
numbers (``visibility``, ``legible``) stay in the digest: they change what the exports call
ground truth, so they must match exactly.

Why and how: docs/datasets.md, "Label fingerprints".
"""
from __future__ import annotations

import hashlib
import json

import numpy as np

INDEX_TOLERANCE_PX = 2.0     # per count and per box edge; measured max on another CPU: 1 (module docstring)
MARKER_INDEX_KEYS = ("visible_pixels", "visible_fraction", "bbox_visible_px")
SECTION_INDEX_KEYS = ("pixels_visible", "visible_fraction", "bbox_visible_px")


def _digest(label: dict) -> str:
    return hashlib.sha256(json.dumps(label, sort_keys=True, separators=(",", ":")).encode()).hexdigest()


def _without_image_measurements(label: dict) -> dict:
    for m in label.get("markers", []):
        m.pop("chroma", None)
    label.get("derived", {}).pop("auto_exposure_scale", None)
    return label


def label_geometry_sha256(text: bytes) -> str:
    """Fingerprint v1: sha256 of a label without what it measures on the rendered image (markers'
    ``chroma``, ``derived.auto_exposure_scale``)."""
    return _digest(_without_image_measurements(json.loads(text)))


def label_core_sha256(text: bytes) -> str:
    """Fingerprint v2's digest: sha256 of a label without its image measurements and without its
    index-pass counts, boxes and fractions (module docstring)."""
    label = _without_image_measurements(json.loads(text))
    for m in label.get("markers", []):
        for key in MARKER_INDEX_KEYS:
            m.pop(key, None)
    for s in label.get("sections", []):
        for key in SECTION_INDEX_KEYS:
            s.pop(key, None)
    return _digest(label)


def _count_and_box(count, box) -> list[float]:
    box = box if box is not None else [None] * 4
    return [np.nan if v is None else float(v) for v in [count, *box]]


def index_measurements(text: bytes) -> np.ndarray:
    """Fingerprint v2's numbers: per marker (label order) its visible pixel count and visible box
    (4 edges), then the same per section; float64, NaN where the label has none."""
    label = json.loads(text)
    rows = [_count_and_box(m.get("visible_pixels"), m.get("bbox_visible_px")) for m in label.get("markers", [])]
    rows += [_count_and_box(s.get("pixels_visible"), s.get("bbox_visible_px")) for s in label.get("sections", [])]
    return np.array(rows, np.float64).reshape(-1)


def index_difference(measured: np.ndarray, published: np.ndarray) -> float | None:
    """Largest absolute difference (px) between two ``index_measurements``, or None when they do
    not describe the same things (another length, or a count or box present in only one)."""
    if measured.shape != published.shape or not np.array_equal(np.isnan(measured), np.isnan(published)):
        return None
    finite = ~np.isnan(measured)
    return float(np.abs(measured[finite] - published[finite]).max()) if finite.any() else 0.0
