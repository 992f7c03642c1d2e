"""Bench of the model error in the covariance: RMS z = error / reported std of X, Y and alpha
on a rendered dataset, for the per-frame pinhole, the per-frame "auto" and the per-run
(``--self-calibrate sequence``) solves, with the lens prior off (the lens taken as known) and
on (the unestimated intrinsics marginalised, :mod:`solver.model_error`), and how many solves
the misfit test flags.

Input: a dataset folder and its detections (``dockfactory detect``), or ``--oracle SIGMA`` for
the exact centroids plus noise. Splits ``--splits`` (default test). ``--scale`` multiplies every
half-range of the lens prior (a sweep over several values shows how the figures depend on the
prior); ``--prior config`` takes the prior matched to the lens ranges the dataset's config draws
(:func:`eval.solve_frames.config_lens_prior`) instead of the default :class:`LensPrior`.

A lens error is the same for every frame of a camera unit, so an RMS z over frames is only as
certain as the number of units: each RMS z comes with a 90 % interval from a bootstrap over the
camera units (frames resampled by unit, 2,000 resamples, seed 0).

``--section-shift-from DATASET DETS`` adds the common offset of a section's centres
(solver.section_shift) measured on another dataset's test split (eval.section_shift), as a user
would measure it on frames of the camera class other than the ones judged.

Run: python -m bench.cli.model_error DATASET --detections DETS.json [--splits test train]
[--scale 1.0 0.5] [--prior default|config] [--section-shift-from OTHER OTHER_DETS] [--json OUT.json]
"""
from __future__ import annotations

import argparse
import json
import time
from dataclasses import asdict, replace

import numpy as np

from dockfactory.eval.pose_metrics import pose_error
from dockfactory.eval.section_shift import measure_section_shift
from dockfactory.eval.solve_frames import config_lens_prior, docking_options, solve_dataset
from dockfactory.eval.uncertainty import reported_std
from dockfactory.generator.datasets.reader import Dataset
from dockfactory.solver.options import LensPrior

METHODS = (("pinhole", "pinhole", None), ("auto", "auto", None), ("sequence", "auto", "sequence"))
COMPS = ("x", "y", "alpha")


def unit_interval(z: np.ndarray, units: np.ndarray, resamples: int = 2000) -> tuple[float, float]:
    """90 % percentile interval of the RMS of ``z`` (n,) when whole camera units (``units`` (n,))
    are resampled with replacement."""
    ids = np.unique(units)
    members = [np.flatnonzero(units == u) for u in ids]
    rng = np.random.default_rng(0)
    stats = []
    for _ in range(resamples):
        pick = np.concatenate([members[k] for k in rng.integers(0, len(ids), len(ids))])
        stats.append(np.sqrt(np.mean(np.square(z[pick]))))
    return float(np.quantile(stats, 0.05)), float(np.quantile(stats, 0.95))


def z_table(ds: Dataset, poses: dict) -> dict:
    """{component: RMS z, "<c>_90": its unit-bootstrap interval, "n", "units", "flagged",
    "rmse_<c>"} over the solved frames of ``poses``."""
    z, e, units, flagged = {c: [] for c in COMPS}, {c: [] for c in COMPS}, [], 0
    for fid, rec in poses["frames"].items():
        if not rec.get("ok"):
            continue
        err = pose_error(rec["pose"], ds.labels[fid]["pose_b_in_d"])
        std = reported_std(rec["covariance"])
        flagged += bool(rec.get("model_check", {}).get("warning"))
        units.append(int(ds.labels[fid]["spec"]["unit"]))
        for c in COMPS:
            z[c].append(err[c] / std[c])
            e[c].append(err[c])
    out = {c: float(np.sqrt(np.mean(np.square(z[c])))) for c in COMPS}
    out.update({f"{c}_90": unit_interval(np.array(z[c]), np.array(units)) for c in COMPS})
    out.update({f"rmse_{c}": float(np.sqrt(np.mean(np.square(e[c])))) for c in COMPS})
    out.update(n=len(z["x"]), units=len(set(units)), flagged=flagged)
    return out


def run(ds, dets, oracle, splits, lens: LensPrior, shift=None) -> dict:
    """{method: z_table} of the three solves under ``lens`` and the section shift ``shift``
    ((x, y) px or None: the detections' own)."""
    out = {}
    for name, model, selfcal in METHODS:
        poses = solve_dataset(ds, splits, detections=dets, oracle_sigma_px=oracle, camera_model=model,
                              self_calibrate=selfcal, lens=lens, section_shift_px=shift)
        out[name] = z_table(ds, poses)
    return out


def _shift_from(dataset, detections) -> dict:
    """The section shift (eval.section_shift) measured on the test split of another dataset with
    its detections, printed."""
    other = Dataset.open(dataset, full=False)
    block = measure_section_shift(other, json.load(open(detections)), ("test",))
    print(f"section shift from {dataset} ({other.version_id}, {block['groups']} sections): "
          f"{block['shift_axis_px']} px")
    return {"dataset": str(dataset), "dataset_version": other.version_id, **block}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dataset")
    ap.add_argument("--detections")
    ap.add_argument("--oracle", type=float)
    ap.add_argument("--splits", nargs="+", default=["test"])
    ap.add_argument("--scale", type=float, nargs="+", default=[1.0])
    ap.add_argument("--prior", choices=("default", "config"), default="default")
    ap.add_argument("--section-shift-from", nargs=2, metavar=("DATASET", "DETECTIONS"),
                    help="measure the section shift on another dataset's test split (eval.section_shift)")
    ap.add_argument("--json")
    a = ap.parse_args(argv)
    ds = Dataset.open(a.dataset, full=False)
    dets = json.load(open(a.detections)) if a.detections else None
    shift = _shift_from(*a.section_shift_from) if a.section_shift_from else None
    base = docking_options(None).lens if a.prior == "default" else config_lens_prior(ds.config)
    print(f"lens prior ({a.prior}): {asdict(base)}")
    t0, result = time.time(), {"dataset_version": ds.version_id, "splits": a.splits, "prior": a.prior,
                               "lens_prior": asdict(base), "section_shift": shift, "rows": []}
    for scale in (0.0, *a.scale):
        lens = replace(base, marginalise=scale > 0, pp_fraction=base.pp_fraction * (scale or 1),
                       k1=base.k1 * (scale or 1), k2=base.k2 * (scale or 1), p=base.p * (scale or 1))
        for name, t in run(ds, dets, a.oracle, tuple(a.splits), lens, shift and shift["shift_axis_px"]).items():
            result["rows"].append({"scale": scale, "method": name, **t})
            zs = "  ".join(f"{c} {t[c]:.2f} ({t[c + '_90'][0]:.2f}-{t[c + '_90'][1]:.2f})" for c in COMPS)
            print(f"scale {scale:4.2f} {name:9s} n {t['n']:3d} units {t['units']:2d} flagged {t['flagged']:3d}  "
                  f"RMS z {zs}  RMSE X {t['rmse_x']:.3f} Y {t['rmse_y']:.3f} alpha {t['rmse_alpha']:.4f}",
                  flush=True)
    print(f"dataset {ds.version_id}, {time.time() - t0:.0f} s")
    if a.json:
        with open(a.json, "w") as fh:
            json.dump(result, fh, indent=1)


if __name__ == "__main__":
    main()
