"""The refinement's bias by marker form ([markers] form: a raised puck, a flat printed plate).

    python -m bench.render.marker_form DATASET [DATASET ...] [--out table.json]

Each DATASET: a render of the same frames (same config but [markers] form / raise_mm, and
[render]) with the shipped detector's detections cached beside it
(``<dataset>.detections_bench.json``, as bench/render/marker_sampling.py writes them). A puck's dark side
shows at a slant on one side of its disc; the edge fit may take part of it for the disc. Per
dataset, over the used detections of the solved test frames, against each label's outline
centroid (the disc's exact image centroid):

- the mean centre error along the side's direction in the image (the unit vector from the disc
  centre's projection to that of a point 1 mm below it, along the marker's normal: where the side
  shows) and across it, each with its standard error and t;
- the same along the side for the markers seen most obliquely (side longer than 0.3 px);
- the median radial error.

Figures and their reading: bench/results/marker_sampling/README.md ("Marker form").
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
from dockfactory.eval.centre_noise import used_centre_matches
from dockfactory.eval.solve_frames import solve_dataset
from dockfactory.generator.datasets.reader import Dataset

MIN_SCORE = 0.25
OBLIQUE_PX = 0.3


def side_vector(label: dict, marker: dict) -> np.ndarray:
    """(2,) px: the image of 1 mm down the marker's normal from its disc centre (pinhole)."""
    k, cam = np.array(label["camera"]["K"]), np.array(label["camera"]["cam_from_d"])
    pts = np.array([marker["center_d_mm"], np.subtract(marker["center_d_mm"], marker["normal_d"])])
    xc = (cam[:3, :3] @ pts.T).T + cam[:3, 3]
    uv = (k @ xc.T).T
    uv = uv[:, :2] / uv[:, 2:]
    return uv[1] - uv[0]


def errors(root: Path) -> dict:
    ds = Dataset.open(root)
    dets = json.loads((root.parent / f"{root.name}.detections_bench.json").read_text())
    poses = solve_dataset(ds, splits=("test",), detections=dets)
    along, across, side_len, radial = [], [], [], []
    for fid, rec in poses["frames"].items():
        if not rec.get("ok"):
            continue
        matches, _ = used_centre_matches(ds.labels[fid], dets["frames"].get(fid, []), rec["marker_ids"], MIN_SCORE)
        for m, e in matches:
            s = side_vector(ds.labels[fid], m)
            n = float(np.hypot(*s))
            if n < 1e-6:
                continue
            u = s / n
            along.append(float(e @ u))
            across.append(float(e @ np.array([-u[1], u[0]])))
            side_len.append(n)
            radial.append(float(np.hypot(*e)))
    along, across, side_len = np.array(along), np.array(across), np.array(side_len)
    oblique = along[side_len > OBLIQUE_PX]
    return {"dataset": str(root), "version": ds.version_id, "form": ds.config.markers.form,
            "raise_mm": ds.config.markers.raise_mm, "n": int(len(along)),
            "along": _mean(along), "across": _mean(across), "oblique": _mean(oblique),
            "side_px_median": float(np.median(side_len)), "median_radial_px": float(np.median(radial))}


def _mean(a: np.ndarray) -> dict:
    if len(a) < 2:
        return {"n": int(len(a)), "mean_px": None, "se_px": None, "t": None}
    se = float(a.std(ddof=1) / np.sqrt(len(a)))
    return {"n": int(len(a)), "mean_px": float(a.mean()), "se_px": se, "t": float(a.mean() / se)}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("datasets", nargs="+", type=Path)
    ap.add_argument("--out", type=Path)
    args = ap.parse_args()
    rows = [errors(root) for root in args.datasets]
    print("| dataset | form, raise | markers | side (px per mm, median) | along the side, mean px (t) | across (t) "
          "| oblique ones along (n, t) | median radial px |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for r in rows:
        a, c, o = r["along"], r["across"], r["oblique"]
        obl = f"{o['mean_px']:+.4f} ({o['n']}, {o['t']:+.1f})" if o["mean_px"] is not None else "-"
        print(f"| {Path(r['dataset']).name} `{r['version']}` | {r['form']}, {r['raise_mm']:g} mm | {r['n']} | "
              f"{r['side_px_median']:.2f} | {a['mean_px']:+.4f} ({a['t']:+.1f}) | {c['mean_px']:+.4f} ({c['t']:+.1f}) | "
              f"{obl} | {r['median_radial_px']:.4f} |")
    if args.out:
        write_json_atomic(args.out, {"rows": rows})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
