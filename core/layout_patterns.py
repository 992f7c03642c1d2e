"""Irregular marker patterns of a given size: the layouts a design question compares (pure).

A pattern is ``n`` (s_mm, phi_deg) pairs as in :mod:`core.layout`: axial offset from the seam and
angle on the circumference. The shipped default (seven per section) is the pattern of size 7, so a
design at seven markers is the shipped layout. Other sizes are drawn from an explicit seed: the
angles spread evenly over the default's span (+-``SPAN_DEG``: the depth spread that pins each
section's rotation about its axis, see core.layout) with a jitter, the axial offsets irregular
within the default's band; a draw is kept only when :func:`core.layout.layout_problems` finds
nothing (no overlap at the widest disc asked for, no symmetry), else the next seed is tried.

Why not a regular grid: the solver identifies markers by their distance signatures, which a
regular pattern repeats.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from dockfactory.core.errors import DockfactoryError
from dockfactory.core.layout import (
    DEFAULT_LAYOUT_A,
    DEFAULT_LAYOUT_B,
    build_layout,
    layout_problems,
)

SPAN_DEG = 60.0                 # angles within +-SPAN_DEG of the camera side
AXIAL_MM = (45.0, 160.0)        # axial offsets from the seam (the default's band)
MIN_MARKERS, MAX_MARKERS = 6, 16
MAX_TRIES = 200

__all__ = ["pattern_pair", "MIN_MARKERS", "MAX_MARKERS"]


def _draw(n: int, rng: np.random.Generator) -> tuple[tuple[float, float], ...]:
    """One candidate pattern of ``n`` markers (module docstring)."""
    step = 2 * SPAN_DEG / n
    phi = -SPAN_DEG + step * (np.arange(n) + 0.5) + rng.uniform(-0.3, 0.3, n) * step
    s = rng.uniform(*AXIAL_MM, n)
    return tuple((round(float(a), 1), round(float(b), 1)) for a, b in zip(s, phi))


def pattern_pair(n: int, radius_mm: float, diameter_mm: float, seed: int = 0):
    """(pattern_a, pattern_b) of ``n`` markers each for sections of ``radius_mm`` carrying discs
    of ``diameter_mm``: the shipped default for n = 7, else the first clean draw from ``seed``
    (module docstring). DockfactoryError (one line) for n outside [MIN_MARKERS, MAX_MARKERS] or
    when no clean pattern is found (discs too large for n on this band). Cached (a pure function
    of its arguments: the designs of a space share their patterns; the tuples are immutable)."""
    if not (isinstance(n, int) and MIN_MARKERS <= n <= MAX_MARKERS):
        raise DockfactoryError(f"markers per section must be an integer in [{MIN_MARKERS}, {MAX_MARKERS}], "
                               f"got {n!r}")
    pair = _pattern_pair(n, float(radius_mm), float(diameter_mm), int(seed))
    if pair is None:
        raise DockfactoryError(f"no irregular pattern of {n} markers of {diameter_mm:g} mm fits the band "
                               f"{AXIAL_MM[0]:g}-{AXIAL_MM[1]:g} mm x +-{SPAN_DEG:g} deg on radius {radius_mm:g} mm")
    return pair


@lru_cache(maxsize=256)
def _pattern_pair(n: int, radius_mm: float, diameter_mm: float, seed: int):
    """:func:`pattern_pair` of checked arguments; None when no clean pattern is found (cached too:
    an infeasible design of a space is asked again by its neighbours)."""
    if n == len(DEFAULT_LAYOUT_A) and not layout_problems(
            build_layout(DEFAULT_LAYOUT_A, DEFAULT_LAYOUT_B, radius_mm, diameter_mm)):
        return DEFAULT_LAYOUT_A, DEFAULT_LAYOUT_B
    rng = np.random.default_rng([seed, n])
    for _ in range(MAX_TRIES):
        a, b = _draw(n, rng), _draw(n, rng)
        if not layout_problems(build_layout(a, b, radius_mm, diameter_mm)):
            return a, b
    return None
