"""Which camera model the data support: forward selection over nested models.

Why and how: docs/solver.md, "Model choice".
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dockfactory.solver.camera_models import PINHOLE, IntrinsicsModel
from dockfactory.solver.options import DEFAULT_MODEL_CHOICE, ModelChoiceOptions
from dockfactory.solver.stats import chi2_logsf, f_logsf

__all__ = ["ModelFitSummary", "ModelTest", "ModelChoice", "choose_model"]


@dataclass(frozen=True)
class ModelFitSummary:
    """What the choice needs of one model's fit: ``cost`` (sum of squared residuals, px^2),
    ``n_residuals``, ``n_params``, ``extra_std`` (e,) standard deviations of the model's free
    extras (order ``model.free``), ``ok`` (valid, converged, focal observable) and the reason
    when it is not."""

    model: IntrinsicsModel
    cost: float
    n_residuals: int
    n_params: int
    extra_std: np.ndarray
    ok: bool = True
    failure: str = ""


@dataclass(frozen=True)
class ModelTest:
    """One candidate tested ``against`` the current model: the statistic (chi-square or F),
    ``log_p`` (natural log of its p-value), ``std_fraction`` (largest std / prior half-range
    of the added parameters), ``accepted`` and, when not, ``reason``."""

    model: str
    against: str
    statistic: float
    log_p: float
    std_fraction: float
    accepted: bool
    reason: str = ""


@dataclass(frozen=True)
class ModelChoice:
    """The chosen model's name and every test made, in order."""

    chosen: str
    tests: tuple


def _test(cand: ModelFitSummary, cur: ModelFitSummary, sigma_px, options, others=()) -> ModelTest:
    """Test ``cand`` against the nested ``cur`` (see the module docstring)."""
    name, against = cand.model.name, cur.model.name
    if not cand.ok:
        return ModelTest(name, against, math.nan, 0.0, math.inf, False, cand.failure)
    added = [k for k, n in enumerate(cand.model.free) if n not in cur.model.free]
    fracs = [cand.extra_std[k] / options.prior(cand.model.free[k]) for k in added]
    frac = float(max(fracs)) if all(np.isfinite(fracs)) else math.inf
    inflation = max((_std_inflation(cand, s) for s in others if s.ok and cand.model.nests(s.model)),
                    default=(1.0, ""))
    q = cand.n_params - cur.n_params
    drop = max(cur.cost - cand.cost, 0.0)
    if sigma_px is not None:
        stat = drop / float(sigma_px) ** 2
        log_p = chi2_logsf(stat, q)
    else:
        dof = cand.n_residuals - cand.n_params
        if dof < options.min_residual_dof:
            return ModelTest(name, against, math.nan, 0.0, frac, False,
                             f"{dof} residual degrees of freedom: too few to test")
        stat = (drop / q) / max(cand.cost / dof, 1e-300)
        log_p = f_logsf(stat, q, dof)
    if not frac <= options.max_std_fraction:
        reason = f"not determined (std / plausible range {frac:.3g})"
    elif not inflation[0] <= options.max_std_inflation:
        reason = f"confounded with {inflation[1]} (its std grows {inflation[0]:.3g}x)"
    elif not log_p <= math.log(options.lr_alpha):
        reason = f"no significant improvement (p {math.exp(log_p):.3g})"
    else:
        reason = ""
    return ModelTest(name, against, float(stat), float(log_p), frac, not reason, reason)


def _std_inflation(cand: ModelFitSummary, sub: ModelFitSummary) -> tuple[float, str]:
    """(largest factor by which the std of a parameter the nested model ``sub`` frees grows in
    the candidate, that parameter): the candidate's other parameters trade off against it."""
    worst = (1.0, "")
    for j, name in enumerate(sub.model.free):
        before, after = sub.extra_std[j], cand.extra_std[cand.model.free.index(name)]
        if np.isfinite(before) and before > 0 and after / before > worst[0]:
            worst = (float(after / before), name)
    return worst


def choose_model(summaries: dict, sigma_px: float | None,
                 options: ModelChoiceOptions = DEFAULT_MODEL_CHOICE) -> ModelChoice:
    """Forward selection from the pinhole over ``summaries`` (model name -> ModelFitSummary;
    must hold "pinhole"); ``sigma_px`` the known pixel noise, or None (estimated). Returns a
    :class:`ModelChoice`."""
    current = summaries[PINHOLE.name]
    tests = []
    while True:
        trials = [_test(s, current, sigma_px, options, summaries.values()) for s in summaries.values()
                  if s.model.nests(current.model)]
        tests.extend(trials)
        good = [t for t in trials if t.accepted]
        if not good:
            return ModelChoice(current.model.name, tuple(tests))
        best = min(good, key=lambda t: (t.log_p, summaries[t.model].n_params))
        current = summaries[best.model]
