"""Frames without a pose, predicted per design: the design's own test frames simulated through the
solver and its goodness-of-fit gate.

Each drawn test frame's marker centroids (the discs' projected outlines, as a detector measures
them) get the design's predicted centre noise (the disc model's shapes and law, the class's size
factors and section offset, times the card's ``noise_factor``) and go through the solve and gate of
a rendered frame's detections (eval.solve_frames.solve_frame) with the camera class's options and
the gate's card figures. With a ``tail`` (eps, m) a centre's noise is m times the rest's with
probability eps, its RMS kept at the prediction's: the centres' heavy tail (measured on the sensor
bench: bench/design/centre_tails.py). A class the gate tests at the card's own noise (three-chip
PNG) is not simulated: its honest frames are not refused.

Why and how: docs/design.md, "Ranking designs".
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np

from dockfactory.eval.camera_classes import CAMERA_CLASS_FACTORS, camera_class
from dockfactory.eval.design_noise import over_weights
from dockfactory.eval.design_predict import NoiseClass, drawn_frames, square_pixel_noise_shapes
from dockfactory.eval.design_space import Design, jpeg_quality
from dockfactory.eval.solve_frames import class_options, docking_options, lens_prior_for, solve_frame
from dockfactory.solver.eccentricity import eccentricity_offsets
from dockfactory.solver.synthetic import project

__all__ = ["GateFigures", "design_camera_class", "simulated_no_pose", "tail_scales"]


@dataclass(frozen=True)
class GateFigures:
    """What the gate of a rendered design's solve knows: the detector's noise card (centre noise
    and robust core px per axis, section shift (x, y) px; detector.noise_card), and the factor on
    the design's predicted centre noise the simulation draws with (1: the prediction as it is;
    what other factors gave on the rendered designs: bench/results/design/README.md)."""
    centre_noise_px: float
    core_px: float | None
    section_shift_px: tuple[float, float] | None
    noise_factor: float = 1.0


def design_camera_class(design: Design) -> str:
    """The camera class (eval.camera_classes) of a design's delivered images."""
    cfa = design.camera.cfa if design.camera.cfa != "none" else None
    return camera_class(cfa, jpeg_quality(design.image_format) is not None)


def _section_draw(markers, cam, focal: float, pp, noise: NoiseClass, factor: float, aspect: float):
    """(centroids (m, 2) px, Cholesky factors (m, 2, 2) of their noise) of one section's markers."""
    pts = np.array([m.center_mm for m in markers], dtype=np.float64)
    centroids = project(cam, focal, pp, pts) + eccentricity_offsets(markers, cam, focal, pp)
    shapes = square_pixel_noise_shapes(markers, cam, focal, aspect)
    ratio = over_weights(markers, cam, focal, noise.law, noise.size_exponent)
    return centroids, np.linalg.cholesky((factor * noise.scale_px) ** 2 * ratio[:, None, None] * shapes)


def tail_scales(n: int, tail: tuple[float, float] | None, rng: np.random.Generator) -> np.ndarray:
    """(n,) factors on n centres' noise: m / c with probability eps, else 1 / c, c = sqrt(1 - eps +
    eps m^2) so that their RMS is 1 (a contaminated normal of the same variance); ones without a
    ``tail`` (eps, m)."""
    if tail is None:
        return np.ones(n)
    eps, m = tail
    return np.where(rng.random(n) < eps, m, 1.0) / np.sqrt(1.0 - eps + eps * m * m)


def _noisy_centres(sections, noise: NoiseClass, factor: float, tail, rng: np.random.Generator):
    """(class ids (n,), centres (n, 2)): each section's centroids with their noise (its ``tail``:
    :func:`tail_scales`) and one common offset per section (the class's section shift), as
    detection arrays without boxes."""
    ids, pts = [], []
    for k, (centroids, chol) in enumerate(sections):
        offset = rng.normal(size=2) * np.asarray(noise.shift_px) * factor
        e = np.einsum("nij,nj->ni", chol, rng.normal(size=centroids.shape))
        pts.append(centroids + tail_scales(len(centroids), tail, rng)[:, None] * e + offset)
        ids.append(np.full(len(centroids), k))
    return np.concatenate(ids), np.vstack(pts)


def _seed(design: Design, seed: int) -> int:
    """A seed of the design's label and the space's ``seed``: the same space, the same draws."""
    return int.from_bytes(hashlib.sha256(f"{seed}|{design.label()}".encode()).digest()[:8], "little")


def simulated_no_pose(cfg, design: Design, noise: NoiseClass, gate: GateFigures, frames: int,
                      seed: int, tail: tuple[float, float] | None = None) -> dict:
    """{"camera_class", "simulated" (frames drawn), "refused" (frames without a pose), "rate" (their
    share), "reasons" (first words of each refusal -> count)} of ``design`` (its dataset config
    ``cfg``: eval.design_predict.design_config) over its first ``frames`` test frames, each drawn
    once (module docstring), the centres with ``tail`` (:func:`tail_scales`; None: Gaussian). A
    class the gate tests at the card's noise: nothing simulated, rate 0.
    ConfigError / DockfactoryError as eval.design_predict.drawn_frames."""
    cls = design_camera_class(design)
    out = {"camera_class": cls, "simulated": 0, "refused": 0, "rate": 0.0, "reasons": {}}
    if CAMERA_CLASS_FACTORS[cls] == 1.0:
        return out
    markers, cams = drawn_frames(cfg, frames)
    sections = [[m for m in markers if m.section == s] for s in ("A", "B")]
    options = docking_options(gate.centre_noise_px, lens_prior_for(cfg), gate.section_shift_px, gate.core_px)
    options, class_factor = class_options(options, [cls], True)
    pp = ((cfg.image.width - 1) / 2.0, (cfg.image.height - 1) / 2.0)   # measure's: the image centre
    rng = np.random.default_rng(_seed(design, seed))
    for f in cams:
        drawn = [_section_draw(ms, cam, f.focal_px, f.principal_point, noise, gate.noise_factor, f.pixel_aspect)
                 for ms, cam in zip(sections, (f.cam_from_a, f.cam_from_b))]
        cls_ids, uv = _noisy_centres(drawn, noise, gate.noise_factor, tail, rng)
        record, _ = solve_frame(markers, pp, (cls_ids, uv, None, None), None, "pinhole", options, class_factor)
        out["simulated"] += 1
        if not record.get("ok"):
            out["refused"] += 1
            why = " ".join(str(record.get("reason", "")).split()[:4])
            out["reasons"][why] = out["reasons"].get(why, 0) + 1
    out["rate"] = out["refused"] / out["simulated"]
    return out
