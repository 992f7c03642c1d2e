"""The statistic a pose gate states its thresholds in: one owner for everything a statistic means.

Each entry of :data:`STATISTICS` owns, for a ``[localization]`` or ``[estimation]`` gate
(eval.acceptance): its name, unit and label; its value of a component's signed errors
(``value``) and of its repeated estimates about each static pose (``spread``, or a ``refusal``
of the block); its one-sided confidence bounds (``bounds``, ``spread_bounds``: the record
``metrics["bounds"]`` keeps; ``own_bounds`` reads it in the statistic's units); its conversion to
and from the RMS under the zero-mean Gaussian model (``to_rms``, ``from_rms``) that the frame
planner, the envelope, the design ranking, conformity and the report's tolerances use; and its
planning (``frames_to_decide``, ``pass_probability``, ``reject_probability``). Consumers ask this
module and branch on no statistic's name: adding a statistic is an entry here and its test.

Why and how: docs/acceptance.md.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dockfactory.eval.confidence import (
    chi2_pass_probability,
    chi2_reject_probability,
    frames_to_decide,
    pooled_spread_bounds,
    rmse_bounds,
)

__all__ = ["GateStatistic", "PowerOfRms", "STATISTICS", "SUMMARY", "gate_statistic", "error_values",
           "spread_values", "statistics_of", "summary_fields"]

BLOCKS = ("localization", "estimation")


@dataclass(frozen=True)
class GateStatistic:
    """A gate's statistic (module docstring): ``name`` as a spec writes it, ``label`` as a table
    heads it. Subclasses define every method; this base names the contracts."""
    name: str
    label: str
    bounds_text = ""   # how its bounds are computed, for a report's sentence "bounds by ..."

    def unit(self, base: str) -> str:
        """The statistic's unit for a component in ``base`` ("mm", "deg")."""
        raise NotImplementedError

    def header(self) -> str:
        """A table's column header: the label, with the unit's power when it is not the base's."""
        unit = self.unit("unit")
        return self.label if unit == "unit" else f"{self.label} ({unit})"

    def refusal(self, block: str) -> str:
        """Why the statistic cannot gate ``block`` ("localization", "estimation"); "" when it can."""
        return ""

    def value(self, errors) -> float | None:
        """The statistic of signed errors ``errors`` (n,) (mm or deg) in its units; None for none."""
        raise NotImplementedError

    def spread(self, groups) -> float | None:
        """The statistic of the spread of repeated estimates about each static pose's mean:
        ``groups`` a list of (n_i,) arrays of one component's estimates per pose (poses with fewer
        than 2 left out); None without a degree of freedom. ValueError when :meth:`refusal` refuses
        estimation."""
        raise NotImplementedError

    def bounds(self, errors, confidence: float, seed: int) -> dict:
        """The one-sided ``confidence`` bounds of the statistic of ``errors`` (n,): a record with at
        least "lower", "upper" (None where none exists), "lower_by", "upper_by" (the methods), in
        the scale :meth:`own_bounds` reads; "note" may say why a bound is missing. Bootstrap
        resamples from default_rng(seed) where a method resamples."""
        raise NotImplementedError

    def spread_bounds(self, groups, confidence: float, seed: int) -> dict:
        """:meth:`bounds` of :meth:`spread` of ``groups`` (the same contract)."""
        raise NotImplementedError

    def own_bounds(self, record: dict) -> tuple[float, float]:
        """(lower, upper) of a :meth:`bounds` record with both bounds, in the statistic's units."""
        raise NotImplementedError

    def to_rms(self, value: float) -> float:
        """The RMS (mm, deg) of a statistic ``value`` (a threshold, a measured value) under the
        zero-mean Gaussian error model."""
        raise NotImplementedError

    def from_rms(self, rms):
        """The statistic of an RMS ``rms`` (mm, deg; a float or an array) under that model."""
        raise NotImplementedError

    def frames_to_decide(self, rms: float, threshold_rms: float, dof: int, confidence: float,
                         limit: int = 100_000) -> int | None:
        """Frames (degrees of freedom) at which the statistic's bound would decide a criterion whose
        true RMS is ``rms`` against a threshold of RMS ``threshold_rms`` (the upper bound within it
        when rms < threshold_rms, the lower bound beyond it otherwise), searched from ``dof``; None
        when no count up to ``limit`` does (rms at the threshold)."""
        raise NotImplementedError

    def pass_probability(self, rms: float, threshold_rms: float, dof: int, confidence: float) -> float:
        """P(the guarded rule proves the criterion passes) with ``dof`` degrees of freedom (frames)
        of errors of true RMS ``rms`` against a threshold of RMS ``threshold_rms``."""
        raise NotImplementedError

    def reject_probability(self, rms: float, threshold_rms: float, dof: int, confidence: float) -> float:
        """P(the guarded rule proves the criterion fails) (as :meth:`pass_probability`)."""
        raise NotImplementedError


@dataclass(frozen=True)
class PowerOfRms(GateStatistic):
    """The RMS to the ``power``: 1 the RMSE (mm, deg), 2 the MSE (mm^2, deg^2). Errors: the RMS
    about zero (a bias counts as error); spread: sqrt(sum of squared deviations from each pose's
    mean / sum(n_i - 1)). Bounds: eval.confidence (chi-square under a Gaussian model and a
    bootstrap, the cautious pair deciding), kept as bounds of the RMS; planning: the chi-square
    bound (eval.confidence.frames_to_decide)."""
    power: int = 1
    bounds_text = ("chi-square under a Gaussian error model and by a studentized bootstrap, the more cautious one "
                   "deciding")

    def unit(self, base: str) -> str:
        return base if self.power == 1 else f"{base}^{self.power}"

    def _of_mean_square(self, ms: float) -> float:
        """The statistic of a mean square."""
        return math.sqrt(ms) if self.power == 1 else ms if self.power == 2 else ms ** (self.power / 2)

    def value(self, errors) -> float | None:
        e = np.asarray(errors, dtype=float)
        return None if e.size == 0 else self._of_mean_square(float(np.mean(e ** 2)))

    def spread(self, groups) -> float | None:
        groups = [np.asarray(g, dtype=float) for g in groups if len(g) >= 2]
        dof = sum(len(g) - 1 for g in groups)
        if not dof:
            return None
        return self._of_mean_square(sum(float(((g - g.mean()) ** 2).sum()) for g in groups) / dof)

    def bounds(self, errors, confidence: float, seed: int) -> dict:
        return rmse_bounds(errors, confidence, seed)

    def spread_bounds(self, groups, confidence: float, seed: int) -> dict:
        return pooled_spread_bounds(groups, confidence, seed)

    def own_bounds(self, record: dict) -> tuple[float, float]:
        return record["lower"] ** self.power, record["upper"] ** self.power

    def to_rms(self, value: float) -> float:
        return float(value) if self.power == 1 else math.sqrt(value) if self.power == 2 else value ** (1 / self.power)

    def from_rms(self, rms):
        return rms if self.power == 1 else rms ** self.power

    def frames_to_decide(self, rms, threshold_rms, dof, confidence, limit=100_000):
        return frames_to_decide(rms, threshold_rms, dof, confidence, limit)

    def pass_probability(self, rms, threshold_rms, dof, confidence):
        return chi2_pass_probability(rms, threshold_rms, dof, confidence)

    def reject_probability(self, rms, threshold_rms, dof, confidence):
        return chi2_reject_probability(rms, threshold_rms, dof, confidence)


STATISTICS: dict[str, GateStatistic] = {
    "rmse": PowerOfRms("rmse", "RMSE", 1),
    "mse": PowerOfRms("mse", "MSE", 2),
}

# The fields of an error summary (eval.pose_metrics.error_stats) in the order metrics.json and the
# report's statistics tables give them: the statistics' values among the errors' own moments (n,
# mean, std, p95 and max of |e|); a statistic not named here follows them.
SUMMARY = ("n", "mse", "rmse", "mean", "std", "p95", "max")


def gate_statistic(name: str) -> GateStatistic:
    """The statistic called ``name``; ValueError naming the known ones."""
    try:
        return STATISTICS[name]
    except (KeyError, TypeError):
        raise ValueError(f"{name!r} is not one of {', '.join(STATISTICS)}") from None


def statistics_of(block: str) -> list[str]:
    """The names of the statistics that can gate ``block`` ("localization", "estimation")."""
    if block not in BLOCKS:
        raise ValueError(f"{block!r} is not one of {', '.join(BLOCKS)}")
    return [name for name, s in STATISTICS.items() if not s.refusal(block)]


def summary_fields() -> tuple[str, ...]:
    """An error summary's fields in order: :data:`SUMMARY`, then any statistic it does not name."""
    return SUMMARY + tuple(name for name in STATISTICS if name not in SUMMARY)


def error_values(errors) -> dict[str, float | None]:
    """{name: value} of every statistic of signed errors ``errors`` (n,) (None each for none)."""
    return {name: s.value(errors) for name, s in STATISTICS.items()}


def spread_values(groups) -> dict[str, float | None]:
    """{name: spread} of every statistic that can gate estimation, of ``groups`` (a list of (n_i,)
    arrays of one component's estimates per static pose; None each without a degree of freedom)."""
    return {name: STATISTICS[name].spread(groups) for name in statistics_of("estimation")}
