"""Label-aware sampling: the same frames rendered at several ``[render] marker_samples``, side by side.

    python -m bench.render.marker_sampling --scene A REF DIR [DIR ...] --scene B REF DIR [DIR ...]
                                    [--weights W] [--out table.json] [--boot 2000]

Each ``--scene`` names its datasets: the first (REF) is the converged reference (e.g.
``marker_samples = 256`` on every crop pixel, no denoiser, no coverage correction: refused
otherwise, unless ``--any-reference``), the others the candidates; all of one scene must be renders of the same
config but for ``[render]`` (the same frames, poses and cameras; checked on the labels' poses).
``DIR+DIR2`` pools renders of other frames (another seed) as one dataset, each in the same place
of every argument of its scene: the frames of both, the timing of the first.
Every dataset's test frames go through the shipped detector with its refinement (``dockfactory
detect``, cached beside the dataset as ``detections_bench.json``) and the paper's pinhole solver
with the weights' noise card. Printed per dataset, with ratios to the reference of the same scene
(paired 95 % bootstrap intervals over frames, seeded):

- s / frame: median wall time of a frame's render (Cycles: frame + marker crops; logs/timings.jsonl)
  and its ratio to the scene's dataset without label-aware sampling (``marker_samples = 0``);
- centre error: median and RMS radial distance (px) of the used refined centres from the labels'
  outline centroids; the mean offset per axis;
- pose: X / Y / alpha RMSE (mm, mm, deg) and the bias t = mean / (std / sqrt(n)) of each.

Figures and their reading: bench/results/marker_sampling/README.md.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

from dockfactory.core.io import write_json_atomic
from dockfactory.eval.centre_noise import used_centre_errors
from dockfactory.eval.evaluate import per_frame_rows
from dockfactory.eval.solve_frames import solve_dataset
from dockfactory.generator.datasets.reader import Dataset
from dockfactory.generator.reference_render import MIN_REFERENCE_SAMPLES

POSE = ("x", "y", "alpha")
MIN_SCORE = 0.25


def detections(root: Path, weights: str | None) -> dict:
    """The detections of the test split (cached as ``detections_bench.json`` beside the dataset)."""
    path = root.parent / f"{root.name}.detections_bench.json"
    if not path.exists():
        cmd = [sys.executable, "-m", "dockfactory", "detect", str(root), "--out", str(path), "--split", "test",
               "--quiet", "--threads", "2"] + (["--weights", weights] if weights else [])
        subprocess.run(cmd, check=True)
    return json.loads(path.read_text())


def render_seconds(root: Path) -> dict:
    """Median wall seconds per frame: Cycles (frame + crops, with their coverage rendered or
    computed from the geometry) and the whole frame."""
    rows = [json.loads(line) for line in (root / "logs" / "timings.jsonl").read_text().splitlines() if line.strip()]
    crops = [r.get("marker_crops", 0.0) + r.get("marker_coverage", 0.0) + r.get("marker_coverage_geometry", 0.0)
             for r in rows]
    cyc = [r["cycles"] + c for r, c in zip(rows, crops)]
    return {"frames": len(rows), "cycles_s": float(np.median(cyc)), "total_s": float(np.median([r["total"] for r in rows])),
            "crops_s": float(np.median(crops))}


def measure(root: Path, weights: str | None) -> dict:
    """Per-frame centre errors and pose errors of one dataset's solved test frames."""
    ds = Dataset.open(root)
    dets = detections(root, weights)
    poses = solve_dataset(ds, splits=("test",), detections=dets)
    rows = {r["frame_id"]: r for r in per_frame_rows(ds, poses, 0.1) if r["split"] == "test" and r["ok"]}
    centres = {}
    for fid in rows:
        rec = poses["frames"][fid]
        errs, _ = used_centre_errors(ds.labels[fid], dets["frames"].get(fid, []), rec.get("marker_ids"), MIN_SCORE)
        centres[fid] = errs
    return {"version": ds.version_id, "marker_samples": ds.config.render.marker_samples,
            "samples": ds.config.render.samples, "denoise": ds.config.render.denoise,
            "marker_denoise": ds.config.render.marker_denoise,
            "marker_adaptive_threshold": ds.config.render.marker_adaptive_threshold,
            "marker_adaptive_min_samples": ds.config.render.marker_adaptive_min_samples,
            "marker_coverage_samples": ds.config.render.marker_coverage_samples,
            "marker_coverage_source": ds.config.render.marker_coverage_source,
            "sampling_pattern": ds.config.render.sampling_pattern,
            "rows": rows, "centres": centres, "timing": render_seconds(root),
            "true": {fid: ds.labels[fid]["pose_b_in_d"] for fid in ds.frames("test")}}


def _coverage_source(entry: dict) -> str:
    """How a dataset's coverage correction got its coverage: rendered at its samples, or from the
    geometry (where the geometry did not apply, rendered at them)."""
    n = entry["marker_coverage_samples"]
    return f"from the geometry (else {n})" if entry.get("marker_coverage_source") == "geometry" else f"{n}"


def centre_stats(errs: np.ndarray) -> dict:
    r = np.hypot(errs[:, 0], errs[:, 1])
    return {"n": int(len(r)), "median_px": float(np.median(r)), "rms_px": float(np.sqrt(np.mean(r ** 2))),
            "mean_px": errs.mean(axis=0).tolist()}


def pose_stats(errs: np.ndarray) -> dict:
    n = len(errs)
    sd = errs.std(ddof=1) if n > 1 else np.nan
    return {"n": n, "rmse": float(np.sqrt(np.mean(errs ** 2))), "mean": float(errs.mean()),
            "t": float(errs.mean() / (sd / np.sqrt(n))) if sd > 0 else float("nan")}


def paired_ratio(num: np.ndarray, den: np.ndarray, stat, boot: int, seed: int) -> list[float]:
    """stat(num) / stat(den) and its 95 % bootstrap interval, resampling frames (rows) jointly."""
    rng = np.random.default_rng(seed)
    n = len(num)
    idx = rng.integers(0, n, size=(boot, n))
    ratios = np.array([stat(num[i]) / stat(den[i]) for i in idx])
    return [float(stat(num) / stat(den)), float(np.percentile(ratios, 2.5)), float(np.percentile(ratios, 97.5))]


def rms(a):
    return np.sqrt(np.mean(np.square(a)))


def compare(ref: dict, cand: dict, boot: int) -> dict:
    """Candidate against reference on the frames both solved: statistics and paired ratios."""
    common = sorted(set(ref["rows"]) & set(cand["rows"]))
    out = {"frames": len(common), "pose": {}, "ratio": {}}
    for k, c in enumerate(POSE):
        e_c = np.array([cand["rows"][f][f"err_{c}"] for f in common])
        e_r = np.array([ref["rows"][f][f"err_{c}"] for f in common])
        out["pose"][c] = pose_stats(e_c)
        out["ratio"][c] = paired_ratio(e_c, e_r, rms, boot, seed=k)
    per_c = [np.hypot(*cand["centres"][f].T) if len(cand["centres"][f]) else np.zeros(0) for f in common]
    per_r = [np.hypot(*ref["centres"][f].T) if len(ref["centres"][f]) else np.zeros(0) for f in common]
    out["centre"] = centre_stats(np.vstack([cand["centres"][f] for f in common]))
    # frames as the resampling unit: per frame the sum of squares / count, and the median of the pooled
    out["ratio"]["centre_median"] = _frame_ratio(per_c, per_r, np.median, boot, 10)
    out["ratio"]["centre_rms"] = _frame_ratio(per_c, per_r, rms, boot, 11)
    return out


def _frame_ratio(per_c: list, per_r: list, stat, boot: int, seed: int) -> list[float]:
    rng = np.random.default_rng(seed)
    n = len(per_c)
    point = stat(np.concatenate(per_c)) / stat(np.concatenate(per_r))
    vals = []
    for _ in range(boot):
        i = rng.integers(0, n, size=n)
        vals.append(stat(np.concatenate([per_c[j] for j in i])) / stat(np.concatenate([per_r[j] for j in i])))
    return [float(point), float(np.percentile(vals, 2.5)), float(np.percentile(vals, 97.5))]


def _fmt_ratio(r) -> str:
    return f"{r[0]:.2f} [{r[1]:.2f}-{r[2]:.2f}]"


def table(results: dict) -> list[str]:
    lines = ["| scene | dataset | marker samples | s / frame (Cycles) | x default | centre median / RMS px | x ref median | "
             "x ref RMS | X / Y / alpha RMSE | x ref X | x ref Y | x ref alpha | bias t X / Y / alpha |",
             "| --- " * 13 + "|"]
    for scene, entries in results.items():
        base = next((e for e in entries if e["marker_samples"] == 0), entries[0])
        for e in entries:
            c, p, r = e["cmp"]["centre"], e["cmp"]["pose"], e["cmp"]["ratio"]
            what = f"{e['marker_samples']}" + (f" + {e['marker_denoise']}" if e["marker_denoise"] != "off" else "") \
                + (f", adaptive {e['marker_adaptive_threshold']:g}" if e["marker_adaptive_threshold"] else "") \
                + (f" from {e['marker_adaptive_min_samples']}" if e.get("marker_adaptive_min_samples") else "") \
                + (f", {e['sampling_pattern']}" if e["sampling_pattern"] != "tabulated_sobol" else "") \
                + (f", coverage {_coverage_source(e)}" if e.get("marker_coverage_samples") else "")
            lines.append(
                f"| {scene} | {e['name']}@{e['version']} | {what} | {e['timing']['cycles_s']:.2f} | "
                f"{e['timing']['cycles_s'] / base['timing']['cycles_s']:.2f} | {c['median_px']:.4f} / {c['rms_px']:.4f} | "
                f"{_fmt_ratio(r['centre_median'])} | {_fmt_ratio(r['centre_rms'])} | "
                f"{p['x']['rmse']:.3f} / {p['y']['rmse']:.3f} / {p['alpha']['rmse']:.4f} | "
                f"{_fmt_ratio(r['x'])} | {_fmt_ratio(r['y'])} | {_fmt_ratio(r['alpha'])} | "
                f"{p['x']['t']:+.1f} / {p['y']['t']:+.1f} / {p['alpha']['t']:+.1f} |")
    return lines


def sample_fit(entries: list[dict]) -> dict | None:
    """The centre error's floor and sampling term, median^2 = floor^2 + c^2 / N, least squares over
    the entries rendered with N uniform samples at the markers (label-aware sampling without
    adaptive sampling or the coverage correction, the reference included); the samples a render needs for a median within
    1.2x of the reference's (None when fewer than two such entries). The reference's sampling
    pattern only."""
    pts = [(e["marker_samples"], e["cmp"]["centre"]["median_px"]) for e in entries
           if e["marker_samples"] > 0 and not e["marker_adaptive_threshold"] and not e.get("marker_coverage_samples")
           and e["sampling_pattern"] == entries[0]["sampling_pattern"]]
    if len(set(n for n, _ in pts)) < 2:
        return None
    a = np.array([[1.0, 1.0 / n] for n, _ in pts])
    (f2, c2), *_ = np.linalg.lstsq(a, np.array([m * m for _, m in pts]), rcond=None)
    ref = entries[0]["cmp"]["centre"]["median_px"]
    need = float(c2 / (1.44 * ref * ref - f2)) if 1.44 * ref * ref > f2 else None   # None: no count reaches it
    return {"points": pts, "floor_px": float(np.sqrt(max(f2, 0.0))), "c_px": float(np.sqrt(max(c2, 0.0))),
            "samples_for_1p2x_ref": need}


def reference_problems(render) -> list[str]:
    """What keeps a dataset's ``[render]`` table (``render``) from being a converged reference at
    the markers: fewer than MIN_REFERENCE_SAMPLES crop samples, adaptive sampling (its threshold stops
    pixels early: a reference about 1.2x worse in median), a denoiser or the coverage correction at
    the markers (docs/rendering.md, "The converged reference"). Empty when it is one."""
    out = []
    if render.marker_samples < MIN_REFERENCE_SAMPLES:
        out.append(f"marker_samples = {render.marker_samples} (at least {MIN_REFERENCE_SAMPLES})")
    if render.marker_adaptive_threshold > 0:
        out.append(f"marker_adaptive_threshold = {render.marker_adaptive_threshold} (0: every pixel every sample)")
    if render.marker_denoise != "off":
        out.append(f"marker_denoise = {render.marker_denoise!r} (\"off\")")
    if render.marker_coverage_samples > 0:
        out.append(f"marker_coverage_samples = {render.marker_coverage_samples} (0)")
    return out


def check_reference(root: str, any_reference: bool = False) -> None:
    """SystemExit (one line naming ``root`` and what is wrong) when the dataset at ``root`` is not
    rendered as a converged reference (:func:`reference_problems`), unless ``any_reference``."""
    problems = reference_problems(Dataset.open(root, full=False).config.render)
    if problems and not any_reference:
        raise SystemExit(f"{root}: not a converged reference: {'; '.join(problems)} "
                         "(docs/rendering.md, \"The converged reference\"; --any-reference to compare anyway)")


def measure_pooled(spec: str, weights: str | None) -> dict:
    """:func:`measure` of ``spec``, one dataset or several joined by "+" (renders of other frames,
    pooled: each frame id prefixed by its dataset's place, the version joined by "+", the
    settings and timing the first's)."""
    parts = [measure(Path(d), weights) for d in spec.split("+")]
    if len(parts) == 1:
        return parts[0]
    out = {**parts[0], "version": "+".join(p["version"] for p in parts)}
    for key in ("rows", "centres", "true"):
        out[key] = {f"{i}/{fid}": v for i, p in enumerate(parts) for fid, v in p[key].items()}
    return out


def run_scene(dirs: list[str], weights: str | None, boot: int, any_reference: bool = False) -> list[dict]:
    for ref in dirs[0].split("+"):
        check_reference(ref, any_reference)
    measured = [measure_pooled(d, weights) for d in dirs]
    ref = measured[0]
    for m, d in zip(measured[1:], dirs[1:]):
        if m["true"] != ref["true"]:
            raise SystemExit(f"{d}: not the reference's frames (other poses in the labels)")
    out = []
    for m, d in zip(measured, dirs):
        entry = {k: m[k] for k in ("version", "marker_samples", "samples", "denoise", "marker_denoise",
                                   "marker_adaptive_threshold", "marker_adaptive_min_samples", "marker_coverage_samples",
                                   "marker_coverage_source", "sampling_pattern", "timing")}
        entry["name"] = "+".join(Path(x).name for x in d.split("+"))
        entry["cmp"] = compare(ref, m, boot)
        out.append(entry)
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", nargs="+", action="append", required=True, metavar="NAME DIR",
                    help="a scene's name, its reference dataset, then the candidates")
    ap.add_argument("--weights", default=None)
    ap.add_argument("--boot", type=int, default=2000)
    ap.add_argument("--out", default=None, help="write the figures (no per-frame rows) as JSON")
    ap.add_argument("--any-reference", action="store_true",
                    help="compare against a first dataset that is not rendered as a converged reference")
    args = ap.parse_args()
    results = {}
    for scene in args.scene:
        if len(scene) < 3:
            raise SystemExit(f"--scene {scene[0]}: give the reference and at least one candidate")
        results[scene[0]] = run_scene(scene[1:], args.weights, args.boot, args.any_reference)
    print("\n".join(table(results)))
    for scene, entries in results.items():
        fit = sample_fit(entries)
        if fit:
            print(f"{scene}: median centre error^2 = {fit['floor_px']:.4f}^2 + {fit['c_px']:.4f}^2 / N px^2 "
                  f"over {len(fit['points'])} settings; a median within 1.2x of the reference needs "
                  + (f"N = {fit['samples_for_1p2x_ref']:.0f} samples at the markers" if fit["samples_for_1p2x_ref"]
                     else "more samples than any count (the fitted floor is above 1.2x the reference)"))
    if args.out:
        fits = {scene: sample_fit(entries) for scene, entries in results.items()}
        write_json_atomic(args.out, {"command": " ".join(sys.argv), "scenes": results, "fits": fits})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
