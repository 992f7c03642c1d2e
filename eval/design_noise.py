"""The centre noise a design's markers will show, beside the noise the solver weighs them by.

The solver weighs each refined centre by its disc image's minor semi-axis b alone
(solver.disc_noise.noise_shapes). What the refinement really shows also depends on the factory
marker's dark ring: it is ``RING_EXTRA_MM`` wide whatever the disc, so at the same b a larger disc
has a thinner ring in the image, and the paint beyond it reaches into the band the refinement reads
(docs/design.md, "The ring's width"). :class:`CentreNoiseLaw` is that noise, per axis, in relative
units; the predictor takes its ratio to the solver's weights per marker (:func:`over_weights`).

A camera class may add noise that grows faster than a three-chip camera's as the disc shrinks
(a Bayer camera samples red and blue at every second pixel along each axis: the smaller the disc's
image, the larger the share of its edge that sampling loses): :func:`size_factors`, its std over the law's, per marker
(docs/design.md, "A Bayer camera's cost grows as the disc shrinks").
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dockfactory.core.layout import RING_EXTRA_MM
from dockfactory.solver.disc_noise import REFERENCE_RADIUS_PX, disc_ellipses, noise_shapes

RING_REFERENCE_PX = 1.5   # the ring width (px) at which the ring term is its coefficient

__all__ = ["CentreNoiseLaw", "ring_width_px", "over_weights", "size_factors", "disc_minor_px", "RING_REFERENCE_PX"]


@dataclass(frozen=True)
class CentreNoiseLaw:
    """Relative variance per axis of a refined centre:
    ``(REFERENCE_RADIUS_PX / b)^minor_exponent + floor + ring_coefficient (RING_REFERENCE_PX / w)^ring_exponent``,
    b the disc image's minor semi-axis (px), w the ring's width across it (px, :func:`ring_width_px`).
    Dimensionless: the predictor's card gives the scale (px)."""
    minor_exponent: float
    floor: float
    ring_coefficient: float
    ring_exponent: float

    def variance(self, minor_px, ring_px) -> np.ndarray:
        """(n,) relative variances of discs of minor semi-axes ``minor_px`` and ring widths ``ring_px`` (px)."""
        b = np.asarray(minor_px, dtype=np.float64)
        w = np.asarray(ring_px, dtype=np.float64)
        return ((REFERENCE_RADIUS_PX / b) ** self.minor_exponent + self.floor
                + self.ring_coefficient * (RING_REFERENCE_PX / w) ** self.ring_exponent)


def ring_width_px(minor_px, diameters_mm) -> np.ndarray:
    """(n,) the width (px) of the factory marker's ring across a disc image of minor semi-axis
    ``minor_px`` and disc diameter ``diameters_mm``: b x RING_EXTRA_MM / (d / 2) (the ring is a
    rim RING_EXTRA_MM wide around the disc, imaged at the disc's scale)."""
    return np.asarray(minor_px, dtype=np.float64) * RING_EXTRA_MM / (0.5 * np.asarray(diameters_mm, dtype=np.float64))


def disc_minor_px(markers, cam_from_s, focal_px: float) -> tuple[np.ndarray, np.ndarray]:
    """((m,) minor semi-axes px, (m, 2, 2) disc ellipses) of ``markers`` (core.layout.Marker, one
    section's) seen by ``cam_from_s`` (4, 4) at ``focal_px`` in the square-pixel pinhole."""
    cam = np.asarray(cam_from_s, dtype=np.float64)
    centres = np.array([m.center_mm for m in markers]) @ cam[:3, :3].T + cam[:3, 3]
    normals = np.array([m.normal for m in markers]) @ cam[:3, :3].T
    ellipses = disc_ellipses(centres, normals, [m.diameter_mm for m in markers], focal_px)
    return np.sqrt(np.maximum(np.linalg.eigvalsh(ellipses)[:, 0], 1e-12)), ellipses


def size_factors(minor_px, exponent: float) -> np.ndarray:
    """(n,) a camera class's centre std over the law's for discs of minor semi-axes ``minor_px``
    (px): (REFERENCE_RADIUS_PX / b)^``exponent``; all ones at exponent 0 (the class costs every
    disc the same factor)."""
    b = np.asarray(minor_px, dtype=np.float64)
    return np.ones(b.shape) if exponent == 0.0 else (REFERENCE_RADIUS_PX / b) ** exponent


def over_weights(markers, cam_from_s, focal_px: float, law: CentreNoiseLaw | None,
                 size_exponent: float = 0.0) -> np.ndarray:
    """(m,) for ``markers`` (core.layout.Marker, one section's, seen by ``cam_from_s`` (4, 4) at
    ``focal_px``): the ratio of ``law``'s variance, times the camera class's :func:`size_factors`
    squared at ``size_exponent``, to the solver's weight (the isotropic
    solver.disc_noise.noise_shapes of the same discs); all ones when ``law`` is None and the
    exponent 0 (the solver's weights are the noise). Both are taken of the discs' images in the
    square-pixel pinhole at ``focal_px``, for a camera of non-square pixels too (a ratio of two
    laws of the same discs)."""
    if len(markers) == 0 or (law is None and size_exponent == 0.0):
        return np.ones(len(markers))
    minor, ellipses = disc_minor_px(markers, cam_from_s, focal_px)
    diameters = np.array([m.diameter_mm for m in markers], dtype=np.float64)
    weights = noise_shapes(ellipses)[:, 0, 0]
    law_var = weights if law is None else law.variance(minor, ring_width_px(minor, diameters))
    return law_var * size_factors(minor, size_exponent) ** 2 / weights
