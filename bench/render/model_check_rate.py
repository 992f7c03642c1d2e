"""How often the camera-model check flags frames of an ideal pinhole camera, per render setting.

    python -m bench.render.model_check_rate DATASET[=NOISE_PX] [DATASET[=NOISE_PX] ...] [--out table.json]

Each DATASET is a rendered dataset of an ideal pinhole camera (no lens distortion, the
principal point at the image centre) whose test frames have cached detections of the shipped
detector (``<dataset>.detections_bench.json`` beside it, as bench/render/marker_sampling.py writes
them). Its test frames are solved as ``solve`` does (the paper's pinhole model, the camera
model check on); ``=NOISE_PX`` sets the centre noise the fits are tested against (the noise
card measured at that dataset's render setting), else the detections' own (the shipped card's).

The check's nominal false-alarm rate is its p-value threshold: every flag on these frames is a
false alarm (the camera *is* the pinhole model). Printed per dataset: frames solved, checked,
flagged (share, and the nominal share), the fit gate's refusals and left-out centres, and the
check's p-values (median, 10th percentile). Figures and their reading:
bench/results/marker_sampling/README.md ("The camera-model check").
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import os

import dockfactory

dockfactory.pin_label_arithmetic(os.environ)   # before numpy loads: labels as the command computes them

import numpy as np

from dockfactory.core.io import write_json_atomic
from dockfactory.eval.solve_frames import solve_dataset
from dockfactory.generator.datasets.reader import Dataset


def rate(root: Path, noise_px: float | None) -> dict:
    """The model check's flags and the fit gate's refusals on one dataset's test frames."""
    ds = Dataset.open(root)
    dets = json.loads((root.parent / f"{root.name}.detections_bench.json").read_text())
    poses = solve_dataset(ds, splits=("test",), detections=dets, sigma_floor_px=noise_px)
    recs = list(poses["frames"].values())
    ok = [r for r in recs if r["ok"]]
    checks = [r["model_check"] for r in ok if r.get("model_check", {}).get("explains") is not None]
    p = np.array([c["p_value"] for c in checks]) if checks else np.array([np.nan])
    return {"dataset": str(root), "version": ds.version_id, "marker_samples": ds.config.render.marker_samples,
            "noise_px": poses["sigma_floor_px"], "frames": len(recs), "solved": len(ok),
            "checked": len(checks), "flagged": sum(not c["explains"] for c in checks),
            "nominal_p": poses["lens_prior"]["misfit_alpha"], "misfit": sum(r.get("category") == "misfit" for r in recs),
            "left_out": sum(bool(r.get("left_out")) for r in ok),
            "p_median": float(np.nanmedian(p)), "p_10": float(np.nanpercentile(p, 10))}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("datasets", nargs="+", help="DATASET or DATASET=NOISE_PX")
    ap.add_argument("--out", type=Path)
    args = ap.parse_args()
    rows = []
    for item in args.datasets:
        path, _, noise = item.partition("=")
        rows.append(rate(Path(path), float(noise) if noise else None))
    print("| dataset | version | marker_samples | noise px | solved | checked | flagged (share; nominal) "
          "| misfit | left out | p median / 10th pct |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for r in rows:
        share = r["flagged"] / max(r["checked"], 1)
        print(f"| {Path(r['dataset']).name} | {r['version']} | {r['marker_samples']} | {r['noise_px']:.4f} | "
              f"{r['solved']}/{r['frames']} | {r['checked']} | {r['flagged']} ({share:.2f}; {r['nominal_p']:g}) | "
              f"{r['misfit']} | {r['left_out']} | {r['p_median']:.3g} / {r['p_10']:.3g} |")
    if args.out:
        write_json_atomic(args.out, {"rows": rows})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
