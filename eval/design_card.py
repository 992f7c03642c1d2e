"""The design predictor's card: the centre-noise figures a prediction uses, what they were fitted
on and the error they showed (written by bench/design/design_fit.py; models/design_predictor.json).

A factor listed in ``provisional`` is reported beside every design that uses it.

Why and how: docs/design.md, "The predictor's card".
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, replace
from pathlib import Path

from dockfactory.core.errors import DockfactoryError
from dockfactory.core.names import COMPONENTS
from dockfactory.eval.design_noise import CentreNoiseLaw
from dockfactory.eval.design_predict import NoiseClass
from dockfactory.eval.design_refusals import GateFigures
from dockfactory.eval.design_sensor import preset_variance, sensor_factor
from dockfactory.eval.design_space import Design, jpeg_quality

CARD_FORMAT = "dockfactory.design_predictor/5"
REFUSALS_FORMAT = "dockfactory.design_refusals/1"
RING_JPEG_FORMAT = "dockfactory.design_predictor/4"  # no size exponent per camera class: 0 for every class
CFA_JPEG_FORMAT = "dockfactory.design_predictor/3"   # one JPEG factor per camera class, whatever the ring
NO_LAW_FORMAT = "dockfactory.design_predictor/2"     # no centre_noise: the centres' noise is the solver's weights
OLD_FORMATS = ("dockfactory.design_predictor/1",)   # fitted under an earlier centre-noise model: refit
LAW_KEYS = ("minor_exponent", "floor", "ring_coefficient", "ring_exponent")

__all__ = ["DesignCard", "load_design_card", "with_refusals", "CARD_FORMAT", "REFUSALS_FORMAT"]


@dataclass(frozen=True)
class DesignCard:
    path: str
    scale_px: float
    shift_px: tuple[float, float]
    cfa_factor: dict
    ring_factor: dict
    jpeg_factor: dict
    jpeg_min_quality: int
    bound_factor: dict
    provisional: tuple[str, ...]
    data: dict
    law: CentreNoiseLaw | None = None
    size_exponent: dict | None = None
    jpeg_above: dict | None = None
    sensor_share: dict | None = None
    sensor_reference: str = ""
    no_pose: dict | None = None
    no_pose_gate: GateFigures | None = None
    no_pose_tail: dict | None = None

    @property
    def disc_range_px(self) -> tuple[float, float] | None:
        """(low, high) px: the median disc minor semi-axes of the scenes the card was fitted on
        (``fitted_on.disc_minor_median_px``), None when the card does not say."""
        r = self.data.get("fitted_on", {}).get("disc_minor_median_px")
        ok = isinstance(r, list) and len(r) == 2 and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in r)
        return (float(min(r)), float(max(r))) if ok else None

    def outside_range(self, minor_median_px: float | None) -> str:
        """"" when a design whose discs' median minor semi-axis is ``minor_median_px`` (px) lies
        within :attr:`disc_range_px` (or either is unknown), else the line saying its figures are
        carried beyond the discs they were measured on."""
        r = self.disc_range_px
        if r is None or minor_median_px is None or r[0] <= minor_median_px <= r[1]:
            return ""
        return f"extrapolated: median disc b {minor_median_px:.1f} px, the card's scenes {r[0]:.1f}-{r[1]:.1f} px"

    def sensor_factor_of(self, design: Design, variance: float | None) -> float:
        """The design's centre std over the card's for a sensor of relative temporal variance
        ``variance`` (eval.design_sensor.camera_variance): 1.0 when the card has no
        ``sensor_noise`` or ``variance`` is None (the card's reference sensor assumed). Behind a
        JPEG of the card's factor J only the PNG part of the variance follows the sensor (the
        encoding's centre error is the same with the sensor's noise at a third or a hundredth:
        bench/results/design/README.md): sqrt(J^2 - 1 + f^2) / J, f the PNG design's factor."""
        if not self.sensor_share or variance is None:
            return 1.0
        f = sensor_factor(self.sensor_share[design.camera.cfa], variance / preset_variance(self.sensor_reference))
        q = jpeg_quality(design.image_format)
        if q is None or q < self.jpeg_min_quality:
            return f
        j = self.jpeg_of(q)[0][design.ring][design.camera.cfa]
        return math.sqrt(j * j - 1.0 + f * f) / j

    def jpeg_of(self, quality: int) -> tuple[dict, str]:
        """({ring: {cfa: factor}}, its key's name) for a JPEG of ``quality``: the table measured at
        the highest quality at or below it (``jpeg_factor`` at ``jpeg_min_quality``,
        ``jpeg_factor_above`` above it): a JPEG's noise falls as its quality rises, so a quality
        between two measured ones takes the noisier figure."""
        table, name = self.jpeg_factor, "jpeg_factor"
        for q in sorted(self.jpeg_above or {}):
            if quality >= q:
                table, name = self.jpeg_above[q], f"jpeg_factor_above.{q}"
        return table, name

    def no_pose_rate_of(self, design: Design) -> tuple[float, str]:
        """(share of honest frames without a pose, the card's key) for ``design``'s camera class
        and image format (``no_pose_rate``: "png", or "jpegQ" at the highest Q at or below the
        design's quality, a JPEG's refusals growing as its quality falls); (0.0, "") when the card
        has no such table: frames without a pose are then not predicted."""
        if not self.no_pose:
            return 0.0, ""
        key = _format_key(self.no_pose, design)
        if key not in self.no_pose:
            return 0.0, ""
        return self.no_pose[key][design.camera.cfa], f"no_pose_rate.{key}.{design.camera.cfa}"

    def tail_of(self, design: Design) -> tuple[float, float] | None:
        """(eps, m) of the centres' tail ``no_pose_simulation.tail`` gives ``design``'s camera class
        and image format ("png", or "jpegQ" at the highest Q at or below the design's quality, as
        :meth:`no_pose_rate_of`); None when the card has none for it (Gaussian centres)."""
        if not self.no_pose_tail:
            return None
        return self.no_pose_tail.get(_format_key(self.no_pose_tail, design), {}).get(design.camera.cfa)

    def noise_of(self, design: Design, sensor_variance: float | None = None) -> tuple[NoiseClass | None, list[str], str]:
        """(noise class, provisional factors used, reason) of ``design`` whose sensor's relative
        temporal variance is ``sensor_variance`` (None: the card's reference sensor): the class
        None with the reason when the card has no figure for it."""
        q = jpeg_quality(design.image_format)
        if q is not None and q < self.jpeg_min_quality:
            return None, [], f"the predictor's card has no JPEG figure below quality {self.jpeg_min_quality}"
        g = self.cfa_factor[design.camera.cfa] * self.ring_factor[design.ring][design.camera.cfa]
        used = [f"cfa_factor.{design.camera.cfa}", f"ring_factor.{design.ring}.{design.camera.cfa}"]
        if q is not None:
            table, name = self.jpeg_of(q)
            g *= table[design.ring][design.camera.cfa]
            used.append(f"{name}.{design.ring}.{design.camera.cfa}")
        k = (self.size_exponent or {}).get(design.camera.cfa, 0.0)
        g *= self.sensor_factor_of(design, sensor_variance)
        noise = NoiseClass(self.scale_px * g, (self.shift_px[0] * g, self.shift_px[1] * g), self.law, k)
        return noise, [u for u in used if u in self.provisional], ""


def _format_key(table: dict, design: Design) -> str:
    """The key of a table by image format ("png" | "jpegQ") that holds ``design``: "png", or the
    "jpegQ" of the highest Q at or below the design's quality (a JPEG's figures grow as its
    quality falls); "" when there is none."""
    q = jpeg_quality(design.image_format)
    return "png" if q is None else max((k for k in table if k != "png" and int(k[4:]) <= q),
                                       key=lambda k: int(k[4:]), default="")


def _positive(path, key, value, zero: bool = False) -> float:
    """``value`` as a float when it is a finite number above 0 (at or above 0 with ``zero``: an
    offset the fit found absent), else DockfactoryError naming the card and the key."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
            or value < 0 or (value == 0 and not zero):
        raise DockfactoryError(f"{path}: {key}: expected a {'non-negative' if zero else 'positive'} number, got {value!r}")
    return float(value)


def _factors(path, data, key, names, where: str = "", zero: bool = False) -> dict:
    table = data.get(key)
    name = f"{where}{key}"
    if not isinstance(table, dict) or set(table) != set(names):
        raise DockfactoryError(f"{path}: {name}: expected a table of {', '.join(names)}, got {table!r}")
    return {n: _positive(path, f"{name}.{n}", table[n], zero) for n in names}


def _law(path, data: dict) -> CentreNoiseLaw | None:
    """The card's ``centre_noise`` (format /3: each of LAW_KEYS a number >= 0), None for a /2 card."""
    if data.get("format") == NO_LAW_FORMAT:
        return None
    table = data.get("centre_noise")
    if not isinstance(table, dict) or set(table) != set(LAW_KEYS):
        raise DockfactoryError(f"{path}: centre_noise: expected a table of {', '.join(LAW_KEYS)}, got {table!r}")
    values = {}
    for k in LAW_KEYS:
        v = table[k]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0:
            raise DockfactoryError(f"{path}: centre_noise.{k}: expected a number >= 0, got {v!r}")
        values[k] = float(v)
    return CentreNoiseLaw(**values)


def _rings(path, table, key: str = "ring_factor") -> dict:
    """{ring: {cfa: factor}} of the card's ``key`` table (dark, white; each none, rggb)."""
    if not isinstance(table, dict) or set(table) != {"dark", "white"}:
        raise DockfactoryError(f"{path}: {key}: expected a table of dark, white, got {table!r}")
    return {ring: _factors(path, table, ring, ("none", "rggb"), f"{key}.") for ring in ("dark", "white")}


def _jpeg(path, data: dict) -> dict:
    """{ring: {cfa: factor}} of the card's ``jpeg_factor``: per ring and camera class (formats /4 and
    /5); a card of an earlier format has one factor per camera class, which is taken for both rings."""
    if data.get("format") in (CARD_FORMAT, RING_JPEG_FORMAT):
        return _rings(path, data.get("jpeg_factor"), "jpeg_factor")
    per_cfa = _factors(path, data, "jpeg_factor", ("none", "rggb"))
    return {ring: dict(per_cfa) for ring in ("dark", "white")}


def _size_exponents(path, data: dict) -> dict:
    """{cfa: exponent >= 0} of the card's ``cfa_size_exponent`` (format /5); zeros for an earlier
    format (one factor for every disc)."""
    if data.get("format") != CARD_FORMAT:
        return {"none": 0.0, "rggb": 0.0}
    return _factors(path, data, "cfa_size_exponent", ("none", "rggb"), zero=True)


def _jpeg_above(path, data: dict, min_quality: int) -> dict:
    """{quality: {ring: {cfa: factor}}} of the card's optional ``jpeg_factor_above`` (format /5):
    each key an integer quality above ``min_quality`` and at most 100, each value a table as
    ``jpeg_factor``; empty when absent."""
    table = data.get("jpeg_factor_above", {}) if data.get("format") == CARD_FORMAT else {}
    if not isinstance(table, dict):
        raise DockfactoryError(f"{path}: jpeg_factor_above: expected a table of qualities, got {table!r}")
    out = {}
    for key, rings in table.items():
        if not (key.isdigit() and min_quality < int(key) <= 100):
            raise DockfactoryError(f"{path}: jpeg_factor_above.{key}: expected an integer quality in "
                                   f"{min_quality + 1}-100")
        out[int(key)] = _rings(path, rings, f"jpeg_factor_above.{key}")
    return out


def _sensor_noise(path, data: dict) -> tuple[dict | None, str]:
    """({cfa: share in [0, 1]}, reference preset) of the card's optional ``sensor_noise``
    (format /5: ``{"reference": PRESET, "share": {"none": s, "rggb": s}}``); (None, "") without it."""
    table = data.get("sensor_noise") if data.get("format") == CARD_FORMAT else None
    if table is None:
        return None, ""
    if not isinstance(table, dict) or set(table) != {"reference", "share"}:
        raise DockfactoryError(f"{path}: sensor_noise: expected a table of reference, share, got {table!r}")
    ref = table["reference"]
    try:
        preset_variance(ref)
    except ValueError as exc:
        raise DockfactoryError(f"{path}: sensor_noise.reference: {exc}") from None
    shares = _factors(path, table, "share", ("none", "rggb"), "sensor_noise.", zero=True)
    bad = [c for c, v in shares.items() if v > 1.0]
    if bad:
        raise DockfactoryError(f"{path}: sensor_noise.share.{bad[0]}: expected a share in [0, 1], got {shares[bad[0]]!r}")
    return shares, ref


def _no_pose(path, data: dict) -> dict | None:
    """{"png" | "jpegQ": {cfa: share of honest frames without a pose, in [0, 1)}} of the card's
    optional ``no_pose_rate`` (written by bench/design/no_pose_rates.py); None without it."""
    table = data.get("no_pose_rate")
    if table is None:
        return None
    if not isinstance(table, dict) or not table:
        raise DockfactoryError(f"{path}: no_pose_rate: expected a table of png / jpegQ, got {table!r}")
    out = {}
    for key, rates in table.items():
        _check_format_key(path, "no_pose_rate", key)
        out[key] = _factors(path, table, key, ("none", "rggb"), "no_pose_rate.", zero=True)
        bad = [c for c, v in out[key].items() if v >= 1.0]
        if bad:
            raise DockfactoryError(f"{path}: no_pose_rate.{key}.{bad[0]}: expected a share in [0, 1), got {out[key][bad[0]]!r}")
    return out


def _check_format_key(path, where: str, key: str) -> None:
    """DockfactoryError (one line) unless ``key`` is "png" or "jpegQ" with Q in 1-100."""
    if key != "png":
        try:
            jpeg_quality(key)
        except ValueError:
            raise DockfactoryError(f"{path}: {where}.{key}: expected 'png' or 'jpegQ' (Q in 1-100)") from None


def _tail_table(path, t) -> dict | None:
    """{"png" | "jpegQ": {cfa: (eps, m)}} of ``no_pose_simulation.tail`` (eps in [0, 1), m >= 1;
    a cfa may be left out); None without it."""
    if t is None:
        return None
    where = "no_pose_simulation.tail"
    if not isinstance(t, dict):
        raise DockfactoryError(f"{path}: {where}: expected a table of png / jpegQ, got {t!r}")
    out = {}
    for key, by_cfa in t.items():
        _check_format_key(path, where, key)
        if not isinstance(by_cfa, dict) or not set(by_cfa) <= {"none", "rggb"}:
            raise DockfactoryError(f"{path}: {where}.{key}: expected a table of none / rggb, got {by_cfa!r}")
        out[key] = {}
        for cfa, v in by_cfa.items():
            ok = isinstance(v, list) and len(v) == 2 and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)
            if not (ok and 0 <= v[0] < 1 and math.isfinite(v[1]) and v[1] >= 1):
                raise DockfactoryError(f"{path}: {where}.{key}.{cfa}: expected [eps in [0, 1), m >= 1], got {v!r}")
            out[key][cfa] = (float(v[0]), float(v[1]))
    return out


def _no_pose_simulation(path, data: dict) -> tuple[GateFigures | None, dict | None]:
    """The gate's figures with the noise factor, and the centres' tail table, of the card's optional
    ``no_pose_simulation`` ({"noise_factor", "centre_noise_px", "core_px" (or null),
    "section_shift_px" ([x, y] or null), "tail" (optional: :func:`_tail_table`)}:
    eval.design_refusals); (None, None) without it."""
    t = data.get("no_pose_simulation")
    if t is None:
        return None, None
    if not isinstance(t, dict):
        raise DockfactoryError(f"{path}: no_pose_simulation: expected a table, got {t!r}")
    where = "no_pose_simulation."
    core = t.get("core_px")
    shift = t.get("section_shift_px")
    if shift is not None and not (isinstance(shift, list) and len(shift) == 2):
        raise DockfactoryError(f"{path}: {where}section_shift_px: expected [x, y] px or null, got {shift!r}")
    gate = GateFigures(_positive(path, where + "centre_noise_px", t.get("centre_noise_px")),
                       None if core is None else _positive(path, where + "core_px", core),
                       None if shift is None else tuple(_positive(path, f"{where}section_shift_px[{i}]", v, zero=True)
                                                        for i, v in enumerate(shift)),
                       _positive(path, where + "noise_factor", t.get("noise_factor")))
    return gate, _tail_table(path, t.get("tail"))


def _read_json(path: Path, what: str) -> dict:
    """The JSON object of ``path``; DockfactoryError (one line) when it cannot be read or parsed."""
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise DockfactoryError(f"{path}: cannot read the {what}: {exc.strerror}") from None
    except ValueError as exc:
        raise DockfactoryError(f"{path}: not valid JSON: {exc}") from None
    return data


def with_refusals(card: DesignCard, path) -> DesignCard:
    """``card`` with the simulated frames without a pose of the figures file ``path`` ({"format":
    REFUSALS_FORMAT, "no_pose_simulation": as a card's}: models/design_refusals.json), unless the
    card has its own section (then ``card`` as it is). Why a file of its own: its figures (the gate's
    card, the centres' tails) are measured apart from the card's noise fit, and the answer adds them to
    any card unless told not to (design --no-refusals).
    DockfactoryError (one line naming the file and key)."""
    if card.no_pose_gate is not None:
        return card
    path = Path(path)
    data = _read_json(path, "refusal figures")
    if not isinstance(data, dict) or data.get("format") != REFUSALS_FORMAT:
        raise DockfactoryError(f"{path}: format: expected {REFUSALS_FORMAT!r}")
    if data.get("no_pose_simulation") is None:
        raise DockfactoryError(f"{path}: no_pose_simulation: missing")
    gate, tail = _no_pose_simulation(path, data)
    return replace(card, no_pose_gate=gate, no_pose_tail=tail)


def load_design_card(path) -> DesignCard:
    """Read and check a predictor card; DockfactoryError (one line naming the file and key)."""
    path = Path(path)
    data = _read_json(path, "predictor card")
    fmt = data.get("format") if isinstance(data, dict) else None
    if fmt in OLD_FORMATS:
        raise DockfactoryError(f"{path}: format {fmt!r}: fitted under the previous centre-noise model; refit it "
                               "(python -m bench.design.design_fit --card-out CARD.json)")
    if fmt not in (CARD_FORMAT, RING_JPEG_FORMAT, CFA_JPEG_FORMAT, NO_LAW_FORMAT):
        raise DockfactoryError(f"{path}: format: expected {CARD_FORMAT!r} (or {RING_JPEG_FORMAT!r}, "
                               f"{CFA_JPEG_FORMAT!r}, {NO_LAW_FORMAT!r})")
    shift = data.get("shift_px")
    if not (isinstance(shift, list) and len(shift) == 2):
        raise DockfactoryError(f"{path}: shift_px: expected [u, v] px, got {shift!r}")
    q = data.get("jpeg_min_quality")
    if isinstance(q, bool) or not isinstance(q, int) or not 1 <= q <= 100:
        raise DockfactoryError(f"{path}: jpeg_min_quality: expected an integer in 1-100, got {q!r}")
    prov = data.get("provisional", [])
    if not (isinstance(prov, list) and all(isinstance(p, str) for p in prov)):
        raise DockfactoryError(f"{path}: provisional: expected a list of factor names, got {prov!r}")
    return DesignCard(str(path), _positive(path, "scale_px", data.get("scale_px")),
                      (_positive(path, "shift_px[0]", shift[0], zero=True), _positive(path, "shift_px[1]", shift[1], zero=True)),
                      _factors(path, data, "cfa_factor", ("none", "rggb")),
                      _rings(path, data.get("ring_factor")),
                      _jpeg(path, data), q,
                      _factors(path, data, "bound_factor", COMPONENTS), tuple(prov), data, _law(path, data),
                      _size_exponents(path, data), _jpeg_above(path, data, q), *_sensor_noise(path, data),
                      _no_pose(path, data), *_no_pose_simulation(path, data))
