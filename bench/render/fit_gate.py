"""The goodness-of-fit gate (eval.fit_gate) on rendered frames: false alarms, and the faults it catches.

    python -m bench.render.fit_gate DATASET [DATASET ...] [--lens-prior pp=0.15] [--noise-factor F]
        [--faults NAMES] [--out table.json]

Each DATASET is a rendered dataset whose test frames have cached detections of the shipped
detector (``<dataset>.detections_bench.json`` beside it, as bench/render/marker_sampling.py writes
them; their ``centre_noise_px`` is the noise card's, the noise the gate tests against). Per
dataset, the same detections solved as they are and after each fault a user really produces:

- as is: frames ok, left one or two centres out, refused; the residual ratio (per-axis RMS over
  the noise tested against: the card's times ``--noise-factor``) median / 90th percentile / max;
- another layout: the markers of a section of radius 450 mm and 30 mm discs (300 mm and 20 mm
  for a dataset of the former);
- stretched: the centres' u stretched 1.5x about the image centre;
- cropped: the principal point assumed 160 / 120 px off (the centres shifted);
- mirrored: u -> W - 1 - u (refused: no camera gives it);
- rotated 90, 180, 270: the image turned about its centre (a camera mounted at that roll; the
  principal point the turned image's centre): a right pose expected.

For every fault: frames ok, and of those the ones whose X, Y or Z error is beyond 3 of their
reported standard deviations ("ok and wrong": the target is 0), and the median reported std of
X, Y, Z over the ok frames (what a wider lens prior costs an honest frame). ``--lens-prior`` (as ``measure``'s:
e.g. ``pp=0.15`` for a user who states that the image may be cut from the sensor by up to 15 % of
its width) replaces the uncalibrated camera's default prior. ``--noise-factor`` tests every frame
against the card times that factor (a noisier camera class's gate: what it lets through).
Figures and their reading:
bench/results/fit_gate/README.md.
"""
from __future__ import annotations

import os

import dockfactory

dockfactory.pin_label_arithmetic(os.environ)   # before numpy loads: labels as the command computes them

import argparse
import json
from pathlib import Path

import numpy as np

from dockfactory.core.io import write_json_atomic
from dockfactory.cli_args import lens_prior
from dockfactory.core.layout import build_layout
from dockfactory.eval.solve_frames import detection_arrays, docking_options, solve_frame
from dockfactory.generator.datasets.reader import Dataset

MIN_SCORE = 0.25
AXES = ("x_mm", "y_mm", "z_mm")


def faults(w: int, h: int, layout_other):
    """{name: (markers or None, centre transform, image size after it)}: the inputs of the table.
    The rotations turn the image about its centre (a camera mounted at that roll): a right pose
    is the expected answer there, not a refusal."""
    c = np.array([(w - 1) / 2.0, (h - 1) / 2.0])
    return {"as is": (None, lambda uv: uv, (w, h)),
            "another layout": (layout_other, lambda uv: uv, (w, h)),
            "stretched 1.5x": (None, lambda uv: c + (uv - c) * np.array([1.5, 1.0]), (w, h)),
            "cropped 160/120 px": (None, lambda uv: uv + np.array([160.0, 120.0]), (w, h)),
            "cropped 80/60 px": (None, lambda uv: uv + np.array([80.0, 60.0]), (w, h)),
            "mirrored": (None, lambda uv: np.column_stack([w - 1 - uv[:, 0], uv[:, 1]]), (w, h)),
            "rotated 90": (None, lambda uv: np.column_stack([uv[:, 1], w - 1 - uv[:, 0]]), (h, w)),
            "rotated 180": (None, lambda uv: np.column_stack([w - 1 - uv[:, 0], h - 1 - uv[:, 1]]), (w, h)),
            "rotated 270": (None, lambda uv: np.column_stack([h - 1 - uv[:, 1], uv[:, 0]]), (h, w))}


def other_layout(ds: Dataset):
    """The "another layout" fault's markers: ``ds``'s layout on another scene's sections (radius
    450 mm and 30 mm discs, or 300 mm and 20 mm for a dataset of the former)."""
    mine = (ds.config.sections.radius_mm, ds.config.markers.diameter_mm)
    radius, diameter = (300.0, 20.0) if mine == (450.0, 30.0) else (450.0, 30.0)
    return build_layout(ds.config.markers.layout_a, ds.config.markers.layout_b, radius, diameter)


def run(root: Path, lens=None, factor: float = 1.0, only=None) -> dict:
    """The fault table of one dataset (see the module's docstring); ``lens`` a LensPrior or None
    (the uncalibrated camera's default); ``factor`` on the card's noise the gate tests against;
    ``only`` the names of the faults to run (None: all)."""
    ds = Dataset.open(root)
    dets = json.loads((root.parent / f"{root.name}.detections_bench.json").read_text())
    card = dets.get("centre_noise_px")
    noise = None if card is None else card * factor
    w, h = ds.config.image.width, ds.config.image.height
    other = other_layout(ds)
    out = {"dataset": str(root), "version": ds.version_id, "card_px": card, "noise_factor": factor,
           "noise_px": noise, "faults": {}}
    for name, (markers, move, size) in faults(w, h, other).items():
        if only is not None and name not in only:
            continue
        rows = []
        for fid in ds.frames(("test",)):
            cls, uv, boxes, refined = detection_arrays(dets["frames"].get(fid, []), MIN_SCORE)
            if len(cls) == 0:
                continue
            rec, _ = solve_frame(markers or ds.markers(), ((size[0] - 1) / 2.0, (size[1] - 1) / 2.0),
                                 (cls, move(uv), _moved_boxes(boxes, move), refined), None,
                                 "pinhole", docking_options(noise, lens))
            rows.append(_row(rec, ds.labels[fid]["pose_b_in_d"]))
        out["faults"][name] = _summary(rows)
    return out


def _moved_boxes(boxes, move):
    """Detection boxes (n, 4) x0, y0, x1, y1 after the centre transform ``move`` (its corners
    moved, the box around them); None stays None."""
    if boxes is None:
        return None
    lo, hi = move(boxes[:, :2]), move(boxes[:, 2:])
    return np.column_stack([np.minimum(lo, hi), np.maximum(lo, hi)])


def _row(rec: dict, truth: dict) -> dict:
    if not rec["ok"]:
        return {"ok": False, "category": rec.get("category")}
    cov = np.array(rec["covariance"])
    z = [abs(rec["pose"][k] - truth[k]) / np.sqrt(cov[i, i]) for i, k in enumerate(AXES)]
    test = rec.get("fit_test", {})
    return {"ok": True, "left_out": len(rec.get("left_out", [])), "ratio": test.get("ratio"),
            "max_z": float(max(z)), "z": [float(v) for v in z], "x_err": rec["pose"]["x_mm"] - truth["x_mm"],
            "std_xyz": np.sqrt(np.diag(cov)[:3]).tolist()}


def _summary(rows: list[dict]) -> dict:
    ok = [r for r in rows if r["ok"]]
    ratios = np.array([r["ratio"] for r in ok if r["ratio"] is not None])
    spread = [float(np.median(ratios)), float(np.percentile(ratios, 90)), float(ratios.max())] if len(ratios) else []
    return {"frames": len(rows), "ok": len(ok), "left_out": sum(r["left_out"] > 0 for r in ok),
            "ok_beyond_3_sigma": sum(r["max_z"] > 3 for r in ok),
            "refused": {c: sum(1 for r in rows if not r["ok"] and r["category"] == c)
                        for c in sorted({r["category"] for r in rows if not r["ok"]})},
            "ratio_median_p90_max": spread,
            "std_xyz_median_mm": np.median([r["std_xyz"] for r in ok], axis=0).round(4).tolist() if ok else []}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("datasets", nargs="+", type=Path)
    ap.add_argument("--lens-prior", type=lens_prior, help="as measure's (default: an uncalibrated camera's)")
    ap.add_argument("--noise-factor", type=float, default=1.0, help="test against the card times this (default 1)")
    ap.add_argument("--faults", default=None, help="comma-separated names of the faults to run (default: all)")
    ap.add_argument("--out", type=Path)
    args = ap.parse_args()
    print("| dataset | input | frames | ok | left a centre out | ok and beyond 3 sigma | refused | ratio median / p90 / max "
          "| std X / Y / Z mm |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |", flush=True)
    results = []
    for root in args.datasets:
        only = None if args.faults is None else args.faults.split(",")
        results.append(res := run(root, args.lens_prior, args.noise_factor, only))
        for name, s in res["faults"].items():
            refused = ", ".join(f"{c} {n}" for c, n in s["refused"].items()) or "-"
            print(f"| {Path(res['dataset']).name} | {name} | {s['frames']} | {s['ok']} | {s['left_out']} | "
                  f"{s['ok_beyond_3_sigma']} | {refused} | " + " / ".join(f"{v:.2f}" for v in s["ratio_median_p90_max"])
                  + " | " + " / ".join(f"{v:.3f}" for v in s["std_xyz_median_mm"]) + " |", flush=True)
    if args.out:
        write_json_atomic(args.out, {"results": results})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
