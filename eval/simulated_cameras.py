"""What the verdict was measured through: the simulated camera of every camera unit (lens, colour
filter array and EMVA 1288 sensor, ISP, encoding) and the localization errors of each unit's test
frames, so a report names the camera its figures hold for, with one row per unit (and preset).

The block is built from the dataset's config (the same draws the factory made: ``unit_lens``,
``unit_sensor``) and the evaluation's per-frame rows; it is reported, not gated. The camera of each
frame (its Bayer pattern and encoding: ``dataset_camera`` per unit for the detector,
``frame_camera`` from the frame's label for its camera class) is read here too.
"""
from __future__ import annotations

import html

import numpy as np

from dockfactory.core.camera_chain.colour_sensor import white_dn
from dockfactory.eval.acceptance import UNITS
from dockfactory.eval.camera_classes import camera_class
from dockfactory.generator.camera_units import unit_lens, unit_sensor
from dockfactory.generator.datasets.reader import Dataset


SHOWN = ("x", "y", "alpha")   # the components the paper's acceptance gates

# what the report reads of metrics["simulated_cameras"] (eval.report.check_schema): the lens, and
# a sensor record of the three-chip model or of a preset (checked by the record's own kind)
LENS_SCHEMA = {"principal_offset_px": ("pair", "num"), "k1": "num", "k2": "num", "aberration_px": ("pair", "num"),
               "f_number": "num?", "jpeg_quality": "num?", "jpeg_subsampling": "str?"}
THREE_CHIP_SCHEMA = {"model": "str", "full_well_e": ("pair", "num"), "read_noise_e": ("pair", "num"), "adc_bits": "int"}
PRESET_SCHEMA = {"model": "str", "preset": "str", "cfa": "str", "demosaic": "str", "saturation_e": "num",
                 "dark_noise_e": "num", "gain_dn_per_e": "num", "adc_bits": "int", "crosstalk": "num",
                 "isp": {"wb_error": ("pair", "num"), "colour_correction": "bool", "tone": "str", "denoise": "str",
                         "sharpen": "num"}}
BLOCK_SCHEMA = {"statement": "str", "units": ("list", {"unit": "int", "lens": LENS_SCHEMA, "sensor": {"model": "str"},
                                                        "test": {"frames": "int", "solved": "int", "x": "num?",
                                                                 "y": "num?", "alpha": "num?"}})}


def sensor_schema(sensor: dict) -> dict:
    """The schema of a unit's sensor record: a preset's, or the three-chip model's."""
    return PRESET_SCHEMA if isinstance(sensor, dict) and "preset" in sensor else THREE_CHIP_SCHEMA


def _lens(cfg, unit: int) -> dict:
    lens = unit_lens(cfg.camera_units, cfg.dataset.seed, unit)
    return {"principal_offset_px": list(lens.principal_offset), "k1": lens.distortion[0], "k2": lens.distortion[1],
            "aberration_px": list(lens.aberration_px), "f_number": lens.f_number or None,
            "jpeg_quality": lens.jpeg_quality or None,
            "jpeg_subsampling": cfg.camera_units.jpeg_subsampling if lens.jpeg_quality else None}


def _sensor(cfg, unit: int) -> dict:
    s = cfg.sensor
    us = unit_sensor(s, cfg.dataset.seed, unit)
    if us is None:
        return {"model": "three-chip noise model", "full_well_e": list(s.full_well_e),
                "read_noise_e": list(s.read_noise_e), "adc_bits": s.adc_bits}
    e = us.sensor
    return {"model": f"EMVA 1288 preset {us.preset}", "preset": us.preset, "cfa": us.cfa, "demosaic": us.demosaic,
            "saturation_e": e.saturation_e, "dark_noise_e": e.dark_noise_e, "gain_dn_per_e": e.gain_dn_per_e,
            "quantum_efficiency": list(e.quantum_efficiency), "dsnu_dn": e.dsnu_dn, "prnu_pct": e.prnu_pct,
            "adc_bits": e.adc_bits, "white_dn": white_dn(e), "crosstalk": us.crosstalk,
            "isp": {"wb_error": list(s.wb_error), "colour_correction": s.colour_correction, "tone": s.tone,
                    "denoise": s.denoise, "sharpen": us.sharpen}}


def _unit_errors(rows: list[dict]) -> dict:
    ok = [r for r in rows if r["ok"]]
    out = {"frames": len(rows), "solved": len(ok)}
    for c in SHOWN:
        e = np.array([r[f"err_{c}"] for r in ok], dtype=float)
        out[c] = float(np.sqrt(np.mean(e ** 2))) if e.size else None
    return out


def simulated_cameras_block(ds: Dataset, test_rows: list[dict]) -> dict:
    """{"units": [{unit, lens, sensor, test errors (RMSE per component)}], "statement": the sensor
    models of the units, in one line}."""
    cfg = ds.config
    by_unit: dict[int, list] = {}
    for r in test_rows:
        by_unit.setdefault(int(ds.labels[r["frame_id"]]["spec"].get("unit", 0)) if r["frame_id"] in ds.labels
                           else -1, []).append(r)
    units = [{"unit": u, "lens": _lens(cfg, u), "sensor": _sensor(cfg, u), "test": _unit_errors(by_unit.get(u, []))}
             for u in range(cfg.camera_units.count)]
    kinds = sorted({u["sensor"]["model"] for u in units})
    return {"units": units, "statement": "; ".join(kinds)}


def _lens_text(lens: dict) -> str:
    jpeg = f"JPEG q{lens['jpeg_quality']} {lens['jpeg_subsampling']}" if lens["jpeg_quality"] else "lossless PNG"
    return (f"pp offset ({lens['principal_offset_px'][0]:+.1f}, {lens['principal_offset_px'][1]:+.1f}) px, "
            f"k1 {lens['k1']:+.3f}, k2 {lens['k2']:+.3f}, CA {lens['aberration_px'][0]:+.2f} / "
            f"{lens['aberration_px'][1]:+.2f} px" + (f", f/{lens['f_number']:.1f}" if lens["f_number"] else "")
            + f"; {jpeg}")


def _sensor_text(s: dict) -> str:
    if "preset" not in s:
        return (f"{s['model']}: full well {s['full_well_e'][0]:g}-{s['full_well_e'][1]:g} e-, read noise "
                f"{s['read_noise_e'][0]:g}-{s['read_noise_e'][1]:g} e-, {s['adc_bits']} bit")
    isp = s["isp"]
    return (f"{s['model']}: {s['cfa']} ({s['demosaic']} demosaic), saturation {s['saturation_e']:.0f} e-, dark noise "
            f"{s['dark_noise_e']:.2f} e-, K {s['gain_dn_per_e']:.3g} DN/e-, {s['adc_bits']} bit, crosstalk "
            f"{s['crosstalk']:.3f}; ISP: white balance error {isp['wb_error'][0]:+.0%} to {isp['wb_error'][1]:+.0%}, "
            f"{'colour correction, ' if isp['colour_correction'] else ''}{isp['tone']} tone, denoise {isp['denoise']}, "
            f"sharpen {isp['sharpen']:.2f}")


def html_simulated_cameras(block: dict) -> list[str]:
    """The report section: what was simulated, per unit, and each unit's test errors."""
    head = ("<tr><th>unit</th><th>lens and encoding</th><th>sensor and ISP</th><th>test frames solved</th>"
            + "".join(f"<th>RMSE {c} ({UNITS[c]})</th>" for c in SHOWN) + "</tr>")
    rows = []
    for u in block["units"]:
        t = u["test"]
        cells = "".join(f"<td>{'-' if t[c] is None else f'{t[c]:.4g}'}</td>" for c in SHOWN)
        rows.append(f"<tr><td>{u['unit']}</td><td>{html.escape(_lens_text(u['lens']))}</td>"
                    f"<td>{html.escape(_sensor_text(u['sensor']))}</td><td>{t['solved']} of {t['frames']}</td>{cells}</tr>")
    return ["<h2>What was simulated</h2>",
            f"<p>The ground truth is rendered, not measured, through simulated cameras "
            f"({html.escape(block['statement'])}). The figures hold for "
            "cameras like these; a camera with another sensor, ISP or encoding needs its own run.</p>",
            f"<table>{head}{''.join(rows)}</table>"]


def unit_camera(cfg, unit: int) -> tuple[str | None, bool]:
    """(Bayer pattern or None, JPEG-encoded?) of camera unit ``unit`` of a dataset config ``cfg``
    (core.config.Config): the draws the factory made for it (``unit_sensor``'s CFA, None for
    "none" or without [sensor] presets; ``unit_lens``'s JPEG quality, 0: lossless)."""
    us = unit_sensor(cfg.sensor, cfg.dataset.seed, unit)
    cfa = us.cfa if us is not None and us.cfa != "none" else None
    return cfa, bool(unit_lens(cfg.camera_units, cfg.dataset.seed, unit).jpeg_quality)


def dataset_camera(ds: Dataset):
    """frame id -> (Bayer pattern or None, JPEG-encoded?) of the unit that took the frame: what the
    maker of a camera knows (its pixel format, its encoding), told to the detector's centre
    refinement; None when every unit is a three-chip camera writing lossless images."""
    cfg = ds.config
    units = {u: unit_camera(cfg, u) for u in range(cfg.camera_units.count)}
    if all(v == (None, False) for v in units.values()):
        return None
    return lambda fid: units[int(ds.labels[fid]["spec"].get("unit", 0))]


def frame_camera(label: dict, cfg) -> tuple[str | None, bool]:
    """(Bayer pattern or None, JPEG-encoded?) of the frame a dataset ``label`` describes, as its image
    was delivered. Each from the label's own record when it has one: ``sampled.sensor`` (the
    pattern of its colour ``chain``'s CFA; no chain, or "none": the frame went through no CFA, as
    with the three-chip noise model or an ideal frame, which skips the sensor) and
    ``camera.jpeg_quality`` (None or 0: lossless); else its camera unit's in the dataset's config
    ``cfg`` (:func:`unit_camera`; the unit from ``spec.unit``, 0 when absent). The stored image
    says nothing: a JPEG unit's frames are kept as PNGs of the decoded JPEG."""
    unit_cfa, unit_jpeg = unit_camera(cfg, int(label.get("spec", {}).get("unit", 0)))
    sensor = label.get("sampled", {}).get("sensor")
    if isinstance(sensor, dict):
        chain = sensor.get("chain") or {}
        cfa = chain.get("cfa") if chain.get("cfa") not in (None, "none") else None
    else:
        cfa = unit_cfa
    camera = label.get("camera", {})
    jpeg = bool(camera["jpeg_quality"]) if "jpeg_quality" in camera else unit_jpeg
    return cfa, jpeg


def frame_camera_class(label: dict, cfg) -> str:
    """The camera class (eval.camera_classes.camera_class) of the dataset frame ``label`` of a
    dataset of config ``cfg``: its :func:`frame_camera`."""
    return camera_class(*frame_camera(label, cfg))
