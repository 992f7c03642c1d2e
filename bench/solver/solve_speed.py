"""Speed of ``solve_docking`` on detections (issue 11, section 2, ``measure``): identification +
joint fit + suspects + eccentricity per frame, single-threaded, against the 15 ms target.

Inputs (what a detector gives: class + refined centre + box, no id):
- ``synthetic``: ``--frames`` docking scenes of solver/synthetic.py (default layout, 1280 x 960,
  ideal pinhole, principal point at the image centre), frame k drawn from
  ``default_rng([seed, k])``: Gaussian centre noise with sigma uniform in 0.1-0.3 px; each
  marker missing with probability 5 % (a section keeps >= 5); 0 spurious detections in 75 %
  of frames, 1 in 20 %, 2 in 5 % (uniform in the image, > 15 px from any marker, random
  class); a swapped class label in 3 % of frames; boxes = the true projected outline's box
  (+- 0.3 px), and in 5 % of the detections a partly hidden marker (box cut to 60-80 % of its
  width or height, centre moved by a third of the cut, ``refined`` False half of the time);
- ``hard`` (``--hard N``, for equivalence checks): the identification benchmark's harder frames
  (sigma 0.5 px, 15 % missing, 0-3 spurious, 0-2 swapped classes; see :func:`hard_frame`);
- ``real``: the detections of ``out/detector_run/detections.json`` (scores >= MIN_SCORE, as
  ``dockfactory solve`` reads them) on the dataset they were made on (``out/detector_run/
  dataset``, else ``out/detector``), principal point at the image centre, if the folders exist.
Both call ``solve_docking(markers, pp, detections=(cls, uv), boxes=..., refined=...)`` with the
defaults of ``dockfactory solve`` (sigma_px None, camera_model "pinhole").

Timing: wall time (perf_counter) per frame, each frame solved ``--repeats`` times (the minimum
kept: the cores are shared with other work), after a warm-up on the first five frames.
OMP / MKL / OPENBLAS threads are set to 1 before numpy is imported: BLAS threads cost more
than they give on these tiny matrices. Stages: ``identification`` (identify_markers), ``suspects``
(leave_out_suspects, with its refit), ``eccentricity`` (eccentricity_corrected: the predicted
offsets), ``disc noise`` (with_disc_noise: the covariance of the disc-shaped noise model, when the
robust refit is off), ``robust refit`` (robust_refit: the reweighted last fit and its covariance) are
timed by wrapping the functions the pipeline calls; ``fit`` is the rest of the frame (input
checks, the first joint fit, the eccentricity refit, packaging of the result). The load average is printed before
and after.

Equivalence (before / after a change of the solver): ``--dump OUT.npz`` stores every frame's
outcome (marker ids, swapped, inliers, d_from_b, focal, covariance, or the exception's class);
``--compare REF.npz`` compares the current run against such a file (ids identical; pose, focal
and covariance differences reported). ``--solver-src DIR`` runs the solver package found in
``DIR`` (a folder holding ``solver/``, e.g. ``git archive HEAD solver | tar -x -C DIR``)
instead of the installed one, so that the old code can be timed and dumped on the same inputs.

Run: python -m bench.solver.solve_speed [--frames 200] [--real-frames N] [--repeats 3] [--seed 0]
[--json OUT.json] [--dump OUT.npz] [--compare REF.npz] [--solver-src DIR] [--profile]
"""
from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import importlib.util  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
TARGET_MS = 15.0
STAGES = ("identification", "fit", "suspects", "eccentricity", "disc noise", "robust refit")


def use_solver_source(src: Path) -> None:
    """Make ``dockfactory.solver`` the package in ``src / "solver"`` (before any import of it)."""
    import dockfactory
    pkg = src / "solver"
    spec = importlib.util.spec_from_file_location(
        "dockfactory.solver", pkg / "__init__.py", submodule_search_locations=[str(pkg)])
    mod = importlib.util.module_from_spec(spec)
    sys.modules["dockfactory.solver"] = mod
    dockfactory.solver = mod
    spec.loader.exec_module(mod)


# ------------------------------------------------------------------------------------ inputs

def _outline_box(marker, cam, focal, pp):
    from dockfactory.solver.outline import projected_outline
    uv = projected_outline(marker, cam, focal, pp)[0]
    return np.array([uv[:, 0].min(), uv[:, 1].min(), uv[:, 0].max(), uv[:, 1].max()])


def _hide_part(rng, box, centre):
    """A partly hidden marker: the box cut to 60-80 % along one axis, the centre moved by a
    third of the cut toward the visible part."""
    box, centre = box.copy(), centre.copy()
    axis, frac = int(rng.integers(2)), rng.uniform(0.6, 0.8)
    cut = (1.0 - frac) * (box[axis + 2] - box[axis])
    if rng.random() < 0.5:
        box[axis] += cut
        centre[axis] += cut / 3.0
    else:
        box[axis + 2] -= cut
        centre[axis] -= cut / 3.0
    return box, centre


def synthetic_frame(seed: int, k: int, layout):
    """(name, markers, pp, cls, uv, boxes, refined, truth ids) of synthetic frame ``k``."""
    from dockfactory.solver.synthetic import docking_scene
    rng = np.random.default_rng([seed, k])
    sc = docking_scene(rng, markers=layout)
    cams = {"A": sc.cam_from_d, "B": sc.cam_from_b}
    n = len(layout)
    uv = np.vstack([sc.uv_a, sc.uv_b]) + rng.uniform(0.1, 0.3) * rng.standard_normal((n, 2))
    cls = np.array([0 if m.section == "A" else 1 for m in layout])
    boxes = np.array([_outline_box(m, cams[m.section], sc.focal_px, sc.principal_point)
                      for m in layout]) + rng.uniform(-0.3, 0.3, (n, 4))
    refined = np.ones(n, dtype=bool)
    for j in np.flatnonzero(rng.random(n) < 0.05):
        boxes[j], uv[j] = _hide_part(rng, boxes[j], uv[j])
        refined[j] = rng.random() >= 0.5
    while True:
        keep = rng.random(n) >= 0.05
        if keep[cls == 0].sum() >= 5 and keep[cls == 1].sum() >= 5:
            break
    if rng.random() < 0.03:
        j = rng.choice(np.flatnonzero(keep))
        cls[j] = 1 - cls[j]
    n_sp = int(rng.choice(3, p=[0.75, 0.20, 0.05]))
    spur = []
    while len(spur) < n_sp:
        q = rng.uniform([0.0, 0.0], sc.image_size)
        if np.min(np.linalg.norm(uv - q, axis=1)) > 15.0:
            spur.append(q)
    half = rng.uniform(5.0, 12.0, (n_sp, 2))
    sp = np.array(spur).reshape(-1, 2)
    truth = [m.id for m, ok in zip(layout, keep) if ok] + [None] * n_sp
    return (f"syn{k:04d}", layout, sc.image_centre, np.concatenate([cls[keep],
            rng.integers(0, 2, n_sp)]), np.vstack([uv[keep], sp]),
            np.vstack([boxes[keep], np.hstack([sp - half, sp + half])]),
            np.concatenate([refined[keep], np.ones(n_sp, dtype=bool)]), truth)


def hard_frame(seed: int, k: int, layout):
    """A frame of the identification benchmark's harder kind (bench/solver/solver_bench.py): sigma
    0.5 px, each marker missing with probability 15 % (a section keeps >= 5), k % 3 swapped
    class labels and k % 4 spurious detections; no boxes. Drawn from
    ``default_rng([seed, 888, k])``."""
    from dockfactory.solver.synthetic import docking_scene
    rng = np.random.default_rng([seed, 888, k])
    sc = docking_scene(rng, markers=layout)
    n = len(layout)
    uv = np.vstack([sc.uv_a, sc.uv_b]) + 0.5 * rng.standard_normal((n, 2))
    cls = np.array([0 if m.section == "A" else 1 for m in layout])
    while True:
        keep = rng.random(n) >= 0.15
        if keep[cls == 0].sum() >= 5 and keep[cls == 1].sum() >= 5:
            break
    for j in rng.choice(np.flatnonzero(keep), size=k % 3, replace=False):
        cls[j] = 1 - cls[j]
    spur = []
    while len(spur) < k % 4:
        q = rng.uniform([0.0, 0.0], sc.image_size)
        if np.min(np.linalg.norm(uv - q, axis=1)) > 15.0:
            spur.append(q)
    pts = np.vstack([uv[keep]] + ([np.array(spur)] if spur else []))
    classes = np.concatenate([cls[keep], rng.integers(0, 2, len(spur))])
    truth = [m.id for m, ok in zip(layout, keep) if ok] + [None] * len(spur)
    return f"hard{k:04d}", layout, sc.image_centre, classes, pts, None, None, truth


def real_frames(limit: int | None):
    """Frames of out/detector_run/detections.json (empty when the folders are missing)."""
    from dockfactory.core.names import MIN_SCORE
    from dockfactory.generator.datasets.reader import Dataset
    det_path = ROOT / "out" / "detector_run" / "detections.json"
    roots = [ROOT / "out" / "detector_run" / "dataset", ROOT / "out" / "detector"]
    root = next((r for r in roots if r.is_dir()), None)
    if not det_path.is_file() or root is None:
        return [], "no real detections (out/detector_run/detections.json or its dataset)"
    ds = Dataset.open(root, full=False)
    dets = json.loads(det_path.read_text())
    markers = ds.markers()
    pp = np.array([(ds.config.image.width - 1) / 2.0, (ds.config.image.height - 1) / 2.0])
    out = []
    for fid in sorted(dets["frames"])[:limit]:
        keep = [d for d in dets["frames"][fid] if d.get("score", 1.0) >= MIN_SCORE]
        cls = np.array([d["class_id"] for d in keep], dtype=int)
        uv = np.array([d["center_px"] for d in keep], dtype=float).reshape(-1, 2)
        boxes = np.array([d["bbox_px"] for d in keep], dtype=float).reshape(-1, 4) \
            if all("bbox_px" in d for d in keep) else None
        refined = np.array([bool(d["refined"]) for d in keep]) \
            if all("refined" in d for d in keep) else None
        out.append((f"real{fid}", markers, pp, cls, uv, boxes, refined, None))
    return out, f"{len(out)} frames of {det_path.relative_to(ROOT)} on {root.relative_to(ROOT)}" \
        f" (dataset {ds.version_id})"


# ------------------------------------------------------------------------------------ timing

class StageClock:
    """Wraps the pipeline's stage functions in :mod:`solver.docking` to time them."""

    NAMES = {"identify_markers": "identification", "leave_out_suspects": "suspects",
             "eccentricity_corrected": "eccentricity", "with_disc_noise": "disc noise",
             "robust_refit": "robust refit"}

    def __init__(self):
        import dockfactory.solver.docking as docking
        self.spent = dict.fromkeys(STAGES, 0.0)
        for fn_name, stage in self.NAMES.items():
            setattr(docking, fn_name, self._wrap(getattr(docking, fn_name), stage))

    def _wrap(self, fn, stage):
        def timed(*args, **kwargs):
            t0 = time.perf_counter()
            try:
                return fn(*args, **kwargs)
            finally:
                self.spent[stage] += time.perf_counter() - t0
        return timed

    def reset(self):
        for k in self.spent:
            self.spent[k] = 0.0


def solve_frame(frame):
    """(result or exception) of one frame."""
    from dockfactory.solver import SolverError, solve_docking
    _, markers, pp, cls, uv, boxes, refined, _ = frame
    try:
        return solve_docking(markers, pp, detections=(cls, uv), boxes=boxes, refined=refined)
    except SolverError as exc:
        return exc


def time_frames(frames, repeats: int):
    """Per frame: (outcome, total s, {stage: s}) with the fastest of ``repeats`` solves."""
    clock = StageClock()
    for fr in frames[:5]:                  # warm-up (imports, caches)
        solve_frame(fr)
    out = []
    for fr in frames:
        best = None
        for _ in range(repeats):
            clock.reset()
            t0 = time.perf_counter()
            res = solve_frame(fr)
            total = time.perf_counter() - t0
            if best is None or total < best[1]:
                stages = dict(clock.spent)
                stages["fit"] = total - sum(v for k, v in stages.items() if k != "fit")
                best = (res, total, stages)
        out.append(best)
    return out


def summary(rows) -> dict:
    tot = np.array([r[1] for r in rows]) * 1e3
    out = {"frames": len(rows), "median_ms": float(np.median(tot)),
           "p90_ms": float(np.percentile(tot, 90)), "max_ms": float(tot.max()),
           "mean_ms": float(tot.mean()), "failed": sum(isinstance(r[0], Exception)
                                                        for r in rows)}
    for st in STAGES:
        v = np.array([r[2][st] for r in rows]) * 1e3
        out[st] = {"median_ms": float(np.median(v)), "p90_ms": float(np.percentile(v, 90)),
                   "mean_ms": float(v.mean())}
    idn = np.array([(r[2]["identification"] + r[2]["fit"] + r[2]["suspects"]
                     + r[2]["eccentricity"]) for r in rows]) * 1e3
    out["ident_plus_solve_median_ms"] = float(np.median(idn))
    return out


def print_summary(name, s, note):
    print(f"\n{name}: {note}")
    print(f"  per frame: median {s['median_ms']:.2f} ms, p90 {s['p90_ms']:.2f}, max "
          f"{s['max_ms']:.2f}, mean {s['mean_ms']:.2f}  [target median <= {TARGET_MS:g} ms: "
          f"{'ok' if s['median_ms'] <= TARGET_MS else 'MISS'}]  ({s['failed']} frames raised)")
    for st in STAGES:
        print(f"  {st:15s} median {s[st]['median_ms']:7.2f} ms  p90 {s[st]['p90_ms']:7.2f}  "
              f"mean {s[st]['mean_ms']:7.2f}")


# ------------------------------------------------------------------------------ equivalence

def outcomes(frames, rows) -> dict:
    """Arrays of every frame's outcome, for --dump / --compare."""
    out = {}
    for fr, (res, _, _) in zip(frames, rows):
        key = fr[0]
        if isinstance(res, Exception):
            out[f"{key}/error"] = np.array(type(res).__name__)
            continue
        out[f"{key}/ids"] = np.array([i or "" for i in res.marker_ids])
        out[f"{key}/swapped"] = res.swapped
        out[f"{key}/inliers"] = res.inliers
        out[f"{key}/d_from_b"] = res.d_from_b
        out[f"{key}/pose"] = np.array([res.x_mm, res.y_mm, res.z_mm, res.alpha_deg,
                                       res.beta_deg, res.gamma_deg])
        out[f"{key}/focal"] = np.array(res.focal_px)
        out[f"{key}/cov"] = res.covariance
    return out


POSE_SAME = 1e-6     # mm / deg: beyond this a pose counts as another solution, not noise


def compare(cur: dict, ref_path: Path) -> dict:
    """Differences between this run's outcomes and a --dump file's: frames whose outcome
    (solved or the exception's class), ids / swapped, inliers (the suspects left out), or pose
    (by more than ``POSE_SAME``) differ, and the largest differences over the other solved
    frames."""
    ref = dict(np.load(ref_path))
    frames = sorted({k.split("/")[0] for k in ref} | {k.split("/")[0] for k in cur})
    rep = {"frames": len(frames), "outcome_differs": [], "ids_differ": [], "inliers_differ": [],
           "pose_differs": [],
           "max_dpos_mm": 0.0, "max_dang_deg": 0.0, "max_dfocal_rel": 0.0, "max_dcov_rel": 0.0}
    for f in frames:
        ea, eb = ref.get(f"{f}/error"), cur.get(f"{f}/error")
        if (ea is None) != (eb is None) or (ea is not None and str(ea) != str(eb)):
            rep["outcome_differs"].append(f)
            continue
        if ea is not None:
            continue
        if not all(np.array_equal(ref[f"{f}/{k}"], cur[f"{f}/{k}"]) for k in ("ids", "swapped")):
            rep["ids_differ"].append(f)
            continue
        if not np.array_equal(ref[f"{f}/inliers"], cur[f"{f}/inliers"]):
            rep["inliers_differ"].append(f)
        dp = np.abs(ref[f"{f}/pose"] - cur[f"{f}/pose"])
        if dp.max() > POSE_SAME:
            rep["pose_differs"].append(f)
            continue
        rep["max_dpos_mm"] = max(rep["max_dpos_mm"], float(dp[:3].max()))
        rep["max_dang_deg"] = max(rep["max_dang_deg"], float(dp[3:].max()))
        rep["max_dfocal_rel"] = max(rep["max_dfocal_rel"], float(
            abs(ref[f"{f}/focal"] - cur[f"{f}/focal"]) / ref[f"{f}/focal"]))
        ca, cb = ref[f"{f}/cov"], cur[f"{f}/cov"]
        rep["max_dcov_rel"] = max(rep["max_dcov_rel"], float(
            np.max(np.abs(ca - cb)) / np.max(np.abs(ca))))
    return rep


# ------------------------------------------------------------------------------------ main

def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--frames", type=int, default=200, help="synthetic frames")
    ap.add_argument("--real-frames", type=int, default=None, help="at most this many real")
    ap.add_argument("--hard", type=int, default=0, help="frames of the identification "
                    "benchmark's harder kind (equivalence checks)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", type=Path)
    ap.add_argument("--dump", type=Path)
    ap.add_argument("--compare", type=Path)
    ap.add_argument("--solver-src", type=Path)
    ap.add_argument("--profile", action="store_true", help="cProfile one pass, top 30")
    args = ap.parse_args(argv)
    if args.solver_src is not None:
        use_solver_source(args.solver_src.resolve())
    import dockfactory.solver
    from dockfactory.solver.synthetic import default_layout
    layout = default_layout()
    t_start, load0 = time.time(), os.getloadavg()[0]
    print(f"solve_docking speed: solver {Path(dockfactory.solver.__file__).parent}, "
          f"threads OMP/MKL/OPENBLAS = 1, {args.repeats} repeats (fastest kept), "
          f"load average before {load0:.2f}")
    sets = {"synthetic": ([synthetic_frame(args.seed, k, layout) for k in range(args.frames)],
                          f"{args.frames} frames, seed {args.seed}")}
    real, note = real_frames(args.real_frames)
    sets["real"] = (real, note)
    if args.hard:
        sets["hard"] = ([hard_frame(args.seed, k, layout) for k in range(args.hard)],
                        f"{args.hard} frames, seed {args.seed} (sigma 0.5 px, 15 % missing, "
                        "0-3 spurious, 0-2 swapped)")
    if args.profile:
        import cProfile
        import pstats
        frames = sets["synthetic"][0] + real
        prof = cProfile.Profile()
        prof.runcall(lambda: [solve_frame(f) for f in frames])
        pstats.Stats(prof).sort_stats("cumulative").print_stats(30)
    report, dump = {"target_ms": TARGET_MS, "threads": 1}, {}
    for name, (frames, note) in sets.items():
        if not frames:
            print(f"\n{name}: skipped ({note})")
            continue
        rows = time_frames(frames, args.repeats)
        report[name] = summary(rows)
        report[name]["input"] = note
        print_summary(name, report[name], note)
        dump.update(outcomes(frames, rows))
        truth = [(r[0], fr[7]) for fr, r in zip(frames, rows) if fr[7] is not None]
        if truth:
            right = sum(not isinstance(res, Exception) and list(res.marker_ids) == t
                        for res, t in truth)
            print(f"  identification: all ids right in {right} of {len(truth)} frames")
            report[name]["ids_right"] = right
    report["load_average"] = [load0, os.getloadavg()[0]]
    report["wall_s"] = time.time() - t_start
    print(f"\nload average after {os.getloadavg()[0]:.2f}; wall {report['wall_s']:.0f} s")
    if args.dump:
        np.savez_compressed(args.dump, **dump)
    if args.compare:
        rep = compare(dump, args.compare)
        report["compare"] = rep
        print(f"compare with {args.compare}: {rep['frames']} frames; outcome differs in "
              f"{len(rep['outcome_differs'])} {rep['outcome_differs'][:5]}, ids differ in "
              f"{len(rep['ids_differ'])} {rep['ids_differ'][:5]}, inliers in "
              f"{len(rep['inliers_differ'])} {rep['inliers_differ'][:5]}, pose (> {POSE_SAME:g})"
              f" in {len(rep['pose_differs'])} {rep['pose_differs'][:8]}; others: max |d pose| "
              f"{rep['max_dpos_mm']:.3g} mm, {rep['max_dang_deg']:.3g} deg; max rel d focal "
              f"{rep['max_dfocal_rel']:.3g}; max rel d covariance {rep['max_dcov_rel']:.3g}")
    if args.json:
        args.json.write_text(json.dumps(report, indent=1))


if __name__ == "__main__":
    main()
