"""Camera models beyond the pinhole on residual blocks: refine from a pinhole fit, covariance,
and the automatic choice.

Layer 3 of the solver (estimators), beside :mod:`solver.joint`: it takes residual blocks
(:class:`solver.refine.Block`), poses and intrinsics that a pinhole estimate started, refines
them with the one LM (:func:`solver.refine.refine_blocks`) for the requested camera model, and
reports the covariance sigma^2 (J^T J)^-1 from the same Jacobian. ``"auto"`` fits every model
from the same pinhole start and keeps the one :func:`solver.model_choice.choose_model` supports.
Used per frame (two blocks: :class:`solver.joint.JointFitter`) and per docking run (2F blocks:
:mod:`solver.sequence`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dockfactory.solver.camera_models import (
    AUTO,
    EXTRA_NAMES,
    MODELS,
    PINHOLE,
    IntrinsicsModel,
    Intrinsics,
    camera_model,
)
from dockfactory.solver.errors import FocalNotObservable, SolverError
from dockfactory.solver.model_choice import ModelChoice, ModelFitSummary, choose_model
from dockfactory.solver.options import (
    DEFAULT_MODEL_CHOICE,
    ModelChoiceOptions,
    RefineOptions,
)
from dockfactory.solver.refine import (
    DEFAULT_REFINE,
    BlocksRefineResult,
    covariance_from_jacobian,
    refine_blocks,
    rel_focal_std,
)

__all__ = ["ModelFit", "refine_model", "fit_camera_model", "check_model_focal"]


@dataclass(frozen=True)
class ModelFit:
    """A refinement (:class:`solver.refine.BlocksRefineResult`) with its ``covariance``
    (6 P + 1 + e square, parameter order of :func:`solver.refine.refine_blocks`), the noise
    ``sigma_px`` used for it, and the automatic ``choice`` that selected it (or None)."""

    refinement: BlocksRefineResult
    covariance: np.ndarray
    sigma_px: float
    choice: ModelChoice | None = None

    @property
    def model(self) -> IntrinsicsModel:
        return self.refinement.model

    @property
    def intrinsics(self) -> Intrinsics:
        return self.refinement.intrinsics

    @property
    def poses(self) -> tuple:
        return self.refinement.poses

    @property
    def focal_index(self) -> int:
        return self.refinement.focal_index

    def intrinsics_std(self) -> dict:
        """{"focal_px": std, "cx": ..., "p2": ...}: standard deviations of the estimated
        intrinsics; 0.0 for the ones the model keeps fixed (given, not estimated)."""
        i0 = self.focal_index
        var = np.diag(self.covariance)[i0:]
        out = {"focal_px": float(np.sqrt(var[0])) if var[0] >= 0 else float("inf")}
        for name in EXTRA_NAMES:
            out[name] = 0.0
        for k, name in enumerate(self.model.free, start=1):
            out[name] = float(np.sqrt(var[k])) if var[k] >= 0 else float("inf")
        return out

    def summary(self, options: RefineOptions) -> ModelFitSummary:
        """What :func:`solver.model_choice.choose_model` needs of this fit."""
        ref = self.refinement
        e = self.model.n_extra
        var = np.diag(self.covariance)[self.focal_index + 1:]
        std = np.where(np.isfinite(var) & (var >= 0), np.sqrt(np.abs(var)), np.inf)
        rel = rel_focal_std(self.covariance, self.intrinsics.focal_px, self.focal_index)
        failure = "" if ref.converged else "refinement did not converge"
        if not rel <= options.max_joint_focal_rel_std:
            failure = f"focal not observable (relative std {rel:.3g})"
        return ModelFitSummary(self.model, ref.cost, ref.residuals.size,
                               ref.jacobian.shape[1], std.reshape(e), not failure, failure)


def refine_model(blocks, poses, intr: Intrinsics, model: IntrinsicsModel, sigma_px,
                 options: RefineOptions = DEFAULT_REFINE) -> ModelFit:
    """One LM for ``model`` from ``poses`` and ``intr``, with its covariance (``sigma_px``
    None: estimated from the residuals)."""
    ref = refine_blocks(blocks, poses, intr, model, options)
    cov, sigma = covariance_from_jacobian(ref.jacobian, ref.residuals, sigma_px, options.sigma_floor_px)
    return ModelFit(ref, cov, sigma)


def check_model_focal(fit: ModelFit, options: RefineOptions) -> None:
    """FocalNotObservable when the fit's focal ran off (``max_joint_focal_rel_std``)."""
    rel = rel_focal_std(fit.covariance, fit.intrinsics.focal_px, fit.focal_index)
    if not rel <= options.max_joint_focal_rel_std:
        raise FocalNotObservable(f"focal length is not observable from these points (relative "
                                 f"std {rel:.3g}, camera model {fit.model.name}); the pose "
                                 "cannot be trusted")


def fit_camera_model(blocks, pinhole: ModelFit, model_name: str, sigma_px,
                     options: RefineOptions = DEFAULT_REFINE,
                     choice_options: ModelChoiceOptions = DEFAULT_MODEL_CHOICE) -> ModelFit:
    """The fit of ``model_name`` (a model name or "auto") started from a ``pinhole`` fit of the
    same blocks. A named model is refined once (its SolverError propagates); "auto" refines
    every model from the pinhole start and returns the chosen one (``choice`` set)."""
    if model_name != AUTO:
        model = camera_model(model_name)
        if model is PINHOLE:
            return pinhole
        return refine_model(blocks, pinhole.poses, pinhole.intrinsics, model, sigma_px, options)
    fits = {PINHOLE.name: pinhole}
    summaries = {PINHOLE.name: pinhole.summary(options)}
    for name, model in MODELS.items():
        if model is PINHOLE:
            continue
        try:
            fits[name] = refine_model(blocks, pinhole.poses, pinhole.intrinsics, model,
                                      sigma_px, options)
            summaries[name] = fits[name].summary(options)
        except SolverError as exc:
            summaries[name] = ModelFitSummary(model, np.inf, 0, 0, np.full(model.n_extra,
                                                                          np.inf), False,
                                              str(exc))
    choice = choose_model(summaries, sigma_px, choice_options)
    best = fits[choice.chosen]
    return ModelFit(best.refinement, best.covariance, best.sigma_px, choice)
