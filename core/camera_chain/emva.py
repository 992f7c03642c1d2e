"""An image sensor described by its EMVA 1288 (release 4.0, linear) parameters, and the standard's
photon transfer method to measure them back.

:func:`expose` takes mean photo-electrons per pixel and returns the raw frame (uint16 DN): PRNU, dark
current, shot noise, the full well, temporal dark noise, system gain, black level, DSNU and the ADC.
All DN figures (``gain_dn_per_e``, ``dsnu_dn``, ``black_level_dn``) are at the sensor's
``adc_bits``; :func:`with_adc_bits` moves them to another depth. Quantum efficiency is carried for
the caller that turns photons into electrons; :func:`expose` takes electrons and never applies it.

Randomness: the fixed patterns come from the camera unit's integer seed (the same seed is the same
unit, bit for bit); every temporal draw comes from the ``numpy.random.Generator`` the caller passes
to :func:`expose`. There is no global random state and no default generator.

Why and how: docs/colour_cameras.md, "The EMVA 1288 sensor".
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from functools import lru_cache

import numpy as np

from dockfactory.core.errors import DockfactoryError

MIN_ADC_BITS, MAX_ADC_BITS = 8, 16
# K * saturation_e + black_level_dn may exceed the ADC's top code by this fraction (then the ADC,
# not the full well, clips the brightest pixels); beyond it the sensor is refused as mistyped.
ADC_OVERRANGE_TOLERANCE = 0.05
MAX_PRNU_PCT = 20.0      # a gain pattern of 1 + 0.2 N(0, 1) would already go negative somewhere
QUANTISATION_VAR_DN2 = 1.0 / 12.0   # variance of uniform rounding to the nearest code, DN^2
MIN_DARK_STD_DN = 0.5    # EMVA 1288: below this temporal dark std the 1/12 correction fails


def _is_real(x) -> bool:
    return not isinstance(x, bool) and isinstance(x, (int, float, np.integer, np.floating))


def _check_number(where: str, name: str, value, *, low: float, low_open: bool = False,
                  high: float | None = None) -> None:
    """Raise DockfactoryError (a ValueError) naming ``name`` unless ``value`` is a finite real
    number >= ``low`` (> when ``low_open``) and <= ``high`` (when given)."""
    if not _is_real(value) or not math.isfinite(value):
        raise DockfactoryError(f"{where}: {name} must be a finite number, got {value!r}")
    if (value <= low) if low_open else (value < low):
        raise DockfactoryError(f"{where}: {name} must be {'>' if low_open else '>='} {low:g}, "
                               f"got {value!r}")
    if high is not None and value > high:
        raise DockfactoryError(f"{where}: {name} must be <= {high:g}, got {value!r}")


@dataclass(frozen=True)
class EmvaSensor:
    """One sensor (camera) at one operating point, in EMVA 1288 terms. Frozen and hashable.

    quantum_efficiency    (R, G, B) quantum efficiency at each colour filter's peak, each in (0, 1]
    dark_noise_e          temporal dark noise sigma_d, electrons (rms), >= 0
    saturation_e          saturation capacity mu_e.sat (the full well), electrons, > 0
    gain_dn_per_e         overall system gain K at ``adc_bits``, DN per electron, > 0
    dark_current_e_per_s  mean dark signal growth, electrons per second, >= 0
    dsnu_dn               dark signal non-uniformity: std of the fixed dark pattern, DN, >= 0
    prnu_pct              photo-response non-uniformity: std of the fixed gain pattern, %, in
                          [0, MAX_PRNU_PCT]
    adc_bits              ADC depth, an int in 8..16; codes are 0 .. 2**adc_bits - 1
    black_level_dn        offset added before quantisation (so noise around zero is not clipped),
                          DN, >= 0 and below the top code

    Construction does not check the values: call :meth:`validate` (the presets do).
    """

    quantum_efficiency: tuple[float, float, float]
    dark_noise_e: float
    saturation_e: float
    gain_dn_per_e: float
    dark_current_e_per_s: float
    dsnu_dn: float
    prnu_pct: float
    adc_bits: int
    black_level_dn: float

    @property
    def max_code(self) -> int:
        """The ADC's top code, 2**adc_bits - 1 (DN)."""
        return (1 << int(self.adc_bits)) - 1

    def validate(self, where: str) -> EmvaSensor:
        """Return ``self`` if every field is in range, else raise DockfactoryError (a ValueError)
        with one line ``"<where>: <field> must be ..., got <value>"`` for the first bad field.
        Checks: finite numbers (no NaN/inf, no bool), QE a 3-tuple each in (0, 1], noise, dark
        current, DSNU, black level >= 0, saturation and K > 0, PRNU <= MAX_PRNU_PCT, adc_bits an int
        in 8..16, black level below the top code, and K * saturation_e + black_level_dn at most
        ADC_OVERRANGE_TOLERANCE above the top code."""
        qe = self.quantum_efficiency
        if not isinstance(qe, tuple) or len(qe) != 3:
            raise DockfactoryError(f"{where}: quantum_efficiency must be a tuple of 3 numbers "
                                   f"(R, G, B), got {qe!r}")
        for channel, value in zip("RGB", qe):
            _check_number(where, f"quantum_efficiency[{channel}]", value, low=0.0, low_open=True,
                          high=1.0)
        for name in ("dark_noise_e", "dark_current_e_per_s", "dsnu_dn"):
            _check_number(where, name, getattr(self, name), low=0.0)
        _check_number(where, "prnu_pct", self.prnu_pct, low=0.0, high=MAX_PRNU_PCT)
        for name in ("saturation_e", "gain_dn_per_e"):
            _check_number(where, name, getattr(self, name), low=0.0, low_open=True)
        bits = self.adc_bits
        if isinstance(bits, bool) or not isinstance(bits, (int, np.integer)) \
                or not MIN_ADC_BITS <= bits <= MAX_ADC_BITS:
            raise DockfactoryError(f"{where}: adc_bits must be an integer in "
                                   f"{MIN_ADC_BITS}..{MAX_ADC_BITS}, got {bits!r}")
        _check_number(where, "black_level_dn", self.black_level_dn, low=0.0,
                      high=self.max_code - 1)
        top = self.gain_dn_per_e * self.saturation_e + self.black_level_dn
        if top > self.max_code * (1.0 + ADC_OVERRANGE_TOLERANCE):
            raise DockfactoryError(
                f"{where}: gain_dn_per_e * saturation_e + black_level_dn must be at most "
                f"{100 * ADC_OVERRANGE_TOLERANCE:g} % above the {bits}-bit top code "
                f"{self.max_code}, got {top:.6g} DN (gain_dn_per_e={self.gain_dn_per_e!r}, "
                f"saturation_e={self.saturation_e!r})")
        return self


FIELD_NAMES = tuple(f.name for f in fields(EmvaSensor))


def _check_sensor(sensor, where: str) -> None:
    """DockfactoryError (a ValueError) unless ``sensor`` is a valid :class:`EmvaSensor`."""
    if not isinstance(sensor, EmvaSensor):
        raise DockfactoryError(f"{where} must be an EmvaSensor, got {type(sensor).__name__}")
    sensor.validate(where)


def with_adc_bits(sensor: EmvaSensor, bits: int) -> EmvaSensor:
    """The same sensor read out at ``bits`` ADC bits: K, DSNU and black level (the DN figures)
    scale by 2**(bits - sensor.adc_bits); electrons, QE and PRNU are unchanged. The result is
    validated (DockfactoryError, a ValueError, for ``bits`` outside 8..16 or not an int)."""
    if isinstance(bits, bool) or not isinstance(bits, (int, np.integer)) \
            or not MIN_ADC_BITS <= bits <= MAX_ADC_BITS:
        raise DockfactoryError(f"adc bits must be an integer in {MIN_ADC_BITS}..{MAX_ADC_BITS}, "
                               f"got {bits!r}")
    scale = 2.0 ** (int(bits) - int(sensor.adc_bits))
    return replace(sensor, adc_bits=int(bits), gain_dn_per_e=sensor.gain_dn_per_e * scale,
                   dsnu_dn=sensor.dsnu_dn * scale,
                   black_level_dn=sensor.black_level_dn * scale).validate(f"sensor at {bits} bits")


@lru_cache(maxsize=4)
def _unit_patterns(seed: int, height: int, width: int) -> tuple[np.ndarray, np.ndarray]:
    """Two independent (height, width) float32 N(0, 1) fields from default_rng(seed): the DSNU
    field is drawn first, the PRNU field second. Read-only, shared."""
    rng = np.random.default_rng(seed)
    dark = rng.standard_normal((height, width), dtype=np.float32)
    gain = rng.standard_normal((height, width), dtype=np.float32)
    dark.flags.writeable = False
    gain.flags.writeable = False
    return dark, gain


def fixed_patterns(sensor: EmvaSensor, seed: int, height: int,
                   width: int) -> tuple[np.ndarray, np.ndarray]:
    """The fixed patterns of one camera unit: ``(dsnu_dn, prnu_gain)``, each (height, width)
    float32, read-only and shared (the last few units are cached on the arguments: copy to
    modify).

    ``dsnu_dn = sensor.dsnu_dn * z1`` (DN at the sensor's ``adc_bits``, mean 0) and
    ``prnu_gain = max(1 + sensor.prnu_pct / 100 * z2, 0)`` (dimensionless, mean 1), with z1, z2
    independent white Gaussian N(0, 1) fields drawn from ``numpy.random.default_rng(seed)`` (z1
    first). White Gaussian patterns are a modelling choice: real DSNU/PRNU also have row/column
    structure and outliers (defect pixels), and the dark-current part of the DSNU grows with the
    exposure time; none of that is modelled (the DSNU here is one offset pattern). The same seed and size give
    the same fields bit for bit, whatever the sensor (a unit keeps its pattern across ADC depths
    and overrides); a different size is a different draw, not a crop. ``seed`` is a non-negative
    int; ``height`` and ``width`` positive ints; ``sensor`` is validated. DockfactoryError (a
    ValueError) otherwise.
    """
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise DockfactoryError(f"fixed pattern seed must be a non-negative integer, got {seed!r}")
    for name, n in (("height", height), ("width", width)):
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
            raise DockfactoryError(f"fixed pattern {name} must be a positive integer, got {n!r}")
    _check_sensor(sensor, "fixed_patterns sensor")
    return _scaled_patterns(sensor, int(seed), int(height), int(width))


@lru_cache(maxsize=4)
def _scaled_patterns(sensor: EmvaSensor, seed: int, height: int,
                     width: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`fixed_patterns` after its checks (the cached part)."""
    z_dark, z_gain = _unit_patterns(seed, height, width)
    dsnu = z_dark * np.float32(sensor.dsnu_dn)
    prnu = z_gain * np.float32(sensor.prnu_pct / 100.0)
    prnu += np.float32(1.0)
    np.maximum(prnu, np.float32(0.0), out=prnu)     # a gain is never negative
    dsnu.flags.writeable = False
    prnu.flags.writeable = False
    return dsnu, prnu


def _check_expose_inputs(electrons_mean, exposure_s, rng, patterns) -> np.ndarray:
    """The validated electron map of :func:`expose` as C-contiguous float32 (a copy only when
    the input is not already that). DockfactoryError (a ValueError) naming the bad argument."""
    if not isinstance(rng, np.random.Generator):
        raise DockfactoryError(f"expose: rng must be a numpy.random.Generator, got "
                               f"{type(rng).__name__}")
    _check_number("expose", "exposure_s", exposure_s, low=0.0)
    e = np.asarray(electrons_mean)
    if e.ndim != 2 or e.size == 0 or not np.issubdtype(e.dtype, np.number) \
            or np.issubdtype(e.dtype, np.complexfloating):
        raise DockfactoryError(f"expose: electrons_mean must be a non-empty real (H, W) array, "
                               f"got shape {e.shape} dtype {e.dtype}")
    e = np.ascontiguousarray(e, dtype=np.float32)
    if not np.isfinite(e).all() or (e < 0).any():
        raise DockfactoryError("expose: electrons_mean must be finite and >= 0 everywhere")
    if not isinstance(patterns, tuple) or len(patterns) != 2 \
            or any(np.shape(p) != e.shape for p in patterns):
        raise DockfactoryError(f"expose: patterns must be the (dsnu_dn, prnu_gain) pair of "
                               f"fixed_patterns for shape {e.shape}")
    return e


NEAR_FULL_WELL_SIGMAS = 6.0   # beyond this many shot-noise sigmas below the full well, clipping is < 1e-9


def _add_temporal_noise(mu: np.ndarray, sensor: EmvaSensor, rng: np.random.Generator) -> None:
    """``mu`` (float32 e-, in place) -> min(mu + sqrt(mu) z1, saturation) + dark_noise z2.

    Away from the full well the clip never acts, and the sum of the two Gaussians is one:
    mu + sqrt(mu + dark_noise^2) z, one draw per pixel (the draws cost most of the stage). The
    pixels within NEAR_FULL_WELL_SIGMAS shot-noise sigmas of the full well take the two steps
    exactly, with their own draws: first one N(0, 1) per pixel (all pixels, row-major), then
    one more per near-full pixel (in row-major order)."""
    sat = np.float32(sensor.saturation_e)
    dark = np.float32(sensor.dark_noise_e)
    z = rng.standard_normal(mu.shape, dtype=np.float32)
    near = mu + np.float32(NEAR_FULL_WELL_SIGMAS) * np.sqrt(mu) >= sat
    if near.any():
        shot = mu[near] + np.sqrt(mu[near]) * z[near]
        clipped = np.minimum(shot, sat) + dark * rng.standard_normal(shot.shape, dtype=np.float32)
    spread = mu + dark * dark
    np.sqrt(spread, out=spread)
    z *= spread
    mu += z
    if near.any():
        mu[near] = clipped


def expose(electrons_mean, sensor: EmvaSensor, exposure_s: float, rng: np.random.Generator,
           patterns: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """One raw frame: (H, W) uint16 DN in [0, 2**sensor.adc_bits - 1].

    ``electrons_mean``: (H, W) real array, the mean photo-electrons each pixel would collect
    during the exposure (photons x QE already applied), finite and >= 0. ``sensor``: validated
    here. ``exposure_s``: exposure time in seconds, >= 0 (it scales the dark current only).
    ``rng``: the numpy Generator of every temporal draw (one (H, W) standard-normal draw, then
    one per pixel near the full well: :func:`_add_temporal_noise`). ``patterns``: ``fixed_patterns(sensor, seed,
    H, W)`` of the camera unit, ``(dsnu_dn, prnu_gain)``.

    Stages (units in brackets): mu = electrons_mean * prnu_gain + dark_current * exposure_s [e-];
    n = mu + sqrt(mu) * N(0, 1) [e-]; n = min(n, saturation_e) [e-]; n += dark_noise_e * N(0, 1)
    [e-] (drawn as one Gaussian away from the full well, where the clip cannot act); y = K * n +
    black_level + dsnu [DN]; rounded to the nearest code and clipped to the ADC range.

    Shot noise is Gaussian N(mu, mu), not Poisson: its mean and variance are exactly the Poisson
    ones (so the photon transfer curve, SNR and the linear response are exact), its shape is not
    (no skew; below a few electrons it is continuous and can dip below zero before the dark noise
    is added; it is not clipped there, which would bias the mean). Chosen for speed: numpy's
    Poisson sampler is several times slower than a float32 normal draw at these frame sizes.
    Saturation clips the electrons at the full well; the ADC clips codes at 0 and the top code.
    DockfactoryError (a ValueError) naming the argument for bad input.
    """
    _check_sensor(sensor, "expose sensor")
    e = _check_expose_inputs(electrons_mean, exposure_s, rng, patterns)
    dsnu, prnu = patterns
    mu = e * prnu                                                        # e-
    mu += np.float32(sensor.dark_current_e_per_s * exposure_s)           # e-
    _add_temporal_noise(mu, sensor, rng)                                 # e-
    mu *= np.float32(sensor.gain_dn_per_e)                               # DN
    mu += dsnu
    mu += np.float32(sensor.black_level_dn)                              # DN
    np.rint(mu, out=mu)
    np.clip(mu, 0.0, float(sensor.max_code), out=mu)
    return mu.astype(np.uint16)


def _frame_pair_stats(a, b) -> tuple[float, float]:
    """Mean (DN) and temporal variance (DN^2) of a pair of frames of one scene: mean of both;
    var(a - b) / 2, the difference's own mean removed (EMVA 1288), so fixed patterns cancel."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    if a.ndim != 2 or a.shape != b.shape or a.size < 2:
        raise DockfactoryError(f"photon_transfer: each pair must be two equal (H, W) frames, got "
                               f"shapes {a.shape} and {b.shape}")
    return 0.5 * (a.mean() + b.mean()), 0.5 * float(np.var(a - b))


def _fit_levels(mean_dn, var_dn2, dark_mean_dn: float, fit_fraction: float,
                saturation_mean_dn) -> np.ndarray:
    """(N,) bool: the levels of :func:`photon_transfer`'s fit, ``0 < mean_dn <= fit_fraction *
    saturation`` (saturation above dark: ``saturation_mean_dn - dark_mean_dn`` when given, else
    the ``mean_dn`` of the largest variance). DockfactoryError if fewer than 2."""
    if saturation_mean_dn is None:
        sat = float(mean_dn[int(np.argmax(var_dn2))])
    else:
        _check_number("photon_transfer", "saturation_mean_dn", saturation_mean_dn, low=0.0)
        sat = float(saturation_mean_dn) - dark_mean_dn
    in_fit = (mean_dn > 0) & (mean_dn <= fit_fraction * sat)
    if in_fit.sum() < 2:
        raise DockfactoryError(f"photon_transfer: fewer than 2 levels between 0 and "
                               f"{fit_fraction:g} of saturation ({sat:.6g} DN above dark)")
    return in_fit


def photon_transfer(pairs, *, fit_fraction: float = 0.7,
                    saturation_mean_dn: float | None = None) -> dict:
    """EMVA 1288 photon transfer method: system gain K and temporal dark noise from frame pairs.

    ``pairs``: a sequence of ``(frame_a, frame_b, dark_a, dark_b)``, one per illumination level,
    each frame an (H, W) array in DN (all four of one level the same shape): two frames of a flat
    field and two dark frames at the same exposure. Per level: ``mean_dn = mu_y - mu_y.dark`` (the
    means of both frames) and ``var_dn2 = sigma_y^2 - sigma_y.dark^2`` with each temporal variance
    ``var(a - b) / 2`` (fixed patterns cancel in the difference).

    K (DN/e-) is the slope of a least-squares line through the origin of ``var_dn2`` against
    ``mean_dn`` over the levels with ``0 < mean_dn <= fit_fraction * saturation``, where
    saturation is ``saturation_mean_dn - mean dark level`` if given (DN) and otherwise, as in the
    standard, the ``mean_dn`` of the level of largest variance. Dark noise (electrons):
    ``sqrt(sigma_y.dark^2 - 1/12) / K`` with sigma_y.dark^2 the mean of the levels' dark
    variances (the dark pairs are taken to share one exposure time) and 1/12 DN^2 the
    quantisation noise; 0 when the dark variance is below 1/12. That correction needs a dark
    noise of at least about half a code: below MIN_DARK_STD_DN (the standard's 0.5 DN) rounding
    hides the noise and ``dark_noise_resolved`` is False (measure at a higher gain or depth).

    Returns ``{"K": float DN/e-, "dark_noise_e": float e-, "dark_var_dn2": float DN^2,
    "dark_noise_resolved": bool, "mean_dn": (N,) float64, "var_dn2": (N,) float64, "in_fit": (N,)
    bool}``, levels in the order given. DockfactoryError (a ValueError) for fewer than 2 levels,
    bad shapes, fewer than 2 levels in the fit range, or a slope that is not positive.
    """
    pairs = list(pairs)
    if len(pairs) < 2 or any(len(p) != 4 for p in pairs):
        raise DockfactoryError("photon_transfer: need at least 2 levels of "
                               "(frame_a, frame_b, dark_a, dark_b)")
    _check_number("photon_transfer", "fit_fraction", fit_fraction, low=0.0, low_open=True,
                  high=1.0)
    stats = np.array([_frame_pair_stats(a, b) + _frame_pair_stats(da, db)
                      for a, b, da, db in pairs])
    mean_dn, var_dn2 = stats[:, 0] - stats[:, 2], stats[:, 1] - stats[:, 3]
    dark_var = float(stats[:, 3].mean())
    in_fit = _fit_levels(mean_dn, var_dn2, float(stats[:, 2].mean()), fit_fraction,
                         saturation_mean_dn)
    x, y = mean_dn[in_fit], var_dn2[in_fit]
    k = float(np.dot(x, y) / np.dot(x, x))
    if not k > 0:
        raise DockfactoryError(f"photon_transfer: the fitted system gain is not positive, got {k}")
    dark_noise = math.sqrt(max(dark_var - QUANTISATION_VAR_DN2, 0.0)) / k
    return {"K": k, "dark_noise_e": dark_noise, "dark_var_dn2": dark_var,
            "dark_noise_resolved": bool(dark_var >= MIN_DARK_STD_DN ** 2), "mean_dn": mean_dn,
            "var_dn2": var_dn2, "in_fit": in_fit}
