"""The measured RMSE over the Cramer-Rao bound, pooled over the test frames of several runs.

The acceptance report prints each localization component's RMSE over the RMS of its frames'
bounds (eval.evaluate.bound_ratios: the disc noise model's bound, and the isotropic one) with the
interval the frame count allows. On a short run (the demo: 9 test frames) a ratio under 1 is not
decided; this pools the frames of several runs of the same kind (``dockfactory run`` work folders)
so that it is. A ratio whose interval lies under 1 is a measured error below the physical bound: a
bound that is too wide (the noise it assumes) or errors that are not independent.

Per group it also prints what the bound assumed: the RMS of the frames' ``sigma_px`` (isotropic)
and ``sigma_disc_px`` (the disc model's per-axis noise), beside the run's measured centre noise.

Inputs: run folders holding ``eval/frames.csv`` (and ``eval/metrics.json``); a group is
``DIR[+DIR...]`` (pooled), optionally named ``NAME=DIR+DIR``. Rows: the test split's solved frames.

Run: python -m bench.solver.bound_ratio [NAME=]RUN[+RUN...] ... [--json OUT]
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from dockfactory.core.io import write_json_atomic
from dockfactory.eval.acceptance import COMPONENTS
from dockfactory.eval.evaluate import bound_ratios
from dockfactory.eval.pose_metrics import error_stats
from dockfactory.eval.report.document import read_rows


def solved_test_rows(run: Path) -> list[dict]:
    """The solved test frames of one run's ``eval/frames.csv``, typed by the report's reader
    (eval.report.document.read_rows: DatasetError naming the file, line and column on bad input)."""
    return [r for r in read_rows(run / "eval") if r["split"] == "test" and r["ok"]]


def group_ratios(runs: list[Path]) -> dict:
    """Pooled ratios of one group: {"frames", "disc": bound_ratios, "isotropic": bound_ratios,
    "sigma_iso_px", "sigma_disc_px", "centre_noise_px": [each run's measured value]}."""
    rows = [r for run in runs for r in solved_test_rows(run)]
    overall = {c: error_stats([r[f"err_{c}"] for r in rows]) for c in COMPONENTS}
    noise = []
    for run in runs:
        m = json.loads((run / "eval" / "metrics.json").read_text())
        noise.append(m.get("centre_noise", {}).get("used", {}).get("value"))
    def rms(key):
        v = [r[key] for r in rows if r.get(key) is not None]
        return float(np.sqrt(np.mean(np.square(v)))) if v else None
    return {"frames": len(rows), "disc": bound_ratios(rows, overall, "crb"),
            "isotropic": bound_ratios(rows, overall, "crb_iso"),
            "sigma_iso_px": rms("sigma_px"), "sigma_disc_px": rms("sigma_disc_px"), "centre_noise_px": noise}


def _parse_group(arg: str) -> tuple[str, list[Path]]:
    name, _, dirs = arg.rpartition("=")
    paths = [Path(p) for p in dirs.split("+")]
    return (name or dirs), paths


def print_table(name: str, g: dict) -> None:
    print(f"\n{name}: {g['frames']} solved test frames; bound's noise: isotropic {g['sigma_iso_px']} px, "
          f"disc {g['sigma_disc_px']} px; runs' measured centre noise {g['centre_noise_px']}")
    print(f"{'':8}{'RMSE':>10}{'bound':>10}{'ratio':>8}{'95 %':>14}{'iso bound':>11}{'ratio':>8}")
    for c in COMPONENTS:
        d, i = g["disc"].get(c), g["isotropic"].get(c, {})
        if not d:
            continue
        iso = f"{i['bound_rms']:>11.4f}{i['ratio']:>8.2f}" if i else ""
        print(f"{c:8}{d['measured_rmse']:>10.4f}{d['bound_rms']:>10.4f}{d['ratio']:>8.2f}"
              f"{d['ratio_low']:>7.2f}-{d['ratio_high']:<6.2f}{iso}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("groups", nargs="+", help="[NAME=]RUN[+RUN...]: run folders pooled")
    ap.add_argument("--json", type=Path, help="write every group's figures here")
    args = ap.parse_args(argv)
    out = {}
    for arg in args.groups:
        name, runs = _parse_group(arg)
        out[name] = {"runs": [str(r) for r in runs], **group_ratios(runs)}
        print_table(name, out[name])
    if args.json:
        write_json_atomic(args.json, out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
