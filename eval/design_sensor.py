"""A design's sensor in the predictor: its temporal noise beside the card's reference sensor.

The card's scale is measured through one sensor (the reference preset). Part of the refined
centres' noise is that sensor's temporal noise (shot, dark, quantisation), the rest the render's
and the refinement's own; a sensor with a deeper full well (more electrons at the same exposure)
shows less. The card's ``sensor_noise.share`` per camera class is the reference sensor's part of
the centre variance (fitted on the sensor bench with the sensor's noise turned down:
bench/design/sensor_share.py). A design's centre std is then the card's times
sqrt(1 - share + share x v / v_ref), v the sensor's relative temporal variance at the auto
exposure's grey (:func:`relative_variance`).

Why and how: docs/design.md, "The sensor's noise".
"""
from __future__ import annotations

import math

from dockfactory.core.camera_chain.colour_sensor import configured_sensor

SIGNAL = 0.18   # the auto exposure's mid grey (core.camera_chain.light), a share of the full well

__all__ = ["SIGNAL", "relative_variance", "preset_variance", "camera_variance", "sensor_factor"]


def relative_variance(full_e: float, dark_noise_e: float, gain_dn_per_e: float | None = None) -> float:
    """The temporal variance over the squared signal (dimensionless) of a pixel at ``SIGNAL`` of
    a full well of ``full_e`` electrons (the electrons at exposure-normalised light 1.0): shot
    noise, dark noise ``dark_noise_e`` (e- rms) and, with ``gain_dn_per_e`` (DN per e-), the
    ADC's quantisation (1 / 12 DN^2)."""
    signal = SIGNAL * full_e
    quant = 0.0 if gain_dn_per_e is None else 1.0 / (12.0 * gain_dn_per_e ** 2)
    return (signal + dark_noise_e ** 2 + quant) / signal ** 2


def preset_variance(name: str, overrides=(), adc_bits: int = 12) -> float:
    """:func:`relative_variance` of sensor preset ``name`` (core.sensor_presets) with ``overrides``
    ((key, value) pairs, as [sensor.overrides]) at ``adc_bits``; the green channel's full well
    (the colour chain's normalisation). ValueError naming an unknown preset or key."""
    s = configured_sensor(name, overrides, adc_bits)
    return relative_variance(s.saturation_e, s.dark_noise_e, s.gain_dn_per_e)


def camera_variance(preset: str, sensor_cfg) -> float:
    """:func:`relative_variance` of the sensor a design's renders use: its ``preset`` with the
    scene's [sensor] overrides and ADC depth (``sensor_cfg``: core.config.SensorConfig); without a
    preset the scene's plain sensor, at the middle of its full-well and read-noise ranges."""
    if preset:
        return preset_variance(preset, sensor_cfg.overrides, sensor_cfg.adc_bits)
    full = 0.5 * (sensor_cfg.full_well_e[0] + sensor_cfg.full_well_e[1])
    read = 0.5 * (sensor_cfg.read_noise_e[0] + sensor_cfg.read_noise_e[1])
    return relative_variance(full, read)


def sensor_factor(share: float, ratio: float) -> float:
    """The centre std of a sensor whose relative temporal variance is ``ratio`` times the
    reference's, over the reference's, when the reference sensor's part of the centre variance is
    ``share`` (in [0, 1]): sqrt(1 - share + share x ratio)."""
    return math.sqrt(1.0 - share + share * ratio)
