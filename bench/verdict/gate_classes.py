"""The goodness-of-fit gate of a camera class at several noise levels: honest frames refused against
faults let through, on the detections the sensor bench kept.

    python -m bench.verdict.gate_classes RESULTS.json DATASET [DATASET ...] --factors 1,2,3.95,7.9
        [--effects bayer-jpeg90,...] [--faults "as is,cropped 160/120 px"] [--frames N] [--out FILE.json]
        [--class-gate] [--pattern-min-dof N] [--pattern-power P] [--left-out-any]

RESULTS.json is a sensor bench results file with its rows (bench/sensor/sensor_effects.py ``--out``:
each frame's detections through each camera effect, the refinement told the camera); each DATASET
the rendered dataset of one of its keys (its markers, image size and labels). Every frame's
detections are solved again, after each fault of bench/render/fit_gate.py (a user's real faults on
this camera's own centres), with the known centre noise the card's times each factor (a gate per
camera class, tried: bench/results/fit_gate/README.md), through the gate as measure solves it. Per
effect, factor and fault: frames ok, ok after leaving centres out, ok and beyond 3 reported
standard deviations in X, Y or Z ("confidently wrong"), the RMS of z = error / reported std of X,
Y, Z, refused by category; every solve carries the card's section shift. With ``--class-gate`` the
solve is measure's for the effect's camera class (eval.camera_classes, the class of the effect's
name): the class's factor for the gate's second test, the class's section shift, and the noise prior
(the card's robust core times the class's factor; dockfactory.measure.images.class_docking_options).
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from bench.render.fit_gate import _moved_boxes, _row, faults, other_layout
from dockfactory.core.io import write_json_atomic
from dockfactory.eval import fit_gate
from dockfactory.eval.camera_classes import CAMERA_CLASS_FACTORS, camera_class
from dockfactory.eval.solve_frames import detection_arrays, docking_options, lens_prior_for, solve_frame
from dockfactory.measure.images import class_docking_options
from dockfactory.generator.datasets.reader import Dataset

MIN_SCORE = 0.25


def effect_class(effect: str) -> str:
    """The camera class of a sensor-bench effect by its name (Bayer, JPEG, both or neither)."""
    return camera_class("RGGB" if effect.startswith("bayer") else None, "jpeg" in effect)


def solve_options(ds: Dataset, figures, noise_px: float, cls: str | None):
    """The solver's options for a frame of ``ds`` through the camera class ``cls``: measure's own
    (dockfactory.measure.images.class_docking_options: the card's floor ``noise_px``, the class's
    section shift and noise prior) with the card's ``figures``; None for ``cls``: the gate at
    ``noise_px`` with the card's section shift and no prior (the bench before the class's test)."""
    lens = lens_prior_for(ds.config)
    if cls is None:
        return docking_options(noise_px, lens, figures.section_shift_px)
    card = SimpleNamespace(centre_noise_px=noise_px, section_shift_px=figures.section_shift_px,
                           noise_core_px=figures.core_px)
    return class_docking_options(card, lens, cls)


def fault_rows(ds: Dataset, rows: list[dict], options, fault, frames: int, class_factor: float = 1.0) -> list[dict]:
    """fit_gate's row of every sensor-bench row of ``ds`` after ``fault`` (markers, move, size),
    solved with ``options`` (:func:`solve_options`) and the camera class's ``class_factor`` for the
    gate's second test."""
    markers, move, size = fault
    out = []
    for row in rows[:frames]:
        cls, uv, boxes, refined = detection_arrays(row["dets"], MIN_SCORE)
        if len(cls) == 0:
            continue
        rec, _ = solve_frame(markers or ds.markers(), ((size[0] - 1) / 2.0, (size[1] - 1) / 2.0),
                             (cls, move(uv), _moved_boxes(boxes, move), refined), None, "pinhole",
                             options, class_factor)
        out.append(_row(rec, ds.labels[row["frame"]]["pose_b_in_d"]))
    return out


def tally(rows: list[dict]) -> dict:
    """Frames, ok, ok with centres left out, ok beyond 3 sigma, the RMS of z (error / reported std)
    of X, Y, Z over the ok frames, refused by category."""
    ok = [r for r in rows if r["ok"]]
    rms_z = np.sqrt(np.mean(np.square([r["z"] for r in ok]), axis=0)).round(2).tolist() if ok else None
    return {"frames": len(rows), "ok": len(ok), "left_out": sum(r["left_out"] > 0 for r in ok),
            "ok_beyond_3_sigma": sum(r["max_z"] > 3 for r in ok), "rms_z_xyz": rms_z,
            "refused": {c: sum(1 for r in rows if not r["ok"] and r["category"] == c)
                        for c in sorted({r["category"] for r in rows if not r["ok"]})}}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("results", type=Path)
    ap.add_argument("datasets", nargs="+", type=Path)
    ap.add_argument("--factors", default="1,2,4,7.9")
    ap.add_argument("--effects", default=None, help="comma-separated (default: every effect with rows)")
    ap.add_argument("--faults", default="as is,cropped 160/120 px,another layout")
    ap.add_argument("--frames", type=int, default=48)
    ap.add_argument("--card", type=float, default=None, help="the card's centre noise, px (default: the shipped weights')")
    ap.add_argument("--out", type=Path)
    ap.add_argument("--class-gate", action="store_true",
                    help="measure's solve: the card, the class's second test, section shift and noise prior")
    ap.add_argument("--pattern-min-dof", type=int, default=None,
                    help="try the class's test with this many tested directions at least (eval.fit_gate.PATTERN_MIN_DOF)")
    ap.add_argument("--pattern-power", type=float, default=None,
                    help="the power against a principal point off by PATTERN_OFFSET lens-prior half-ranges that lets "
                         "fewer directions test the pattern (eval.fit_gate.PATTERN_POWER, off by default; 0: off)")
    ap.add_argument("--left-out-any", action="store_true",
                    help="the gate before: a noisy class's fit with centres left out kept however few directions its "
                         "camera-model check has left (eval.fit_gate.LEFT_OUT_NEEDS_PATTERN off)")
    args = ap.parse_args(argv)
    if args.left_out_any:
        fit_gate.LEFT_OUT_NEEDS_PATTERN = False
    if args.pattern_min_dof is not None:
        fit_gate.PATTERN_MIN_DOF = args.pattern_min_dof
    if args.pattern_power is not None:
        fit_gate.PATTERN_POWER = args.pattern_power or None
    if args.class_gate:
        args.factors = "1"
    from dockfactory.core.resources import shipped_weights
    from dockfactory.detector.noise_card import card_figures
    figures = card_figures(shipped_weights())
    if args.card is None:
        args.card = figures.centre_noise_px
    results = json.loads(args.results.read_text())["datasets"]
    opened = {f"{d.config.dataset.name}@{d.version_id}": d for d in map(Dataset.open, args.datasets)}
    out = {"card_px": args.card, "pattern_min_dof": args.pattern_min_dof, "pattern_power": fit_gate.PATTERN_POWER,
           "pattern_offset": fit_gate.PATTERN_OFFSET if fit_gate.PATTERN_POWER else None,
           "tables": []}
    print("| dataset | effect | factor | fault | frames | ok | left out | ok beyond 3 sigma | RMS z X / Y / Z | refused |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |", flush=True)
    for key, effects in results.items():
        ds = opened.get(key)
        if ds is None:
            print(f"{key}: no dataset given, skipped", file=sys.stderr)
            continue
        w, h = ds.config.image.width, ds.config.image.height
        table = faults(w, h, other_layout(ds))
        for effect, res in effects.items():
            if (args.effects and effect not in args.effects.split(",")) or "rows" not in res:
                continue
            for f in (float(v) for v in args.factors.split(",")):
                for name in args.faults.split(","):
                    cls = effect_class(effect) if args.class_gate else None
                    cf = CAMERA_CLASS_FACTORS[cls or "three-chip"]
                    options = solve_options(ds, figures, args.card * f, cls)
                    t = tally(fault_rows(ds, res["rows"], options, table[name], args.frames, cf))
                    out["tables"].append({"dataset": key, "effect": effect, "factor": f, "class_factor": cf,
                                          "fault": name, **t})
                    refused = ", ".join(f"{c} {n}" for c, n in t["refused"].items()) or "-"
                    print(f"| {key.split('@')[0]} | {effect} | {f:g} | {name} | {t['frames']} | {t['ok']} | "
                          f"{t['left_out']} | {t['ok_beyond_3_sigma']} | {' / '.join(map(str, t['rms_z_xyz'] or ['-']))} | "
                          f"{refused} |", flush=True)
                    if args.out:
                        write_json_atomic(args.out, out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
