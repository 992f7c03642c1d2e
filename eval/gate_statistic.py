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

Why and how: docs/acceptance.md, "Gate statistics".
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from statistics import NormalDist

import numpy as np

from dockfactory.eval.confidence import (
    chi2_pass_probability,
    chi2_reject_probability,
    first_decided,
    frames_to_decide,
    pooled_spread_bounds,
    rmse_bounds,
)

__all__ = ["GateStatistic", "PowerOfRms", "AbsQuantile", "STATISTICS", "order_ranks", "SUMMARY", "gate_statistic", "error_values",
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


def _binomial_pmf(n: int, p: float) -> np.ndarray:
    """P(B = k) for k = 0..n, B ~ Binomial(n, p), 0 <= p <= 1 (log space, normalised; no scipy)."""
    if p <= 0 or p >= 1:
        pmf = np.zeros(n + 1)
        pmf[0 if p <= 0 else n] = 1.0
        return pmf
    k = np.arange(n + 1)
    log_comb = np.concatenate(([0.0], np.cumsum(np.log((n - k[1:] + 1) / k[1:]))))
    log_pmf = log_comb + k * math.log(p) + (n - k) * math.log1p(-p)
    pmf = np.exp(log_pmf - log_pmf.max())
    return pmf / pmf.sum()


@lru_cache(maxsize=4096)
def order_ranks(n: int, q: float, confidence: float) -> tuple[int | None, int | None]:
    """(j, k): the 1-based ranks of the order statistics of ``n`` independent draws of any
    continuous distribution that bound its ``q`` quantile xi at ``confidence``, one-sided each:
    P(X_(j) <= xi) >= confidence (the largest such j) and P(X_(k) >= xi) >= confidence (the
    smallest such k), from the number of draws below xi, Binomial(n, q); None where no rank does
    (k needs 1 - q^n >= confidence)."""
    cdf = np.cumsum(_binomial_pmf(n, q))
    m = int(np.searchsorted(cdf, confidence))                      # first m with P(B <= m) >= c
    upper = m + 1 if m <= n - 1 else None
    m = int(np.searchsorted(cdf, 1 - confidence, side="right")) - 1  # last m with P(B <= m) <= 1 - c
    return (m + 1 if m >= 0 else None), upper


@dataclass(frozen=True)
class AbsQuantile(GateStatistic):
    """The ``percent`` percentile of |e| (mm, deg): localization only.

    Value: numpy's percentile (linear interpolation) of |e| over the errors. Bounds:
    distribution-free, the order statistics of |e| that :func:`order_ranks` names at the
    confidence (method "binomial"; no upper bound under 1 - q^n >= confidence, e.g. 59 frames for
    p95 at 95 %, and the record's note says so: a guarded criterion then fails). RMS: under the
    zero-mean Gaussian model the percentile is z sigma, z = Phi^-1((1 + q) / 2) (1.95996 for p95).
    Planning under that model: P(X_(k) <= T) = P(Binomial(n, P(|e| <= T)) >= k) exactly, and the
    frames that decide put the bound's order statistic at its expected place, the k / (n + 1)
    quantile of |e|.

    Estimation is refused: the deviations of repeated estimates about each pose's mean are
    dependent within a pose (two captures give two equal and opposite deviations), and rescaled by
    sqrt(n_i / (n_i - 1)) they share the errors' distribution only when that is Gaussian, so neither
    the percentile nor a distribution-free bound of it means what it does for the errors."""
    percent: float = 95.0
    bounds_text = "for a percentile of |e|, its order statistics (distribution-free binomial bounds)"

    @property
    def _q(self) -> float:
        return self.percent / 100.0

    @property
    def _z(self) -> float:
        """The percentile of |e| in units of sigma for zero-mean Gaussian errors."""
        return NormalDist().inv_cdf(0.5 + self._q / 2)

    def unit(self, base: str) -> str:
        return base

    def refusal(self, block: str) -> str:
        if block != "estimation":
            return ""
        powers = " or ".join(n for n, s in STATISTICS.items() if isinstance(s, PowerOfRms))
        return (f"a percentile of |e| gates localization only: the deviations about each pose's mean are "
                f"dependent within a pose and not distributed as the errors; gate estimation in {powers}")

    def value(self, errors) -> float | None:
        e = np.asarray(errors, dtype=float)
        return None if e.size == 0 else float(np.percentile(np.abs(e), self.percent))

    def spread(self, groups) -> float | None:
        raise ValueError(f"{self.name}: {self.refusal('estimation')}")

    def spread_bounds(self, groups, confidence: float, seed: int) -> dict:
        raise ValueError(f"{self.name}: {self.refusal('estimation')}")

    def min_frames(self, confidence: float) -> int:
        """The fewest errors whose order statistics bound the percentile from above at ``confidence``."""
        n = max(1, math.ceil(math.log(1 - confidence) / math.log(self._q)) - 1)
        while order_ranks(n, self._q, confidence)[1] is None:
            n += 1
        return n

    def bounds(self, errors, confidence: float, seed: int) -> dict:
        a = np.sort(np.abs(np.asarray(errors, dtype=float)))
        j, k = order_ranks(a.size, self._q, confidence) if a.size else (None, None)
        lower, upper = (float(a[j - 1]) if j else None), (float(a[k - 1]) if k else None)
        out = {"binomial": {"lower": lower, "upper": upper, "lower_rank": j, "upper_rank": k, "n": int(a.size)},
               "lower": lower, "upper": upper, "lower_by": "binomial" if j else None,
               "upper_by": "binomial" if k else None}
        if k is None:
            out["note"] = (f"no {confidence:.0%} upper bound of the {self.label} from {a.size} values: its order "
                           f"statistics give one from {self.min_frames(confidence)}")
        return out

    def own_bounds(self, record: dict) -> tuple[float, float]:
        return record["lower"], record["upper"]

    def to_rms(self, value: float) -> float:
        return float(value) / self._z

    def from_rms(self, rms):
        return rms * self._z

    def _within(self, rms: float, threshold_rms: float) -> float:
        """P(|e| <= the threshold) for zero-mean Gaussian errors of RMS ``rms`` > 0."""
        return math.erf(threshold_rms * self._z / (rms * math.sqrt(2.0)))

    def frames_to_decide(self, rms, threshold_rms, dof, confidence, limit=100_000):
        if rms is None or threshold_rms is None or rms == threshold_rms or dof < 1:
            return None
        half_normal = NormalDist()

        def decided(n: int) -> bool:
            lower, upper = order_ranks(n, self._q, confidence)
            rank = upper if rms < threshold_rms else lower
            if rank is None:
                return False
            expected = rms * half_normal.inv_cdf(0.5 + rank / (n + 1) / 2)
            return expected <= threshold_rms * self._z if rms < threshold_rms else expected > threshold_rms * self._z
        return first_decided(decided, dof, limit)

    def pass_probability(self, rms, threshold_rms, dof, confidence):
        upper = order_ranks(dof, self._q, confidence)[1]
        if upper is None:
            return 0.0
        if rms <= 0:
            return 1.0
        return float(_binomial_pmf(dof, self._within(rms, threshold_rms))[upper:].sum())

    def reject_probability(self, rms, threshold_rms, dof, confidence):
        lower = order_ranks(dof, self._q, confidence)[0]
        if lower is None or rms <= 0:
            return 0.0
        return float(_binomial_pmf(dof, self._within(rms, threshold_rms))[:lower].sum())


STATISTICS: dict[str, GateStatistic] = {
    "rmse": PowerOfRms("rmse", "RMSE", 1),
    "mse": PowerOfRms("mse", "MSE", 2),
    "p95": AbsQuantile("p95", "p95 |e|", 95.0),
}

# The fields of an error summary (eval.pose_metrics.error_stats) in the order metrics.json and the
# report's statistics tables give them: the statistics' values among the errors' own moments (n,
# mean, std and max of |e|); a statistic not named here follows them.
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
