"""Percentiles of an endless stream in constant memory: a histogram of log-spaced bins.

``measure --camera`` runs for days; keeping every frame's latency to take its median at the end
grows without bound. A value v > 0 falls in bin floor(log(v / LOW) / log(1 + REL)), so a
percentile read from the bins is within REL (relative) of the exact one over the range LOW-HIGH
(values outside it are clamped into the end bins; the maximum is kept exactly). Adding is O(1)
and the memory is the fixed bin count (about 2,800 for 1e-3-1e9 at 1 %).
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["LogHistogram"]

LOW, HIGH, REL = 1e-3, 1e9, 0.01


class LogHistogram:
    """Counts of non-negative values in log-spaced bins (zeros in their own bin)."""

    def __init__(self):
        self.bins = np.zeros(int(math.ceil(math.log(HIGH / LOW) / math.log1p(REL))) + 1, dtype=np.int64)
        self.zeros, self.n, self.max = 0, 0, None

    def add(self, value: float) -> None:
        """Count one value (NaN and negatives are refused: ValueError)."""
        v = float(value)
        if not v >= 0.0:
            raise ValueError(f"a histogram value must be >= 0, got {value!r}")
        self.n += 1
        self.max = v if self.max is None else max(self.max, v)
        if v == 0.0:
            self.zeros += 1
            return
        k = int(math.log(min(max(v, LOW), HIGH) / LOW) / math.log1p(REL))
        self.bins[min(k, self.bins.size - 1)] += 1

    def percentile(self, q: float) -> float | None:
        """The q-th percentile (0-100), the geometric centre of its bin (within REL of the exact
        value), the exact maximum at 100; None when empty."""
        if self.n == 0:
            return None
        if q >= 100.0:
            return self.max
        rank = q / 100.0 * (self.n - 1) + 1.0       # 1-based rank of the value (lower of a pair)
        if rank <= self.zeros:
            return 0.0
        k = int(np.searchsorted(np.cumsum(self.bins), rank - self.zeros))
        return min(LOW * (1.0 + REL) ** (k + 0.5), self.max)
