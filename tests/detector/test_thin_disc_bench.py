"""bench/sensor/thin_disc_noise.py's law fit: z_minor^2 drawn from a known thin-disc law gives back its
constants, and the normalisation takes out the input's own noise scale."""
from __future__ import annotations

import numpy as np
import pytest

from bench.sensor import thin_disc_noise as tdn


def draws(rng, big_r: float, p: float, n: int, scale: float) -> np.ndarray:
    """(n, 3) rows (r, z_minor^2, z_major^2) of Gaussian errors under the law, noise scale ``scale``."""
    r = rng.uniform(1.5, 20.0, n)
    f = 1.0 + (big_r / r) ** p
    return np.stack([r, scale * f * rng.normal(size=n) ** 2, scale * rng.normal(size=n) ** 2], 1)


def test_the_law_fit_recovers_its_constants():
    """20000 draws per input at the shipped law (R 4.75, P 1.5) and at R 3, P 2.5, each with two
    different noise scales: the pooled fit is within one grid step of R and P (0.25 each)."""
    rng = np.random.default_rng(7)
    for true_r, true_p in ((tdn.THIN_DISC_RATIO, tdn.THIN_DISC_POWER), (3.0, 2.5)):
        data = [tdn.normalised(draws(rng, true_r, true_p, 20000, s)) for s in (0.003, 0.02)]
        big_r, p = tdn.best_law(data)
        assert big_r == pytest.approx(true_r, abs=0.26) and p == pytest.approx(true_p, abs=0.26)


def test_normalisation_divides_by_the_major_axis_scale():
    rows = np.array([[2.0, 4.0, 1.0], [3.0, 2.0, 3.0]])
    assert tdn.normalised(rows) == pytest.approx(np.array([[2.0, 2.0], [3.0, 1.0]]))
