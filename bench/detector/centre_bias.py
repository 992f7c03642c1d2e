"""Centre bias bench (issue 12): per-class mean offset and RMS of the sub-pixel centre refinement.

    python -m bench.detector.centre_bias DATASET [DATASET ...] [--box-jitter PX | --weights W.pt]
                                [--impl CENTRE.py] [--paired OTHER ...] [--out NAME.json]

For every fully visible (visibility 2), legible marker of the datasets' main frames,
``detector.centre.refine_centre`` is called on the marker's true outline box (``bbox_px``; with
``--box-jitter PX`` each side moved by a seeded uniform draw in [-PX, PX], like a detector's box),
so the figures isolate the refinement from the network; with ``--weights W.pt`` on the box of
the network's highest-scoring raw detection (score >= 0.25, before refinement) of the marker's
class whose centre lies in the marker's true box (markers without one are skipped). The error
is the refined centre minus the
label's ``outline_centroid_px`` (the exact centroid of the projected outline, OpenCV pixels). Per
dataset and class, over normal frames and over every condition: markers (n), refined share, mean
dx and dy with their standard errors (clustered by frame: the markers of one frame share its
lighting, colours and noise, so they are not independent), RMS, median and 95th percentile of the
error length, and the mean error of the refined box's sides against the label box (x0, y0, x1, y1;
> 0 = right of / below the truth). Time per call is the median over the calls.

Targets (issue 12): |mean dx|, |mean dy| <= 0.01 px per class over >= 250 markers (every
condition) on two scenes that differ in section radius and marker size; RMS <= 0.07 px on normal
frames. Markers the refinement leaves unrefined (it returns the box centre) are counted in
``refined`` and left out of the error figures.

``--impl FILE`` takes ``refine_centre`` from another copy of detector/centre.py (a before/after
comparison: ``git show HEAD:detector/centre.py > /tmp/centre_before.py``).

``--paired OTHER [OTHER ...]``: OTHER i is a render of DATASET i's frames (same scene config and
seed) with other render settings (e.g. bench/results/centre_bias/oidn_fast.toml against
oidn_off.toml: the denoiser on and off); per class, the mean of (error in OTHER - error in
DATASET) pooled over the markers refined in both: the effect of the settings on the same scenes
and the same path-tracing samples.
"""
from __future__ import annotations

import argparse
import importlib.util
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from dockfactory.detector.data import read_rgb
from dockfactory.generator.datasets.reader import Dataset

TARGET_MEAN_PX, TARGET_MIN_MARKERS, TARGET_RMS_PX = 0.01, 250, 0.07


def load_refine(impl: str | None):
    """``refine_centre`` of the package, or of the module file ``impl``."""
    if impl is None:
        from dockfactory.detector.centre import refine_centre
        return refine_centre
    spec = importlib.util.spec_from_file_location("centre_impl", impl)
    module = importlib.util.module_from_spec(spec)
    sys.modules["centre_impl"] = module          # dataclasses look their module up
    spec.loader.exec_module(module)
    return module.refine_centre


def network_box(raw: np.ndarray | None, marker: dict) -> np.ndarray | None:
    """The box of the highest-scoring raw detection ``(K, 6)`` [x0, y0, x1, y1, score, class] of
    the marker's class whose centre lies in the marker's true box."""
    if raw is None:
        return None
    b = marker["bbox_px"]
    cx, cy = (raw[:, 0] + raw[:, 2]) / 2, (raw[:, 1] + raw[:, 3]) / 2
    ok = (raw[:, 5] == marker["class_id"]) & (cx >= b[0]) & (cx <= b[2]) & (cy >= b[1]) & (cy <= b[3])
    return raw[ok][np.argmax(raw[ok, 4]), :4] if ok.any() else None


def collect(dataset: Dataset, refine, box_jitter: float, detector=None, seed: int = 0) -> list[dict]:
    """One row per fully visible, legible marker of the main frames (with a matched network box
    when ``detector`` is given): frame, marker, class, condition, refined, centre error (2,) px,
    box side errors (4,) px, seconds of the call."""
    rows = []
    for i, fid in enumerate(dataset.frames()):
        label = dataset.labels[fid]
        if label["spec"]["kind"] != "main":
            continue
        markers = [m for m in label["markers"] if m["visibility"] == 2 and m["legible"] and m["bbox_px"]]
        if not markers:
            continue
        image = read_rgb(dataset.image_path(fid))
        rng = np.random.default_rng([seed, i])
        raw = detector.raw(image)[0] if detector is not None else None
        for m in markers:
            truth_box = np.array(m["bbox_px"], dtype=np.float64)
            box = truth_box + rng.uniform(-box_jitter, box_jitter, 4) if box_jitter > 0 else truth_box
            if detector is not None:
                box = network_box(raw, m)
                if box is None:
                    continue
            t0 = time.perf_counter()
            r = refine(image, box, m["class_id"])
            dt = time.perf_counter() - t0
            rows.append({"frame": fid, "marker": m["id"], "class_id": m["class_id"],
                         "condition": label["spec"]["condition"],
                         "refined": bool(r.refined), "seconds": dt,
                         "error": np.asarray(r.center) - np.asarray(m["outline_centroid_px"]),
                         "box_error": np.asarray(r.box) - truth_box})
    return rows


def summarise(rows: list[dict]) -> dict:
    """Figures of a group of rows (see the module docstring)."""
    n = len(rows)
    ok = [r for r in rows if r["refined"]]
    out = {"n": n, "refined": len(ok)}
    if len(ok) < 2:
        return out
    e = np.array([r["error"] for r in ok])
    b = np.array([r["box_error"] for r in ok])
    length = np.hypot(e[:, 0], e[:, 1])
    se = clustered_se(e, [r["frame"] for r in ok])
    out.update(mean_dx=float(e[:, 0].mean()), se_dx=float(se[0]), mean_dy=float(e[:, 1].mean()),
               se_dy=float(se[1]), rms=float(np.sqrt((length ** 2).mean())), median=float(np.median(length)),
               p95=float(np.percentile(length, 95)), box_side_mean=[float(v) for v in b.mean(axis=0)])
    return out


def clustered_se(values: np.ndarray, clusters: list) -> np.ndarray:
    """Standard error (per column) of the mean of ``values: (n, k)`` whose rows are correlated
    within a cluster (a frame): sqrt(sum over clusters of (sum of deviations)^2) / n."""
    dev = values - values.mean(axis=0)
    sums = {}
    for c, d in zip(clusters, dev):
        sums[c] = sums.get(c, 0.0) + d
    return np.sqrt(sum(s ** 2 for s in sums.values())) / len(values)


def paired(rows_ref: list[dict], rows_other: list[dict]) -> dict:
    """Per class: mean (dx, dy) of error(other) - error(ref) over the markers refined in both."""
    ref = {(r["frame"], r["marker"]): r for r in rows_ref if r["refined"]}
    out = {}
    for cls, name in ((0, "RedA"), (1, "BlueB")):
        pairs = [(r, ref[(r["frame"], r["marker"])]) for r in rows_other
                 if r["refined"] and r["class_id"] == cls and (r["frame"], r["marker"]) in ref]
        if len(pairs) < 2:
            out[name] = {"n": len(pairs)}
            continue
        diff = np.array([o["error"] - r["error"] for o, r in pairs])
        se = clustered_se(diff, [o["frame"] for o, _ in pairs])
        out[name] = {"n": len(pairs), "mean_dx": float(diff[:, 0].mean()), "se_dx": float(se[0]),
                     "mean_dy": float(diff[:, 1].mean()), "se_dy": float(se[1])}
    return out


def bench_dataset(root: str, refine, box_jitter: float, detector=None) -> tuple[dict, list[dict]]:
    """(per class, normal frames and every condition, the version id and time per call; the rows)."""
    dataset = Dataset.open(root, full=False)
    rows = collect(dataset, refine, box_jitter, detector)
    groups = {}
    for group, keep in (("normal", lambda r: r["condition"] == "normal"), ("all", lambda r: True)):
        for cls, name in ((0, "RedA"), (1, "BlueB")):
            groups[f"{group}/{name}"] = summarise([r for r in rows if r["class_id"] == cls and keep(r)])
    res = {"dataset": str(root), "version_id": dataset.version_id, "config_name": dataset.config.dataset.name,
           "box_jitter_px": box_jitter, "boxes": "network" if detector is not None else "true", "calls": len(rows),
           "ms_per_call_median": 1000 * float(np.median([r["seconds"] for r in rows])) if rows else None,
           "groups": groups}
    return res, rows


def verdicts(res: dict) -> list[str]:
    """Target lines of one dataset's figures."""
    lines = []
    for name in ("RedA", "BlueB"):
        g = res["groups"][f"all/{name}"]
        if "mean_dx" in g:
            worst = max(abs(g["mean_dx"]), abs(g["mean_dy"]))
            ok = worst <= TARGET_MEAN_PX and g["refined"] >= TARGET_MIN_MARKERS
            lines.append(f"  {name}: |mean| {worst:.4f} px over {g['refined']} markers "
                         f"[target <= {TARGET_MEAN_PX} over >= {TARGET_MIN_MARKERS}: {'ok' if ok else 'MISS'}]")
        g = res["groups"][f"normal/{name}"]
        if "rms" in g:
            lines.append(f"  {name}: RMS on normal frames {g['rms']:.4f} px "
                         f"[target <= {TARGET_RMS_PX}: {'ok' if g['rms'] <= TARGET_RMS_PX else 'MISS'}]")
    return lines


def format_table(res: dict) -> str:
    head = (f"{res['dataset']} (config {res['config_name']}, version {res['version_id']}), {res['boxes']} boxes, "
            f"jitter {res['box_jitter_px']:g} px, {res['calls']} calls, median {res['ms_per_call_median']:.2f} ms per call")
    lines = [head, "| frames | class | n | refined | mean dx (px) | mean dy (px) | RMS | median | p95 | box sides x0 y0 x1 y1 (px) |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for key, g in res["groups"].items():
        group, name = key.split("/")
        if "mean_dx" not in g:
            lines.append(f"| {group} | {name} | {g['n']} | {g['refined']} | - | - | - | - | - | - |")
            continue
        sides = " ".join(f"{v:+.3f}" for v in g["box_side_mean"])
        lines.append(f"| {group} | {name} | {g['n']} | {g['refined']} | {g['mean_dx']:+.4f} ± {g['se_dx']:.4f} | "
                     f"{g['mean_dy']:+.4f} ± {g['se_dy']:.4f} | {g['rms']:.4f} | {g['median']:.4f} | "
                     f"{g['p95']:.3f} | {sides} |")
    return "\n".join(lines + verdicts(res))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("datasets", nargs="+", help="dataset directories (complete renders)")
    p.add_argument("--box-jitter", type=float, default=0.0, help="move each box side by up to this many px")
    p.add_argument("--weights", help="refine the boxes of this detector's raw detections instead of the true boxes")
    p.add_argument("--impl", help="a copy of detector/centre.py to take refine_centre from")
    p.add_argument("--paired", nargs="+", help="renders of the datasets' frames with other settings (one each)")
    p.add_argument("--out", help="also write the figures to this JSON file")
    args = p.parse_args(argv)
    refine = load_refine(args.impl)
    detector = None
    if args.weights:
        from dockfactory.detector.infer import MarkerDetector  # torch: only when asked
        detector = MarkerDetector(args.weights, conf_threshold=0.25)
    print(f"refine_centre from {args.impl or 'dockfactory.detector.centre'}; load average {os.getloadavg()[0]:.2f}")
    if args.paired and len(args.paired) != len(args.datasets):
        p.error("--paired takes one render per dataset")
    results, all_rows = [], []
    for k, root in enumerate(args.datasets + (args.paired or [])):
        res, rows = bench_dataset(root, refine, args.box_jitter, detector)
        for r in rows:
            r["frame"] = (k % len(args.datasets), r["frame"])      # pair i-th dataset with i-th other
        results.append(res)
        all_rows.append(rows)
        print(format_table(res), flush=True)
    doc = {"impl": args.impl or "dockfactory.detector.centre", "results": results}
    if args.paired:
        n = len(args.datasets)
        classes = paired(sum(all_rows[:n], []), sum(all_rows[n:], []))
        doc["paired"] = {"reference": args.datasets, "other": args.paired, "classes": classes}
        for name, g in classes.items():
            if "mean_dx" in g:
                print(f"paired (other - reference): {name} n {g['n']} dx {g['mean_dx']:+.4f} ± {g['se_dx']:.4f}, "
                      f"dy {g['mean_dy']:+.4f} ± {g['se_dy']:.4f} px")
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(json.dumps(doc, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
