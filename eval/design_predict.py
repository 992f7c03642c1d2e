"""Predicted pose errors of a design, computed in milliseconds: the solver's own covariance model evaluated
at the true geometry of the design's pose distribution, with the centre noise its camera class is
known to have.

The scale, offset and factors come from the predictor's card (eval.design_card): fitted on
renders, with the error it showed on renders it was not fitted on.

Why and how: docs/design.md, "Predicting a design".
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dockfactory.core.config import config_from_dict
from dockfactory.core.errors import DockfactoryError
from dockfactory.core.layout_patterns import pattern_pair
from dockfactory.core.names import COMPONENTS
from dockfactory.eval.design_noise import CentreNoiseLaw, disc_minor_px, over_weights, size_factors
from dockfactory.eval.design_space import Design, DesignSpace, jpeg_quality
from dockfactory.generator.random_draws import static_scene
from dockfactory.eval.frame_cameras import cameras_of_test_frames
from dockfactory.eval.pixel_aspect import delivered_ellipses, square_pixel_covariances, square_pixel_shift
from dockfactory.solver.disc_noise import disc_ellipses, noise_shapes, section_noise_shapes
from dockfactory.solver.refine import (
    d_from_b_jacobian,
    inverse_spd,
    joint_jacobian,
    residuals_and_jacobian,
)
from dockfactory.solver.section_shift import section_shift_covariance

__all__ = ["NoiseClass", "design_config", "frame_variances", "predict_design", "mean_variances", "Prediction",
           "square_pixel_noise_shapes"]


@dataclass(frozen=True)
class NoiseClass:
    """The centre noise of one design's camera class: disc-model scale (px per axis at
    REFERENCE_RADIUS_PX), section offset (px per axis), the law the centres' noise follows
    (eval.design_noise; None: the solver's own weights, solver.disc_noise.noise_shapes) and the
    class's size exponent (eval.design_noise.size_factors: 0, the law's shape; above 0, the
    class's noise and offset grow faster as the discs shrink)."""
    scale_px: float
    shift_px: tuple[float, float]
    law: CentreNoiseLaw | None = None
    size_exponent: float = 0.0


@dataclass(frozen=True)
class Prediction:
    """``rmse`` and ``repeat`` {component: mm or deg}; ``frames`` pose draws used;
    ``minor_median_px`` the median minor semi-axis (px) of the markers' disc images over them."""
    rmse: dict
    repeat: dict
    frames: int
    minor_median_px: float | None = None


def design_config(scene_cfg, design: Design, space: DesignSpace, frames: int, repeat=(1, 2)):
    """The dataset config of ``design`` in the space's scene: its image size, fixed focal,
    working distance, markers (core.layout_patterns), CFA, sensor preset and JPEG; ``frames``
    test frames in normal light, ``repeat`` (poses, captures). ConfigError (one line) when the
    design cannot be rendered (e.g. its markers do not fit)."""
    d = scene_cfg.resolved_dict()
    f = design.focal_px
    pa, pb = pattern_pair(design.markers_per_section, scene_cfg.sections.radius_mm,
                          design.marker_diameter_mm, space.seed)
    q = jpeg_quality(design.image_format)
    d["dataset"].update(name="design", frames=frames, train_fraction=0.0, val_fraction=0.0)
    d["conditions"] = {"normal": 1.0, "low_light": 0.0, "occlusion": 0.0, "glare": 0.0, "ideal": 0.0}
    d["repeatability"].update(poses=repeat[0], captures=repeat[1])
    d["image"] = {"width": design.camera.width, "height": design.camera.height}
    d["camera"].update(distance_mm=list(design.distance_mm), focal_px=[f, f])
    d["camera_units"].update(calibration="", jpeg=q is not None, jpeg_quality=[q or 90, q or 90])
    d["markers"].update(diameter_mm=design.marker_diameter_mm, ring=design.ring,
                        layout_a=[list(p) for p in pa], layout_b=[list(p) for p in pb])
    d["sensor"].update(cfa=[design.camera.cfa.upper() if design.camera.cfa != "none" else "none"],
                       presets=[design.camera.preset] if design.camera.preset else [])
    return config_from_dict(d, f"{space.source}: design {design.label()}")


def _section_jac(markers, cam, focal, pp):
    pts = np.array([m.center_mm for m in markers], dtype=np.float64)
    _, jac, z = residuals_and_jacobian(pts, np.zeros((len(pts), 2)), pp, cam[:3, :3], cam[:3, 3], focal)
    if np.any(z <= 0):
        raise DockfactoryError("a marker is behind the camera")
    return jac


def square_pixel_noise_shapes(markers, cam_from_s, focal: float, pixel_aspect: float = 1.0):
    """(m, 2, 2): the disc model's noise shapes (solver.disc_noise.noise_shapes) of ``markers`` (one
    section's, seen by ``cam_from_s`` (4, 4)) in the square-pixel pinhole at fx = ``focal``: the
    shapes of their discs' delivered images (fy = ``pixel_aspect`` fx:
    eval.pixel_aspect.delivered_ellipses) taken there (S^-1 T S^-1), as the judge's bound takes
    delivered noise (eval.pixel_aspect.crb_delivered).
    solver.disc_noise.section_noise_shapes itself for ``pixel_aspect`` 1."""
    if pixel_aspect == 1.0 or len(markers) == 0:
        return section_noise_shapes(markers, cam_from_s, focal)
    cam = np.asarray(cam_from_s, dtype=np.float64)
    centres = np.array([m.center_mm for m in markers]) @ cam[:3, :3].T + cam[:3, 3]
    normals = np.array([m.normal for m in markers]) @ cam[:3, :3].T
    ellipses = disc_ellipses(centres, normals, [m.diameter_mm for m in markers], focal)
    return square_pixel_covariances(noise_shapes(delivered_ellipses(ellipses, pixel_aspect)), pixel_aspect)


def _weighted_fit_covariance(jw: np.ndarray, ratio: np.ndarray) -> np.ndarray:
    """(p, p) covariance in units of scale^2 of the fit weighted by the solver's noise shapes
    (``jw``: (2m, p) Jacobian whitened by them) when marker i's true variance is ``ratio[i]`` (m,)
    times its weight: H J_w^T R J_w H, H = (J_w^T J_w)^-1, R the ratios per axis; H itself when all
    ratios are 1."""
    h = inverse_spd(jw.T @ jw)
    if np.all(ratio == 1.0):
        return h
    return h @ (jw.T * np.repeat(ratio, 2)) @ jw @ h


def _shift_size_factor(ma, mb, cam_a, cam_b, focal: float, exponent: float) -> float:
    """The section offset's factor in a frame for a class of size ``exponent``: the RMS of the
    markers' eval.design_noise.size_factors (the offset comes from the same sampling as the
    noise); 1 at exponent 0."""
    if exponent == 0.0:
        return 1.0
    minor = np.r_[disc_minor_px(ma, cam_a, focal)[0], disc_minor_px(mb, cam_b, focal)[0]]
    return float(np.sqrt(np.mean(size_factors(minor, exponent) ** 2)))


def frame_variances(markers, cam_a, cam_b, focal: float, pp, noise: NoiseClass, pixel_aspect: float = 1.0):
    """(noise (6,), offset (6,)) variances of d_from_b (POSE_NAMES order, mm^2 / deg^2) of one
    frame: the covariance of the fit weighted by the disc noise (as the solver's robust refit
    weighs the centres, solver.disc_noise.robust_refit: scale^2 (J^T T^-1 J)^-1 when the centres'
    noise is the solver's weights, the sandwich of :func:`_weighted_fit_covariance` under
    ``noise.law`` and the class's size factors) and what the section offset adds to that weighted
    fit (the offset times :func:`_shift_size_factor`). A camera
    with non-square pixels (``pixel_aspect`` = fy / fx, ``focal`` = fx): the fit in the square-pixel
    pinhole at fx about ``pp``, the noise the delivered discs show taken there
    (:func:`square_pixel_noise_shapes`) and the offset likewise (eval.pixel_aspect); 1: square."""
    ma = [m for m in markers if m.section == "A"]
    mb = [m for m in markers if m.section == "B"]
    jac = joint_jacobian(_section_jac(ma, cam_a, focal, pp), _section_jac(mb, cam_b, focal, pp))
    shapes = np.concatenate([square_pixel_noise_shapes(ma, cam_a, focal, pixel_aspect),
                             square_pixel_noise_shapes(mb, cam_b, focal, pixel_aspect)])
    sqrt_w = np.linalg.inv(np.linalg.cholesky(shapes))
    jw = np.einsum("nab,nbp->nap", sqrt_w, jac.reshape(-1, 2, jac.shape[1])).reshape(jac.shape)
    k = noise.size_exponent
    cov_noise = noise.scale_px ** 2 * _weighted_fit_covariance(
        jw, np.r_[over_weights(ma, cam_a, focal, noise.law, k), over_weights(mb, cam_b, focal, noise.law, k)])
    groups = np.r_[np.zeros(len(ma), int), np.ones(len(mb), int)]
    shift = np.asarray(square_pixel_shift(noise.shift_px, pixel_aspect), dtype=np.float64) * _shift_size_factor(
        ma, mb, cam_a, cam_b, focal, k)
    cov_shift = section_shift_covariance(jac, groups, shift, sqrt_w)
    prop = d_from_b_jacobian(cam_a[:3, :3], cam_a[:3, 3], cam_b[:3, :3], cam_b[:3, 3])
    return (np.diag(prop @ cov_noise[:12, :12] @ prop.T), np.diag(prop @ cov_shift[:12, :12] @ prop.T))


def drawn_frames(cfg, max_frames: int) -> tuple[list, list]:
    """(markers, the first ``max_frames`` test frames' cameras) of ``cfg``: what a prediction
    averages over, drawn once. ConfigError when a frame cannot fit its markers."""
    return static_scene(cfg).markers, cameras_of_test_frames(cfg, max_frames, "design")


def mean_variances(cfg, noise: NoiseClass, max_frames: int, drawn=None):
    """(noise (6,), offset (6,), frames): :func:`frame_variances` averaged over the first
    ``max_frames`` test frames of ``cfg`` (each at its camera's pixel aspect; ``drawn``: their
    :func:`drawn_frames` when already drawn). ConfigError / DockfactoryError when a frame cannot be
    drawn (the markers do not fit the image) or its geometry is degenerate."""
    markers, frames = drawn or drawn_frames(cfg, max_frames)
    parts = [frame_variances(markers, f.cam_from_a, f.cam_from_b, f.focal_px, f.principal_point, noise,
                             f.pixel_aspect) for f in frames]
    vn, vs = np.mean(parts, axis=0)
    if not (np.all(np.isfinite(vn)) and np.all(np.isfinite(vs))):
        raise DockfactoryError("the pose is not observable from these markers (degenerate geometry)")
    return vn, vs, len(frames)


def median_minor_px(cfg, max_frames: int, drawn=None) -> float:
    """The median minor semi-axis (px) of every marker's disc image over the first ``max_frames``
    test frames of ``cfg`` (square-pixel pinhole at each frame's focal; ``drawn`` as in
    :func:`mean_variances`): the disc size a centre-noise figure measured on other scenes is
    carried to. Errors as :func:`mean_variances`."""
    markers, frames = drawn or drawn_frames(cfg, max_frames)
    ma = [m for m in markers if m.section == "A"]
    mb = [m for m in markers if m.section == "B"]
    minor = [np.r_[disc_minor_px(ma, f.cam_from_a, f.focal_px)[0], disc_minor_px(mb, f.cam_from_b, f.focal_px)[0]]
             for f in frames]
    return float(np.median(np.concatenate(minor)))


def predict_design(cfg, noise: NoiseClass, bound_factor: dict, max_frames: int) -> Prediction:
    """Predicted RMSE and repeatability (module docstring) over the first ``max_frames`` test
    frames of ``cfg`` (a :func:`design_config`), with their discs' :func:`median_minor_px`; errors
    as :func:`mean_variances`."""
    drawn = drawn_frames(cfg, max_frames)
    vn, vs, n = mean_variances(cfg, noise, max_frames, drawn)
    rmse = {c: bound_factor[c] * math.sqrt(vn[i] + vs[i]) for i, c in enumerate(COMPONENTS)}
    repeat = {c: bound_factor[c] * math.sqrt(vn[i]) for i, c in enumerate(COMPONENTS)}
    return Prediction(rmse, repeat, n, median_minor_px(cfg, max_frames, drawn))
