"""Probe `measure` with the faults a user really produces, on rendered frames with known poses:
no traceback, and no `ok` pose beyond its own expanded uncertainty U.

    python -m bench.solver.probe_faults DATASET [--frames 8] [--out RESULTS.json] [--weights W]

DATASET: a rendered dataset (its layout.json, labels and test frames). Its first ``--frames``
test images are measured by the command line (one `dockfactory measure` process per fault) as
they are and after each fault:

- ``as-is``; ``rot90``, ``rot180``, ``rot270`` (a camera mounted at that roll: a right pose
  expected, the relative pose of B does not depend on the camera); ``mirrored`` (no camera makes
  it: refused expected);
- ``stretched`` (width x1.5), ``cropped`` (the right 320 and bottom 240 px cut: the principal
  point 160 / 120 px off the image centre);
- ``other-layout``: the layout of another scene (radius 450 mm and 30 mm markers, or 300 / 20 for
  a dataset of radius 450 mm: the markers on another radius, not only another size).

Per fault: images, ok, ok beyond U (|error| > expanded U on any of X, Y, Z, alpha), tracebacks
and exit statuses. The target: 0 tracebacks, 0 ok beyond U.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

import cv2

from dockfactory.core.io import write_json_atomic
from dockfactory.generator.datasets.folder import layout_record
from dockfactory.generator.datasets.reader import Dataset

AXES = ("x_mm", "y_mm", "z_mm", "alpha_deg")
FAULTS = {
    "as-is": lambda im: im,
    "rot90": lambda im: cv2.rotate(im, cv2.ROTATE_90_CLOCKWISE),
    "rot180": lambda im: cv2.rotate(im, cv2.ROTATE_180),
    "rot270": lambda im: cv2.rotate(im, cv2.ROTATE_90_COUNTERCLOCKWISE),
    "mirrored": lambda im: cv2.flip(im, 1),
    "stretched": lambda im: cv2.resize(im, (int(im.shape[1] * 1.5), im.shape[0]), interpolation=cv2.INTER_LINEAR),
    "cropped": lambda im: im[:-240, :-320],
    "other-layout": lambda im: im,
}


def other_layout(ds, path: Path) -> Path:
    """A layout file of the dataset's patterns on another scene's section radius and marker size."""
    mine = (ds.config.sections.radius_mm, ds.config.markers.diameter_mm)
    radius, diameter = (300.0, 20.0) if mine[0] == 450.0 else (450.0, 30.0)   # another radius: the markers elsewhere
    cfg = ds.config
    cfg = replace(cfg, sections=replace(cfg.sections, radius_mm=radius), markers=replace(cfg.markers, diameter_mm=diameter))
    write_json_atomic(path, layout_record(cfg))
    return path


def measure(folder: Path, layout: Path, out: Path, weights: str | None) -> tuple[int, str, dict]:
    cmd = [sys.executable, "-m", "dockfactory", "measure", str(folder), "--layout", str(layout), "--out", str(out)]
    cmd += ["--weights", weights] if weights else []
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=1800)
    doc = json.loads((out / "measurements.json").read_text()) if (out / "measurements.json").is_file() else {}
    return p.returncode, p.stderr, doc


def judge(doc: dict, truth: dict) -> dict:
    """ok and beyond-U counts of a measurements document against the labels' poses."""
    ok, beyond, worst = 0, 0, []
    for rec in doc.get("images", []):
        if not rec.get("ok"):
            continue
        ok += 1
        t = truth[Path(rec["image"]).stem]
        z = {a: abs(rec["pose"][a] - t[a]) / rec["uncertainty"][a]["expanded"] for a in AXES}
        if max(z.values()) > 1.0:
            beyond += 1
            worst.append({"image": Path(rec["image"]).name, **{a: round(v, 2) for a, v in z.items()}})
    return {"ok": ok, "ok_beyond_U": beyond, "beyond": worst}


def probe(root: Path, frames: int, weights: str | None, work: Path) -> dict:
    ds = Dataset.open(root)
    ids = ds.frames(("test",))[:frames]
    truth = {fid: ds.labels[fid]["pose_b_in_d"] for fid in ids}
    layouts = {"mine": root / "layout.json", "other": other_layout(ds, work / "other_layout.json")}
    out = {"dataset": str(root), "version": ds.version_id, "frames": ids, "faults": {}}
    for name, fault in FAULTS.items():
        folder = work / name
        folder.mkdir()
        for fid in ids:
            cv2.imwrite(str(folder / f"{fid}.png"), fault(cv2.imread(str(root / "images" / f"{fid}.png"))))
        code, err, doc = measure(folder, layouts["other" if name == "other-layout" else "mine"], work / f"out_{name}", weights)
        row = {"exit": code, "traceback": "Traceback" in err, "images": len(ids), **judge(doc, truth),
               "failures": doc.get("failures")}
        out["faults"][name] = row
        print(f"{name:<13} exit {code}  ok {row['ok']}/{len(ids)}  ok beyond U {row['ok_beyond_U']}  "
              f"traceback {row['traceback']}  failures {row['failures']}", flush=True)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dataset", type=Path)
    ap.add_argument("--frames", type=int, default=8)
    ap.add_argument("--weights")
    ap.add_argument("--out", type=Path)
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        result = probe(args.dataset, args.frames, args.weights, Path(tmp))
    if args.out:
        write_json_atomic(args.out, result)
    bad = sum(r["traceback"] or r["ok_beyond_U"] > 0 for r in result["faults"].values())
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
