"""Sensor presets: Sony Pregius global-shutter colour sensors in EMVA 1288 terms, from published
figures (cited beside each preset), for :mod:`dockfactory.core.camera_chain.emva`.

Every preset is at 12 ADC bits (``emva.with_adc_bits`` moves it) and at the camera's base gain.
Where the sources found give a figure only indirectly, the comment shows the derivation; where
they give none, the comment says what was assumed and why. The colour quantum efficiencies come
from the monochrome versions' figures (the red and blue ratios assumed).

Nothing here is downloaded or read at run time.

Why and how: docs/colour_cameras.md, "The sensor presets' figures".
"""
from __future__ import annotations

from dataclasses import replace

from dockfactory.core.camera_chain.emva import FIELD_NAMES, EmvaSensor
from dockfactory.core.errors import DockfactoryError

IR_CUT_TRANSMITTANCE = 0.93   # Basler's example value at 545 nm (source in the module docstring)
RED_OVER_GREEN, BLUE_OVER_GREEN = 0.80, 0.85   # assumed peak ratios of the Bayer filters


def _colour_qe(mono_qe: float) -> tuple[float, float, float]:
    """(R, G, B) peak QE of the colour version from the monochrome peak QE (see module doc)."""
    green = mono_qe * IR_CUT_TRANSMITTANCE
    return (round(green * RED_OVER_GREEN, 4), round(green, 4), round(green * BLUE_OVER_GREEN, 4))


PRESETS: dict[str, EmvaSensor] = {
    # Sony IMX174 (Pregius 1st generation, 5.86 um pixel; e.g. Basler acA1920-155uc, FLIR
    # Grasshopper3 GS3-U3-23S6C). Source: F. Herb, "Sony Exmor Sensoren: Datenblattrekonstruktion
    # IMX157", fhotolab.fherb.de, 7 September 2016, quoting the IMX174 EMVA 1288 figures published by
    # Point Grey (monochrome camera): saturation capacity 32 691 e-, temporal dark noise 6.83 e-,
    # QE 77 % at 525 nm, gain 0.51 (e-/ADU; read here as Point Grey's 16-bit-normalised ADU, i.e.
    # 0.51 * 16 = 8.16 e-/DN at 12 bits, K = 0.1225 DN/e-, which puts saturation at 4006 of 4095
    # -- an interpretation, the unit is not stated). Cross-check: MATRIX VISION mvBlueFOX3-2024a
    # technical documentation (IMX249, the same pixel at a lower frame rate), "measured accord. to
    # EMVA1288 with gray scale version": SNR 45.1 dB -> 32 359 e-, DNR 73 dB -> about 6.3 e-.
    # Assumed (no published figure found): dark current 10 e-/s (at the exposures of this project,
    # at most tens of ms, it adds well under 1 e-), DSNU 2 e- (0.25 DN), PRNU 0.5 %, black level
    # 64 DN (a user setting; chosen to keep noise around zero off the bottom code).
    "imx174": EmvaSensor(quantum_efficiency=_colour_qe(0.77), dark_noise_e=6.83,
                         saturation_e=32691.0, gain_dn_per_e=0.1225, dark_current_e_per_s=10.0,
                         dsnu_dn=0.25, prnu_pct=0.5, adc_bits=12, black_level_dn=64.0),
    # Sony IMX250 (Pregius 2nd generation, 3.45 um pixel; e.g. FLIR Blackfly S BFS-U3-51S5C, Basler
    # acA2440-75uc; the IMX264 is the same pixel at a lower frame rate). Source: MATRIX VISION
    # (Balluff), mvBlueFOX3 technical documentation, "mvBlueFOX3-2051 / BF3-5M-0024Z (5.1 Mpix)",
    # sensor table, "measured accord. to EMVA1288 with gray scale version of the camera": SNRmax
    # 40.3 dB -> saturation 10 715 e-; DNR 71.2 dB -> temporal dark noise 2.32 e- (derivation in
    # the module docstring, with the K below). Cross-check: Teledyne DALSA Genie Nano C2450 / M2450
    # manual (IMX250), full well 10.7 ke- in the standard design. QE: Basler, "About EMVA1288
    # Reports for Color Sensors" (docs.baslerweb.com knowledge base) quotes 70 % at 545 nm for the
    # acA4112-30uc, whose IMX304 has the same 2nd-generation 3.45 um pixel; used here as the
    # monochrome peak. Assumed: K = 0.37 DN/e- (saturation at 3965 of 4095; no system gain found),
    # dark current 5 e-/s, DSNU 2 e- (0.74 DN), PRNU 0.5 %, black level 64 DN.
    "imx250": EmvaSensor(quantum_efficiency=_colour_qe(0.70), dark_noise_e=2.32,
                         saturation_e=10715.0, gain_dn_per_e=0.37, dark_current_e_per_s=5.0,
                         dsnu_dn=0.74, prnu_pct=0.5, adc_bits=12, black_level_dn=64.0),
    # Sony IMX273 (Pregius 2nd generation, 3.45 um pixel, 1456 x 1088; e.g. Basler acA1440-220uc,
    # FLIR Blackfly S BFS-U3-16S2C). Source: Balluff / MATRIX VISION, BVS CA-SF technical
    # documentation, "mvBlueFOX3-2016 / [BVS CA-SF2|BVS CA-SF5|BF3-5M]-0016Z (1.6 Mpix)", sensor
    # table, "measured accord. to EMVA1288 with gray scale version of the camera": SNRmax 40.2 dB
    # -> saturation 10 471 e-; DNR 71.4 dB -> temporal dark noise 2.19 e- (with the K below). QE
    # as for the IMX250 (same pixel generation, Basler knowledge base figure). Assumed: K = 0.38
    # DN/e- (saturation at 3979 of 4095), dark current 5 e-/s, DSNU 2 e- (0.76 DN), PRNU 0.5 %,
    # black level 64 DN.
    "imx273": EmvaSensor(quantum_efficiency=_colour_qe(0.70), dark_noise_e=2.19,
                         saturation_e=10471.0, gain_dn_per_e=0.38, dark_current_e_per_s=5.0,
                         dsnu_dn=0.76, prnu_pct=0.5, adc_bits=12, black_level_dn=64.0),
}

for _name, _sensor in PRESETS.items():
    _sensor.validate(f"sensor preset {_name!r}")

def preset(name: str) -> EmvaSensor:
    """The preset called ``name`` (lower case, as in :data:`PRESETS`). DockfactoryError (a
    ValueError) naming the unknown name and listing the known ones."""
    if not isinstance(name, str) or name not in PRESETS:
        raise DockfactoryError(f"unknown sensor preset {name!r}; known presets: "
                               f"{', '.join(sorted(PRESETS))}")
    return PRESETS[name]


def with_overrides(sensor: EmvaSensor, overrides: dict,
                   where: str = "sensor overrides") -> EmvaSensor:
    """``sensor`` with the fields named in ``overrides`` replaced, validated. A list for
    ``quantum_efficiency`` is turned into a tuple. DockfactoryError (a ValueError) naming the key
    for an unknown field, or naming the field and value for one out of range (see
    ``EmvaSensor.validate``); ``where`` prefixes the message."""
    if not isinstance(overrides, dict):
        raise DockfactoryError(f"{where}: overrides must be a dict of field: value, got "
                               f"{type(overrides).__name__}")
    unknown = [k for k in overrides if k not in FIELD_NAMES]
    if unknown:
        raise DockfactoryError(f"{where}: unknown sensor field {unknown[0]!r}; fields: "
                               f"{', '.join(FIELD_NAMES)}")
    values = dict(overrides)
    if isinstance(values.get("quantum_efficiency"), list):
        values["quantum_efficiency"] = tuple(values["quantum_efficiency"])
    return replace(sensor, **values).validate(where)
