"""The statistic a pose gate states its thresholds in: one owner for its name, unit and conversions.

An acceptance spec's ``[localization]`` and ``[estimation]`` gates (eval.acceptance) state each
threshold in one statistic of the errors (localization) or of the spreads about each static pose
(estimation): ``"rmse"`` (mm, deg) or ``"mse"`` (its square: mm^2, deg^2). Every consumer (the
verdict, its confidence bounds and the frames that would decide it, a single pose's conformity,
the envelope, the frame planner, the design predictor, the report's tolerances) asks this module
for the statistic's unit and for the conversion between the statistic and the RMS the pose
metrics and bounds are computed in, so adding a statistic of that kind is one entry in
:data:`STATISTICS` (and its value in eval.pose_metrics).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["GateStatistic", "STATISTICS", "gate_statistic"]


@dataclass(frozen=True)
class GateStatistic:
    """``name`` as a spec writes it; the statistic is the RMS to the ``power``."""
    name: str
    power: int

    def unit(self, base: str) -> str:
        """The statistic's unit for a component in ``base`` ("mm", "deg")."""
        return base if self.power == 1 else f"{base}^{self.power}"

    def to_rms(self, value: float) -> float:
        """The RMS (mm, deg) of a statistic ``value`` (a threshold, a measured value)."""
        return float(value) if self.power == 1 else math.sqrt(value) if self.power == 2 else value ** (1 / self.power)

    def from_rms(self, rms: float) -> float:
        """The statistic of an RMS (mm, deg)."""
        return rms if self.power == 1 else rms ** self.power


STATISTICS = {"rmse": GateStatistic("rmse", 1), "mse": GateStatistic("mse", 2)}


def gate_statistic(name: str) -> GateStatistic:
    """The statistic called ``name``; ValueError naming the known ones."""
    try:
        return STATISTICS[name]
    except (KeyError, TypeError):
        raise ValueError(f"{name!r} is not one of {', '.join(STATISTICS)}") from None
