"""The centre noise of a detector's weights, measured once on labelled frames: a sidecar JSON next
to the weights (``<weights stem>.noise.json``) that names the weights by sha256 and the centre
refinement (detector/centre.py) by the sha256 of its source: either changing makes the card stale
(ignored, so no floor) until it is measured again (``dockfactory noise-card``).

``detect`` copies both into the detections it writes, and ``solve`` and ``measure`` pass them
to the solver.

Why and how: docs/detector.md, "The noise card".
"""
from __future__ import annotations

import hashlib
import json
import math
from functools import lru_cache
from typing import NamedTuple
from pathlib import Path

from dockfactory.core.io import sha256_file, write_json_atomic
import dockfactory.detector.centre as centre

NOISE_FORMAT = "dockfactory.centre_noise/1"
MAX_CARD_NOISE_PX = 100.0   # px: a larger figure is no detector's (equal to solver.checks.MAX_SIGMA_PX, tested)


@lru_cache(maxsize=1)
def refinement_sha256() -> str:
    """sha256 of the centre refinement's source (detector/centre.py)."""
    return hashlib.sha256(Path(centre.__file__).read_bytes()).hexdigest()


def noise_card_path(weights) -> Path:
    w = Path(weights)
    return w.with_name(w.stem + ".noise.json")


def _card(weights) -> dict | None:
    """The noise card of ``weights`` when it is theirs (their sha256, this centre refinement, the
    format) and valid, else None."""
    card = noise_card_path(weights)
    if not card.is_file():
        return None
    try:
        doc = json.loads(card.read_text())
        value = float(doc["centre_noise_px"])
        ok = (doc.get("format") == NOISE_FORMAT and doc.get("weights_sha256") == sha256_file(weights)
              and doc.get("refinement_sha256") == refinement_sha256())
    except (OSError, ValueError, KeyError, TypeError):
        return None
    return doc if ok and math.isfinite(value) and 0 < value <= MAX_CARD_NOISE_PX else None


class CardFigures(NamedTuple):
    """What a valid noise card says, read once (None where it says nothing): ``centre_noise_px``
    (px per axis), ``section_shift_px`` (x, y) px, ``bias_px`` (x, y) px, ``core_px`` (its robust
    core, px per axis: the noise the camera is known to have at least, solver.refine.scale_with_prior)."""

    centre_noise_px: float | None
    section_shift_px: tuple[float, float] | None
    bias_px: tuple[float, float] | None
    core_px: float | None = None


def card_figures(weights) -> CardFigures:
    """What the noise card of a weights file says, the card read and the weights hashed once.

    Parameters
    ----------
    weights : str or Path
        The weights file; its card is ``<stem>.noise.json`` beside it.

    Returns
    -------
    CardFigures
        ``centre_noise_px`` (px per axis), ``section_shift_px`` and ``bias_px`` ((x, y) px), each
        None without a valid card: none beside the weights, one for other weights or another
        centre refinement, or not a card.

    Raises
    ------
    OSError
        A card beside weights that cannot be read (the weights are hashed to check the card).
    """
    doc = _card(weights)
    if doc is None:
        return CardFigures(None, None, None)
    return CardFigures(float(doc["centre_noise_px"]), _shift_of(doc), _bias_of(doc), _core_of(doc))


def _core_of(doc: dict) -> float | None:
    """The card's robust core (px per axis) when it states a positive finite one, else None."""
    try:
        value = float(doc["robust_px"])
    except (KeyError, TypeError, ValueError):
        return None
    return value if math.isfinite(value) and 0 < value <= MAX_CARD_NOISE_PX else None


def centre_noise_px(weights) -> float | None:
    """The measured centre noise (px, per axis) of ``weights`` (:func:`card_figures`)."""
    return card_figures(weights).centre_noise_px


def centre_bias_px(weights) -> tuple[float, float] | None:
    """The measured mean offset (x, y) px of the weights' refined centres from the exact ones
    (:func:`card_figures`, :func:`_bias_of`)."""
    return card_figures(weights).bias_px


def section_shift_px(weights) -> tuple[float, float] | None:
    """The measured common offset (x, y) px of a section's refined centres in a frame
    (eval.section_shift: what no fit's residuals show; :func:`card_figures`); None also when the
    card did not measure it."""
    return card_figures(weights).section_shift_px


def _bias_of(doc: dict) -> tuple[float, float] | None:
    """The detection-weighted mean of a card's per-condition ``mean_px``; None without
    per-condition means (a detector bias that was not measured)."""
    try:
        per = [(int(v["n"]), [float(x) for x in v["mean_px"]]) for v in doc.get("by_condition", {}).values()
               if v.get("mean_px") is not None and v.get("n")]
    except (KeyError, TypeError, ValueError, AttributeError):
        return None
    n = sum(k for k, _ in per)
    if not n or not all(len(m) == 2 and all(math.isfinite(x) for x in m) for _, m in per):
        return None
    return (sum(k * m[0] for k, m in per) / n, sum(k * m[1] for k, m in per) / n)


def _shift_of(doc: dict) -> tuple[float, float] | None:
    """A card's ``section_shift_px`` when it is two finite px in [0, MAX_CARD_NOISE_PX], else None."""
    try:
        x, y = (float(v) for v in doc["section_shift_px"])
    except (KeyError, TypeError, ValueError):
        return None
    ok = all(math.isfinite(v) and 0 <= v <= MAX_CARD_NOISE_PX for v in (x, y))
    return (x, y) if ok else None


def write_noise_card(weights, centre_noise: float, details: dict) -> Path:
    """Write the noise card of a weights file, ``<weights stem>.noise.json``, atomically.

    Parameters
    ----------
    weights : str or Path
        The weights measured (named in the card by their sha256, with the centre refinement's).
    centre_noise : float
        The measured centre noise, px per axis.
    details : dict
        How, where and on how many detections it was measured (stored as given, JSON-able).

    Returns
    -------
    Path
        The card written.

    Raises
    ------
    ValueError
        A centre noise that is not a finite number above 0.
    OSError
        The weights cannot be read or the card cannot be written (an older card keeps its bytes).
    """
    if not (math.isfinite(centre_noise) and centre_noise > 0):
        raise ValueError(f"centre noise must be a finite number of pixels > 0, got {centre_noise}")
    card = noise_card_path(weights)
    write_json_atomic(card, {"format": NOISE_FORMAT, "weights": Path(weights).name,
                             "weights_sha256": sha256_file(weights), "refinement_sha256": refinement_sha256(),
                             "centre_noise_px": float(centre_noise),
                             **details})
    return card
