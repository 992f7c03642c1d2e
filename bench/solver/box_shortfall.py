"""The refined boxes' shortfall against the markers' outlines, and what taking the frame's own
shortfall (solver.suspects.frame_shortfall) changes, on designs rendered by ``dockfactory design
--verify`` (their ``verify/*/run`` folders: detections, poses and dataset).

Per design: the median (outline - refined box) extent per axis of the fully visible markers (the
labels' outline boxes; centres matched within 2 px), the share of them more than 1 px short (the box
noise the occlusion rule allows), then every test frame solved again as its run solved it (the card,
the dataset's lens prior, the frame's camera class) with the rule off and on: frames without a pose
and the X / Y / alpha RMSE of the posed ones. With the rule off, the frames' outcomes must be the
run's own (checked, printed).

    python -m bench.solver.box_shortfall out/s26/confirm7_quick [...] [--json OUT]
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from bench.sensor.sensor_effects import pose_errors
from dockfactory.core.io import write_json_atomic
from dockfactory.eval.solve_frames import class_options, detection_arrays, docking_options, lens_prior_for, solve_frame
from dockfactory.generator.datasets.reader import Dataset
from dockfactory.solver import suspects

MATCH_PX = 2.0


def box_cuts(frames: dict, ds: Dataset) -> np.ndarray:
    """(n, 2) px: outline minus refined box extent (width, height) of every fully visible marker."""
    cuts = []
    for fid, dets in frames.items():
        for m in ds.labels[fid]["markers"] if fid in ds.labels else ():
            near = [d for d in dets if d["class_id"] == m["class_id"]]
            if m.get("visible_fraction", 0.0) < 0.99 or not near:
                continue
            c = np.asarray(m["outline_centroid_px"])
            d = min(near, key=lambda d: np.hypot(*(np.asarray(d["center_px"]) - c)))
            if np.hypot(*(np.asarray(d["center_px"]) - c)) <= MATCH_PX:
                lab, box = np.asarray(m["bbox_px"]), np.asarray(d["bbox_px"])
                cuts.append((lab[2:] - lab[:2]) - (box[2:] - box[:2]))
    return np.array(cuts).reshape(-1, 2)


def solved(run: Path, ds: Dataset, rule: bool) -> dict:
    """{"frames", "refused", "rmse" [x, y, alpha], "as_run"} of the run's test frames solved again."""
    dets, poses = (json.loads((run / n).read_text()) for n in ("detections.json", "poses.json"))
    suspects.SHORTFALL_FROM_FRAME = rule
    errs, refused, as_run, n = [], 0, 0, 0
    try:
        for fid, rec0 in sorted(poses["frames"].items()):
            if ds.labels[fid]["spec"].get("split") != "test":
                continue
            options = docking_options(dets["centre_noise_px"], lens_prior_for(ds.config), dets["section_shift_px"],
                                      dets["centre_noise_core_px"])
            options, factor = class_options(options, [rec0.get("camera_class", "three-chip")], True)
            rec, _ = solve_frame(ds.markers(), tuple(poses["principal_point"]),
                                 detection_arrays(dets["frames"][fid], poses["min_score"]), None, "pinhole", options, factor)
            n, as_run = n + 1, as_run + (bool(rec.get("ok")) == bool(rec0.get("ok")))
            if not rec.get("ok"):
                refused += 1
                continue
            e = pose_errors(rec, ds.labels[fid])
            errs.append([e["err_x"], e["err_y"], e["err_alpha"]])
    finally:
        suspects.SHORTFALL_FROM_FRAME = True
    rmse = np.sqrt(np.mean(np.square(errs), axis=0)).tolist() if errs else None
    return {"frames": n, "refused": refused, "rmse": rmse, "as_run": as_run}


def design(folder: Path) -> dict:
    run = folder / "run"
    name = (folder / "config.toml").read_text().splitlines()[0].lstrip("# ").strip()
    ds = Dataset.open(run / "dataset", full=False)
    cuts = box_cuts(json.loads((run / "detections.json").read_text())["frames"], ds)
    return {"design": name, "id": folder.name, "cut_median_px": np.median(cuts, axis=0).tolist(),
            "share_over_1px": float(np.mean(cuts.max(axis=1) > 1.0)),
            "rule_off": solved(run, ds, False), "rule_on": solved(run, ds, True)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("spaces", nargs="+", type=Path)
    ap.add_argument("--json", type=Path)
    args = ap.parse_args(argv)
    print("| design | box short u / v px | > 1 px | frames without a pose: off -> on (off as run) | "
          "RMSE X / Y / alpha off | on |\n| --- | --- | --- | --- | --- | --- |")
    out = []
    for folder in sorted(f for s in args.spaces for f in (s / "verify").iterdir() if (f / "run").is_dir()):
        r = design(folder)
        out.append(r)
        off, on = r["rule_off"], r["rule_on"]
        fmt = (lambda v: "-" if v is None else f"{v[0]:.3f} / {v[1]:.3f} / {v[2]:.4f}")
        print(f"| {r['design'].replace('|', '/')} | {r['cut_median_px'][0]:+.2f} / {r['cut_median_px'][1]:+.2f} | "
              f"{r['share_over_1px']:.2f} | {off['refused']} -> {on['refused']} of {off['frames']} ({off['as_run']} / "
              f"{off['frames']}) | {fmt(off['rmse'])} | {fmt(on['rmse'])} |", flush=True)
    if args.json:
        write_json_atomic(args.json, out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
