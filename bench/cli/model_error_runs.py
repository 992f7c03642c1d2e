"""Why a docking run's Y is under-covered from detections: the per-run solve's errors taken apart.

    python -m bench.cli.model_error_runs DATASET --detections DETS.json units
    python -m bench.cli.model_error_runs DATASET --detections DETS.json parts --out-dir DIR
    python -m bench.cli.model_error_runs DATASET --detections DETS.json no-aberration --out-dir DIR
    python -m bench.cli.model_error_runs DATASET --detections DETS.json section-shift --tau 0.04 0.08
    python -m bench.cli.model_error_runs DATASET --detections DETS.json gate --alpha 0.001 0.05 1
    python -m bench.cli.model_error_runs DATASET --detections DETS.json length --length 0.1 0.19 0.38
    python -m bench.cli.model_error_runs DATASET --detections DETS.json correlation

- ``units``: per camera unit, Y RMSE, median reported std and RMS z of three solves: per run with
  the config's lens prior (what the judge does), per run and per frame through each frame's true
  camera (the label's principal point and distortion: no lens left to model).
- ``parts``: writes three detection files beside each other, each detected centre replaced by the
  label's outline centroid plus one part of its error: ``persistent`` (its mean over the run's
  frames, per marker), ``transient`` (the rest) and ``no-section-mean`` (the error less its
  section's mean over the run); solve them with bench/cli/model_error.py.
- ``no-aberration``: the detections with each centre's lateral chromatic aberration undone (the
  label's red / blue magnification about the principal point, in undistorted pixels).
- ``section-shift``: per-run RMS z when the per-run covariance also carries one common shift per
  section and axis over the whole run (prior std ``--tau`` px; ``solver.section_shift``); a shift
  that a run's residuals cannot show, since the section's pose absorbs it.
- ``gate``: per-run RMS z with the run-bias term counted at other significance levels
  (``solver.model_error.BIAS_ALPHA``; 1: whenever its estimate is positive).
- ``length``: per-run RMS z with other correlation lengths of the run-bias field
  (``solver.model_error.BIAS_LENGTH``, image diagonals).
- ``correlation``: how the detector's centre errors correlate between two markers of a section in
  one frame (by image distance) and for one marker over a run's frames: what the run-bias
  field's length and persistence rest on.

Figures and their reading: results/README.md, "Per-run Y, taken apart".
"""
from __future__ import annotations

import argparse
import copy
import json
from pathlib import Path

import numpy as np

from dockfactory.core.distortion import distort_pixels, undistort_pixels
from dockfactory.core.io import write_json_atomic
from dockfactory.eval.pose_metrics import pose_error
from dockfactory.eval.solve_frames import config_lens_prior, docking_runs, solve_dataset
from dockfactory.eval.uncertainty import reported_std
from dockfactory.generator.datasets.reader import Dataset


def frame_detections(dets: dict, fid: str) -> list[dict]:
    v = dets["frames"][fid]
    return v["detections"] if isinstance(v, dict) else v


def matches(ds: Dataset, dets: dict, fid: str) -> list[tuple[int, str, np.ndarray]]:
    """(detection index, marker id, outline centroid (2,)) of each fully visible marker with a
    detection of its class within 3 px (the nearest)."""
    found, out = frame_detections(dets, fid), []
    for m in ds.labels[fid]["markers"]:
        if m.get("visibility") != 2:
            continue
        truth = np.array(m["outline_centroid_px"])
        near = [i for i, d in enumerate(found) if d["class_id"] == m["class_id"]
                and np.hypot(*(np.array(d["center_px"]) - truth)) < 3.0]
        if near:
            out.append((min(near, key=lambda i: np.hypot(*(np.array(found[i]["center_px"]) - truth))), m["id"], truth))
    return out


def write_parts(ds: Dataset, dets: dict, out_dir: Path) -> None:
    """The ``parts`` mode: three detection files in ``out_dir``."""
    parts = {name: copy.deepcopy(dets) for name in ("persistent", "transient", "no-section-mean")}
    section_means = []
    for group in docking_runs(ds, ds.frames("test")):
        seen = {fid: matches(ds, dets, fid) for fid in group}
        err = {(fid, i): np.array(frame_detections(dets, fid)[i]["center_px"]) - t
               for fid, rows in seen.items() for i, _, t in rows}
        per_marker: dict = {}
        for fid, rows in seen.items():
            for i, mid, _ in rows:
                per_marker.setdefault(mid, []).append(err[(fid, i)])
        mean = {mid: np.mean(v, axis=0) for mid, v in per_marker.items()}
        section = {s: np.mean([e for mid, v in per_marker.items() if mid[0] == s for e in v], axis=0)
                   for s in {mid[0] for mid in per_marker}}
        section_means += list(section.values())
        for fid, rows in seen.items():
            for i, mid, t in rows:
                e = err[(fid, i)]
                for name, value in (("persistent", t + mean[mid]), ("transient", t + e - mean[mid]),
                                    ("no-section-mean", t + e - section[mid[0]])):
                    frame_detections(parts[name], fid)[i]["center_px"] = [float(v) for v in value]
    rms = np.sqrt(np.mean(np.square(section_means), axis=0))
    print(f"mean centre error per run and section: RMS x {rms[0]:.3f} y {rms[1]:.3f} px over {len(section_means)}")
    for name, doc in parts.items():
        write_json_atomic(out_dir / f"dets_{name}.json", doc)
        print(out_dir / f"dets_{name}.json")


def without_aberration(ds: Dataset, dets: dict) -> dict:
    """``dets`` with each centre moved to where the green image would have put it."""
    out = copy.deepcopy(dets)
    for fid in out["frames"]:
        cam = ds.labels[fid]["camera"]
        pp, f, dist = tuple(cam["principal_point"]), cam["focal_px"], cam.get("distortion") or [0.0] * 5
        for d in frame_detections(out, fid):
            scale = cam["aberration_scale"]["red" if d["class_id"] == 0 else "blue"]
            u = undistort_pixels(np.array([d["center_px"]]), f, pp, dist)
            d["center_px"] = [float(v) for v in distort_pixels(np.array(pp) + (u - pp) / scale, f, pp, dist)[0]]
    return out


SOLVES = {"run, config prior": dict(camera_model="auto", self_calibrate="sequence"),
          "run, true camera": dict(camera_model="pinhole", self_calibrate="sequence", true_camera=True),
          "frame, true camera": dict(camera_model="pinhole", true_camera=True)}


def unit_table(ds: Dataset, dets: dict) -> str:
    """Markdown: per unit and solve, Y RMSE (mm), median reported std (mm) and RMS z; last row all."""
    rows: dict = {}
    for name, opts in SOLVES.items():
        lens = None if opts.get("true_camera") else config_lens_prior(ds.config)
        poses = solve_dataset(ds, ("test",), detections=dets, lens=lens, **opts)
        for fid, rec in poses["frames"].items():
            if rec.get("ok"):
                e, s = pose_error(rec["pose"], ds.labels[fid]["pose_b_in_d"])["y"], reported_std(rec["covariance"])["y"]
                rows.setdefault(name, []).append((ds.labels[fid]["spec"]["unit"], e, s))
    lines = ["| unit | " + " | ".join(f"{n}: Y RMSE / std / RMS z" for n in SOLVES) + " |",
             "| --- |" + " --- |" * len(SOLVES)]
    units = sorted({u for v in rows.values() for u, _, _ in v})
    for u in [*units, "all"]:
        cells = []
        for name in SOLVES:
            v = np.array([(e, s) for uu, e, s in rows[name] if u == "all" or uu == u])
            cells.append(f"{np.sqrt(np.mean(v[:, 0] ** 2)):.3f} / {np.median(v[:, 1]):.3f} / "
                         f"{np.sqrt(np.mean((v[:, 0] / v[:, 1]) ** 2)):.2f}")
        lines.append(f"| {u} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def section_shift_z(ds: Dataset, dets: dict, taus) -> None:
    """Prints per-run RMS z X / Y / alpha with a common per-section shift of std tau (both axes)
    in the covariance (``solver.section_shift``, one shift per section over the run)."""
    for tau in taus:
        print(f"tau {tau:.3f} px: per-run RMS z X / Y / alpha {run_z(ds, dets, (tau, tau))}")


def run_z(ds: Dataset, dets: dict, shift=None) -> str:
    """Per-run RMS z X / Y / alpha of the judge's per-run solve (config prior; ``shift`` the
    section shift (x, y) px, None: the detections')."""
    poses = solve_dataset(ds, ("test",), detections=dets, lens=config_lens_prior(ds.config), section_shift_px=shift,
                          **SOLVES["run, config prior"])
    z = np.array([[pose_error(r["pose"], ds.labels[f]["pose_b_in_d"])[c] / reported_std(r["covariance"])[c]
                   for c in ("x", "y", "alpha")] for f, r in poses["frames"].items() if r.get("ok")])
    return " / ".join(f"{v:.2f}" for v in np.sqrt(np.mean(z ** 2, 0)))


def _sweep(module, name: str, values, label: str, ds: Dataset, dets: dict) -> None:
    """Prints per-run RMS z with ``module``'s constant ``name`` set to each of ``values``."""
    keep = getattr(module, name)
    for value in values:
        setattr(module, name, value)
        try:
            print(f"{label.format(value)}: per-run RMS z X / Y / alpha {run_z(ds, dets)}")
        finally:
            setattr(module, name, keep)


def gate_z(ds: Dataset, dets: dict, levels) -> None:
    """Prints per-run RMS z with the run-bias term's significance level (``BIAS_ALPHA``) set to
    each of ``levels`` (1: counted whenever its estimate is positive)."""
    import dockfactory.solver.model_error as me
    _sweep(me, "BIAS_ALPHA", levels, "bias counted at p < {:g}", ds, dets)


def length_z(ds: Dataset, dets: dict, lengths) -> None:
    """Prints per-run RMS z with the run-bias field's correlation length (``BIAS_LENGTH``, image
    diagonals) set to each of ``lengths``."""
    import dockfactory.solver.sequence as sq
    _sweep(sq, "BIAS_LENGTH", lengths, "bias length {:g} diagonals", ds, dets)


CORRELATION_BINS_PX = (0, 100, 200, 400, 100000)
CLIP_PX = 0.8   # centre errors beyond this (gross ones) left out of the correlations


def correlation_table(rows) -> str:
    """Markdown: the correlation of centre errors, per axis, between two markers of one section in
    one frame by their image distance (CORRELATION_BINS_PX), and of one marker over two frames of
    one docking run. ``rows``: (frame key, run key or None, marker id, truth (2,) px, error (2,)
    px) per matched centre; errors beyond CLIP_PX (gross ones) are left out."""
    rows = [r for r in rows if np.all(np.abs(r[4]) < CLIP_PX)]
    by_frame, by_marker = {}, {}
    for frame, run, mid, truth, err in rows:
        by_frame.setdefault(frame, []).append((mid, truth, err))
        if run is not None:
            by_marker.setdefault((run, mid), []).append(err)
    pairs = {}
    for found in by_frame.values():
        for a, (ma, ta, ea) in enumerate(found):
            for mb, tb, eb in found[a + 1:]:
                if ma[0] == mb[0]:
                    k = int(np.searchsorted(CORRELATION_BINS_PX, np.hypot(*(ta - tb)))) - 1
                    pairs.setdefault(k, []).append(ea * eb)
    var = np.mean(np.square([r[4] for r in rows]), axis=0)
    lines = ["| pairs | n | x | y |", "| --- | --- | --- | --- |"]
    for k in sorted(pairs):
        c = np.mean(pairs[k], axis=0) / var
        lines.append(f"| same section, {CORRELATION_BINS_PX[k]}-{CORRELATION_BINS_PX[k + 1]} px | {len(pairs[k])} "
                     f"| {c[0]:.2f} | {c[1]:.2f} |")
    same = [ea * eb for e in by_marker.values() for i, ea in enumerate(e) for eb in e[i + 1:]]
    if same:
        c = np.mean(same, axis=0) / var
        lines.append(f"| one marker, two frames of a run | {len(same)} | {c[0]:.2f} | {c[1]:.2f} |")
    return "\n".join(lines) + f"\n\ncentre error RMS x / y {np.sqrt(var[0]):.3f} / {np.sqrt(var[1]):.3f} px"


def centre_correlations(ds: Dataset, dets: dict) -> str:
    """:func:`correlation_table` of a dataset's detections (detected centre minus the label's
    outline centroid; runs from the labels' unit and run)."""
    rows = []
    for fid in ds.frames(("train", "val", "test")):
        if fid not in dets["frames"]:
            continue
        found, spec = frame_detections(dets, fid), ds.labels[fid]["spec"]
        run = (spec.get("unit", 0), spec["run"]) if spec.get("run", -1) >= 0 else None
        rows += [(fid, run, mid, truth, np.array(found[i]["center_px"]) - truth) for i, mid, truth in matches(ds, dets, fid)]
    return correlation_table(rows)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dataset")
    ap.add_argument("--detections", required=True)
    ap.add_argument("mode", choices=("units", "parts", "no-aberration", "section-shift", "gate", "length",
                                     "correlation"))
    ap.add_argument("--out-dir", default=".")
    ap.add_argument("--tau", type=float, nargs="+", default=[0.0, 0.04, 0.08])
    ap.add_argument("--alpha", type=float, nargs="+", default=[0.001, 0.05, 1.0])
    ap.add_argument("--length", type=float, nargs="+", default=[0.05, 0.1, 0.19, 0.38])
    a = ap.parse_args(argv)
    ds = Dataset.open(a.dataset, full=False)
    dets = json.loads(Path(a.detections).read_text())
    if a.mode == "units":
        print(unit_table(ds, dets))
    elif a.mode == "parts":
        write_parts(ds, dets, Path(a.out_dir))
    elif a.mode == "no-aberration":
        write_json_atomic(Path(a.out_dir) / "dets_no_aberration.json", without_aberration(ds, dets))
        print(Path(a.out_dir) / "dets_no_aberration.json")
    elif a.mode == "gate":
        gate_z(ds, dets, a.alpha)
    elif a.mode == "length":
        length_z(ds, dets, a.length)
    elif a.mode == "correlation":
        print(centre_correlations(ds, dets))
    else:
        section_shift_z(ds, dets, a.tau)
    print(f"dataset {ds.version_id}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
