"""bench/sensor/disc_noise_law.py's law fit: errors drawn from a known law (isotropic, variance
(10 / b)^p + floor) give back its constants whatever each input's own scale, and the errors are
taken about their section's mean.

Tolerances: 12000 draws per input, two inputs of different scales; the fit must land within one
grid step of p (0.25) and on the floor's grid neighbour."""
from __future__ import annotations

import numpy as np
import pytest

from bench.sensor import disc_noise_law as dnl


def draws(rng, p: float, floor: float, n: int, scale: float) -> np.ndarray:
    """(n, 3) rows (b, ex, ey) of Gaussian errors under the law, noise scale ``scale`` px."""
    b = rng.uniform(2.0, 20.0, n)
    sd = scale * np.sqrt(dnl.law_variance(b, p, floor))
    return np.stack([b, sd * rng.normal(size=n), sd * rng.normal(size=n)], 1)


@pytest.mark.parametrize("p, floor", [(2.5, 0.5), (1.5, 0.0), (3.5, 2.0)])
def test_the_law_fit_recovers_its_constants(p, floor):
    rng = np.random.default_rng(11)
    data = [draws(rng, p, floor, 12000, s) for s in (0.01, 0.08)]
    got_p, got_floor = dnl.best_law(data)
    k = int(np.flatnonzero(dnl.GRID_FLOOR == floor)[0])
    assert got_p == pytest.approx(p, abs=0.26)
    assert got_floor in dnl.GRID_FLOOR[max(k - 1, 0):k + 2]


def test_errors_are_taken_about_their_sections_mean():
    ms = [{"section": "A", "minor": 5.0, "ex": 1.0 + d, "ey": 2.0} for d in (-0.1, 0.0, 0.1)]
    ms += [{"section": "B", "minor": 6.0, "ex": 0.0, "ey": 0.0}] * 2       # two markers: dropped
    rows = dnl.about_section_means(ms)
    assert rows.shape == (3, 3)
    assert rows[:, 1] == pytest.approx(np.array([-0.1, 0.0, 0.1]) * np.sqrt(1.5))
    assert rows[:, 2] == pytest.approx(np.zeros(3), abs=1e-12)
