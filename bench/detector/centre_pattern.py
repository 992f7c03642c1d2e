"""The centres' fixed pattern per marker, and the pose bias it carries.

A pose bias that a converged render keeps (no sampling setting takes it away) must come from the
centres' errors that do not average out over frames. This bench looks for them per marker of the
layout: each refined centre's error (the detection's ``center_px`` minus the label's
``outline_centroid_px``, fully visible markers only) is expressed in the marker's own image frame
(``seam``: along the section axis's image direction, positive toward the other section; ``across``:
perpendicular to it), and averaged per marker id over the frames. Three figures:

- the pattern: each marker's mean error with its standard error, and the RMS of the means;
- its stability: the pattern of the first half of the frames against the second's (correlation of
  the per-marker means, chi-square of their differences over their standard errors: about the
  degrees of freedom when the pattern is the same in both halves);
- the pose bias it carries, out of sample: the test frames solved again with every matched centre
  moved to its label's outline centroid plus the marker's mean error measured on the *other* half
  of the frames (``pattern``), and plus its own error minus that mean (``rest``); mean error and
  its t of X, Y and alpha for the detections as they are, ``pattern`` and ``rest``.

Inputs: datasets whose detections lie beside them as ``DIR.detections_bench.json`` (what
bench.render.marker_sampling writes), or ``dockfactory run`` folders (``RUN/dataset`` with
``RUN/detections.json``); ``DIR+DIR`` pools frames of several (e.g. 40 + 80 frames of one scene).

Run: python -m bench.detector.centre_pattern [NAME=]DIR[+DIR...] ... [--json OUT]
"""
from __future__ import annotations

import argparse
import copy
import json
from pathlib import Path

import numpy as np
from bench.marker_match import nearest_marker

from dockfactory.core.geometry import project_points
from dockfactory.core.io import write_json_atomic
from dockfactory.eval.pose_metrics import pose_error
from dockfactory.eval.solve_frames import solve_dataset
from dockfactory.generator.datasets.reader import Dataset

MATCH_PX = 3.0
FULLY_VISIBLE = 0.99
COMPONENTS = ("x", "y", "alpha")


def open_source(path: Path) -> tuple[Dataset, dict]:
    """(dataset, detections document) of a dataset folder with ``DIR.detections_bench.json``
    beside it, or of a run folder (``dataset/`` + ``detections.json``). Raises
    FileNotFoundError naming what is missing."""
    if (path / "detections.json").exists() and (path / "dataset").exists():
        return Dataset.open(path / "dataset"), json.loads((path / "detections.json").read_text())
    dets = path.parent / f"{path.name}.detections_bench.json"
    if not dets.exists():
        raise FileNotFoundError(f"{path}: neither a run folder nor a dataset with {dets.name} beside it")
    return Dataset.open(path), json.loads(dets.read_text())


def axis_frame(label: dict, marker: dict) -> tuple[np.ndarray, np.ndarray]:
    """(seam, across) unit vectors in the image at the marker: the image direction of the D
    frame's +x axis (the section axis) at the marker's centre, turned toward the other section
    (A's markers look to +x, B's to -x), and its perpendicular."""
    c = np.asarray(marker["center_d_mm"], dtype=float)
    uv, _ = project_points(label["camera"]["K"], label["camera"]["cam_from_d"], np.stack([c, c + [1.0, 0.0, 0.0]]))
    u = uv[1] - uv[0]
    u /= np.linalg.norm(u)
    seam = u if marker["section"] == "A" else -u
    return seam, np.array([-seam[1], seam[0]])


def matched_centres(ds: Dataset, dets: dict) -> list[dict]:
    """One row per refined detection matched (within MATCH_PX) to a fully visible marker:
    frame, index in the frame's list, marker id, outline centroid, local frame and error."""
    rows = []
    for fid, frame_dets in sorted(dets["frames"].items()):
        label = ds.labels[fid]
        markers = [m for m in label["markers"] if m.get("visibility") == 2
                   and m.get("visible_fraction", 0.0) >= FULLY_VISIBLE]
        for k, det in enumerate(frame_dets):
            hit = nearest_marker(det, markers, MATCH_PX) if det.get("refined") else None
            if hit is None:
                continue
            err, marker = hit
            seam, across = axis_frame(label, marker)
            rows.append({"frame": fid, "k": k, "id": marker["id"], "split": label["spec"]["split"],
                         "centroid": np.asarray(marker["outline_centroid_px"], dtype=float),
                         "seam": seam, "across": across, "local": np.array([err @ seam, err @ across])})
    return rows


def pattern(rows: list[dict]) -> dict:
    """{marker id: (mean (2,), standard error (2,), n)} of the local errors (seam, across)."""
    by_id = {}
    for r in rows:
        by_id.setdefault(r["id"], []).append(r["local"])
    return {i: (np.mean(v, axis=0), np.std(v, axis=0, ddof=1) / np.sqrt(len(v)) if len(v) > 1
                else np.full(2, np.inf), len(v)) for i, v in sorted(by_id.items())}


def halves(rows: list[dict]) -> tuple[set, set]:
    """The frames split in two by their order (first half, second half)."""
    frames = sorted({r["frame"] for r in rows})
    return set(frames[: len(frames) // 2]), set(frames[len(frames) // 2:])


def stability(rows: list[dict]) -> dict:
    """The first half's pattern against the second's: correlation of the means, chi-square of
    their differences and its degrees of freedom (markers x 2 axes seen in both halves)."""
    first, _ = halves(rows)
    p1 = pattern([r for r in rows if r["frame"] in first])
    p2 = pattern([r for r in rows if r["frame"] not in first])
    ids = [i for i in p1 if i in p2 and p1[i][2] > 1 and p2[i][2] > 1]
    a = np.concatenate([p1[i][0] for i in ids])
    b = np.concatenate([p2[i][0] for i in ids])
    var = np.concatenate([p1[i][1] ** 2 + p2[i][1] ** 2 for i in ids])
    return {"correlation": float(np.corrcoef(a, b)[0, 1]), "chi2": float(np.sum((a - b) ** 2 / var)),
            "dof": len(a)}


def moved_detections(dets: dict, rows: list[dict], kind: str) -> dict:
    """A copy of ``dets`` with every matched centre moved to its outline centroid plus (kind
    "pattern") the marker's mean error over the other half of the frames, or plus (kind "rest")
    its own error minus that mean."""
    first, _ = halves(rows)
    other = {True: pattern([r for r in rows if r["frame"] not in first]),
             False: pattern([r for r in rows if r["frame"] in first])}
    out = copy.deepcopy(dets)
    for r in rows:
        mean = other[r["frame"] in first].get(r["id"], (np.zeros(2),))[0]
        local = mean if kind == "pattern" else r["local"] - mean
        centre = r["centroid"] + local[0] * r["seam"] + local[1] * r["across"]
        out["frames"][r["frame"]][r["k"]]["center_px"] = [float(centre[0]), float(centre[1])]
    return out


def pose_bias(ds: Dataset, dets: dict) -> dict:
    """{component: (errors of the solved test frames)} of ``dets`` solved by the shipped solver."""
    poses = solve_dataset(ds, splits=("test",), detections=dets)
    errs = {c: [] for c in COMPONENTS}
    for fid, rec in poses["frames"].items():
        if rec["ok"]:
            e = pose_error(rec["pose"], ds.labels[fid]["pose_b_in_d"])
            for c in COMPONENTS:
                errs[c].append(e[c])
    return errs


def bias_stats(errs: list[float]) -> dict:
    a = np.asarray(errs, dtype=float)
    return {"n": len(a), "mean": float(a.mean()), "rmse": float(np.sqrt(np.mean(a ** 2))),
            "t": float(a.mean() / (a.std(ddof=1) / np.sqrt(len(a))))}


def group_figures(paths: list[Path]) -> dict:
    """Pattern, stability and pose bias (as detected, pattern, rest) of the pooled sources."""
    sources = [open_source(p) for p in paths]
    rows = []
    for n, (ds, dets) in enumerate(sources):
        rows += [{**r, "frame": (n, r["frame"])} for r in matched_centres(ds, dets)]
    bias = {}
    for kind in ("detected", "pattern", "rest"):
        errs = {c: [] for c in COMPONENTS}
        for n, (ds, dets) in enumerate(sources):
            own = [{**r, "frame": r["frame"][1]} for r in rows if r["frame"][0] == n]
            doc = dets if kind == "detected" else moved_detections(dets, own, kind)
            for c, v in pose_bias(ds, doc).items():
                errs[c] += v
        bias[kind] = {c: bias_stats(v) for c, v in errs.items()}
    pat = pattern(rows)
    means = np.array([m for m, _, _ in pat.values()])
    return {"centres": len(rows), "frames": len({r["frame"] for r in rows}),
            "pattern": {i: {"mean_px": m.tolist(), "se_px": s.tolist(), "n": n} for i, (m, s, n) in pat.items()},
            "pattern_rms_px": float(np.sqrt(np.mean(np.sum(means ** 2, axis=1)))),
            "stability": stability(rows), "pose_bias": bias}


def print_group(name: str, g: dict) -> None:
    st = g["stability"]
    print(f"\n{name}: {g['centres']} centres on {g['frames']} frames; pattern RMS {g['pattern_rms_px']:.4f} px; "
          f"halves: correlation {st['correlation']:+.2f}, chi2 {st['chi2']:.1f} on {st['dof']}")
    print("  marker  seam / across mean px (se)")
    for i, p in g["pattern"].items():
        print(f"  {i:6} {p['mean_px'][0]:+.4f} ({p['se_px'][0]:.4f}) / {p['mean_px'][1]:+.4f} ({p['se_px'][1]:.4f})  n {p['n']}")
    for kind, b in g["pose_bias"].items():
        cells = "  ".join(f"{c} {b[c]['mean']:+.4f} (t {b[c]['t']:+.1f}, RMSE {b[c]['rmse']:.4f})" for c in COMPONENTS)
        print(f"  {kind:9} {cells}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("groups", nargs="+", help="[NAME=]DIR[+DIR...]")
    ap.add_argument("--json", type=Path)
    args = ap.parse_args(argv)
    out = {}
    for arg in args.groups:
        name, _, dirs = arg.rpartition("=")
        out[name or dirs] = group_figures([Path(p) for p in dirs.split("+")])
        print_group(name or dirs, out[name or dirs])
    if args.json:
        write_json_atomic(args.json, out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
