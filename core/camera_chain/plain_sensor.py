"""The plain sensor of the camera chain: a camera without [sensor] presets (pure numpy).

Every pixel sees all three colours (no CFA, no crosstalk). In: the exposure-normalised linear
light ``(H, W, 3) float32`` (1.0 fills the full well). Out: DN at ``adc_bits``, ``(H, W, 3)``
float32 holding integers. ``plain_dn``: electrons (full well at 1.0, clipped), shot noise, read
noise, ADC; shot noise uses the Gaussian approximation N(e, e), accurate above a few electrons.
``ideal_dn``: a noise-free sensor, the light quantised at the ADC's levels. Its ISP is
``isp.display_from_dn``; a colour camera's sensor is ``colour_sensor``.
"""
from __future__ import annotations

import numpy as np

from dockfactory.core.scene import SensorParams


def ideal_dn(light: np.ndarray, adc_bits: int) -> np.ndarray:
    """DN (H, W, 3) float32 of a noise-free sensor: ``light`` (H, W, 3) float32 clipped to [0, 1]
    and rounded to the ADC's 2^``adc_bits`` levels."""
    return np.rint(np.clip(light, 0.0, 1.0) * (2 ** adc_bits - 1))


def plain_dn(light: np.ndarray, p: SensorParams, rng: np.random.Generator) -> np.ndarray:
    """DN (H, W, 3) float32 in [0, 2^adc_bits - 1] of ``light`` (H, W, 3) float32, overwritten:
    electrons = min(light, 1) x ``full_well_e`` plus shot and read noise (``read_noise_e``) drawn
    from ``rng`` (the frame's noise stream), then the ADC (rounded, clipped)."""
    levels = 2 ** p.adc_bits
    electrons = np.clip(light, 0.0, 1.0, out=light)
    electrons *= np.float32(p.full_well_e)
    sigma = np.sqrt(electrons + np.float32(p.read_noise_e ** 2))
    sigma *= rng.standard_normal(electrons.shape, dtype=np.float32)
    electrons += sigma
    electrons *= np.float32((levels - 1) / p.full_well_e)
    return np.clip(np.rint(electrons, out=electrons), 0, levels - 1, out=electrons)
