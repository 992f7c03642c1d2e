"""Assemble results/paper/ (issue 13): render figures, Table 1, both detectors' figures and their
acceptance runs, against the paper's published numbers.

    python -m bench.paper.paper_results --dataset out/paper --out results/paper \\
        [--table1 results/paper/table1] [--detector NAME=EVAL_DIR:BENCH_JSON:WEIGHTS ...]

Inputs (every one optional except the dataset; a missing part is reported as missing, never
invented):
- the dataset's ``logs/timings.jsonl`` (render figures: frames, active wall time, s/frame,
  frames/hour, peak RSS of a worker) and its ``manifest.json`` (version id, sha256);
- ``--published``: the published manifest. When the dataset is a re-render of it (another
  manifest: other image bits on another CPU, checked with ``dataset verify --manifest``), its
  figures go to ``rerender`` and the published render's figures are kept from the previous
  ``OUT/metrics.json`` (when that one was made on the published dataset);
- ``--table1``: the ablation's run records (``dockfactory ablate ... --record DIR``);
- ``--detector NAME=EVAL_DIR:BENCH_JSON:WEIGHTS``: a detector's acceptance run (the ``evaluate``
  output folder with metrics.json), its ``bench/detector/detector_bench.py --out`` figures and its weights.

Writes ``OUT/metrics.json`` and ``OUT/report.md`` (atomically) and prints the README table.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

from dockfactory.core.io import sha256_file, write_json_atomic, write_text_atomic

PAPER_TABLE1 = {"none": (0.995, 0.770), "eca": (0.995, 0.825), "se": (0.995, 0.834), "a2": (0.995, 0.812)}
PAPER_RANKING = ("se", "eca", "a2", "none")      # by mAP50:95, the paper's order
PAPER_POSE = {"estimation": {"x": 0.856, "y": 0.877, "alpha": 0.048},
              "localization": {"x": 0.794, "y": 0.776, "alpha": 0.869}}
VARIANT_NAMES = {"none": "YOLOv5s", "se": "YOLOv5s + SE", "eca": "YOLOv5s + ECA", "cbam": "YOLOv5s + CBAM",
                 "a2": "YOLOv5s + A2"}
AXES = ("x", "y", "alpha")
PAUSE_S = 300.0   # a gap between two finished frames longer than this is an interruption of the job


def render_figures(rows: list[dict], pause_s: float = PAUSE_S) -> dict:
    """Figures of a (possibly interrupted and resumed) render from its per-frame timing rows: the
    active wall time counts each frame's gap to the previous one, or its own total after a pause.
    A frame rendered more than once (its first render deleted, e.g. made by older code) counts once,
    by its last render; the time of the earlier ones is left out."""
    last = {r.get("frame_id", i): r for i, r in enumerate(sorted(rows, key=lambda r: r["finished_at"]))}
    rows = sorted(last.values(), key=lambda r: r["finished_at"])
    if not rows:
        return {"frames": 0}
    wall, segments = rows[0]["total"], 1
    for prev, cur in zip(rows, rows[1:]):
        gap = cur["finished_at"] - prev["finished_at"]
        if gap > pause_s:
            segments += 1
            wall += cur["total"]
        else:
            wall += gap
    totals = np.array([r["total"] for r in rows])
    return {"frames": len(rows), "active_wall_s": round(float(wall), 1), "segments": segments,
            "s_per_frame": round(float(wall / len(rows)), 3), "frames_per_hour": round(3600 * len(rows) / wall, 1),
            "median_frame_total_s": round(float(np.median(totals)), 3),
            "median_cycles_s": round(float(np.median([r["cycles"] for r in rows])), 3),
            "peak_worker_rss_mb": round(max(r.get("rss_mb", 0.0) for r in rows), 1)}


def table1(records: list[dict]) -> dict:
    """Per attention variant: seeds, mean and sample std of mAP50 and mAP50:95 (all classes), of the
    boxes our pipeline outputs (refined) and, as ``network_*``, of the network's own boxes (the
    paper's Table 1 scores a network), each also on YOLOv5's scale (``yolov5_*``)."""
    out = {}
    for att in VARIANT_NAMES:
        rs = sorted((r for r in records if r["attention"] == att), key=lambda r: r["seed"])
        if not rs:
            continue
        row = {"seeds": [r["seed"] for r in rs]}
        for key in ("mAP50", "mAP50_95"):
            row[key] = _spread([r[key] for r in rs])
            if all("yolov5" in r for r in rs):   # the same runs on YOLOv5's scale (eval/yolov5_ap.py)
                row["yolov5_" + key] = _spread([r["yolov5"][key] for r in rs])
            if all("network_boxes" in r for r in rs):
                row["network_" + key] = _spread([r["network_boxes"][key] for r in rs])
                row["network_yolov5_" + key] = _spread([r["network_boxes"]["yolov5"][key] for r in rs])
        out[att] = row
    return out


def _spread(values) -> dict:
    """Mean, sample std (None for one value) and the values."""
    v = np.array(values, dtype=float)
    return {"mean": float(v.mean()), "std": float(v.std(ddof=1)) if len(v) > 1 else None, "values": v.tolist()}


def ranking_check(t1: dict, order=PAPER_RANKING, key: str = "mAP50_95") -> list[dict]:
    """Each consecutive pair of the paper's ranking: our difference of means, that difference in
    units of the pair's pooled seed std (how many standard deviations separate them) and Welch's t
    (the difference over its standard error, which shrinks with the seeds)."""
    out = []
    for hi, lo in zip(order, order[1:]):
        if key not in t1.get(hi, {}) or key not in t1.get(lo, {}):
            continue
        a, b = t1[hi][key], t1[lo][key]
        diff = a["mean"] - b["mean"]
        both = a["std"] is not None and b["std"] is not None
        pooled = float(np.sqrt((a["std"] ** 2 + b["std"] ** 2) / 2)) if both else None
        se = float(np.sqrt(a["std"] ** 2 / len(a["values"]) + b["std"] ** 2 / len(b["values"]))) if both else None
        out.append({"pair": f"{hi} > {lo}", "difference": diff, "pooled_std": pooled,
                    "sigmas": diff / pooled if pooled else None, "welch_t": diff / se if se else None,
                    "holds": bool(diff > 0)})
    return out


def pose_figures(metrics: dict) -> dict:
    """MSE and RMSE of X, Y, alpha for estimation (repeatability) and localization (test split),
    with the Cramer-Rao bound's RMS beside localization."""
    loc = metrics["localization"]["overall"]
    est = metrics["estimation"]["pooled"]
    crb = metrics["localization"].get("crb", {})
    return {"localization": {a: {"mse": loc[a]["mse"], "rmse": loc[a]["rmse"],
                                 "crb_rms": crb.get(a, {}).get("bound_rms")} for a in AXES},
            "estimation": {a: {"mse": est[a]["mse"], "rmse": est[a]["rmse"]} for a in AXES},
            "n_test": metrics["localization"]["n_frames"], "n_solved": metrics["localization"]["n_solved"],
            "n_repeat": metrics["estimation"]["n_frames"]}


DETECTION_KEYS = ("frames", "mAP50", "mAP50_95", "yolov5", "per_class", "centre_error",
                  "centre_error_by_condition", "recall_visible50", "network_boxes")


def detector_figures(eval_dir: Path, bench_json: Path, weights: Path) -> dict:
    """A detector's weights (sha256, size), detection figures on the test and repeat splits
    (``BENCH_JSON`` and its ``_repeat`` sibling from bench/detector/detector_bench.py) and acceptance run."""
    out: dict = {"weights": str(weights)}
    if weights.is_file():
        out.update(weights_sha256=sha256_file(weights), weights_bytes=weights.stat().st_size)
    for split, path in (("test", bench_json), ("repeat", bench_json.with_name(bench_json.stem + "_repeat.json"))):
        if path.is_file():
            b = json.loads(path.read_text())
            acc = b.get("accuracy", {})
            out.setdefault("detection", {})[split] = {k: acc[k] for k in DETECTION_KEYS if k in acc}
            out.setdefault("inference_ms_per_image", b.get("inference", {}).get("ms_per_image_median"))
    metrics_path = eval_dir / "metrics.json"
    if metrics_path.is_file():
        m = json.loads(metrics_path.read_text())
        out["pose"] = pose_figures(m)
        acc = m.get("acceptance", {})
        out["accepted"] = acc.get("accepted")
        out["criteria"] = [{k: c.get(k) for k in ("name", "value", "threshold", "unit", "pass", "paper")}
                           for c in acc.get("criteria", [])]
    return out


def _cell(x, fmt="{:.3f}") -> str:
    return "—" if x is None or (isinstance(x, float) and np.isnan(x)) else fmt.format(x)


def _mean_std(x: dict) -> str:
    return f"{x['mean']:.3f} ± {_cell(x['std'])}"


def _table1_cell(ours: dict | None, key: str) -> str:
    """Our figure of one Table 1 cell: the network's boxes (the paper's measure) first, then the
    refined boxes our pipeline outputs; COCO's and YOLOv5's scales; the seed count."""
    if not ours:
        return "not run yet"
    def both(prefix: str) -> str:
        return f"{_mean_std(ours[prefix + key])} COCO" + (f", {_mean_std(ours[prefix + 'yolov5_' + key])} YOLOv5's"
                                                         if prefix + "yolov5_" + key in ours else "")
    net = f"network boxes {both('network_')}; " if "network_" + key in ours else ""
    n = len(ours["seeds"])
    return f"{net}refined {both('')} ({n} seed{'s' if n != 1 else ''})"


def readme_table(t1: dict, detectors: dict) -> str:
    """The README's "Results on the paper's dataset" table (paper against ours)."""
    lines = ["| figure | paper | ours |", "| --- | --- | --- |"]
    for att, name in VARIANT_NAMES.items():
        paper = PAPER_TABLE1.get(att)
        for i, key in enumerate(("mAP50", "mAP50_95")):
            p = _cell(paper[i]) if paper else "not in the paper"
            lines.append(f"| {name}: {key.replace('_', ':')} | {p} | {_table1_cell(t1.get(att), key)} |")
    pose = detectors.get("s_se", {}).get("pose")
    for kind in ("estimation", "localization"):
        for a in AXES:
            unit = "deg" if a == "alpha" else "mm"
            paper = PAPER_POSE[kind][a]
            if pose:
                f = pose[kind][a]
                crb = f" (bound {_cell(f.get('crb_rms'))})" if kind == "localization" else ""
                o = f"RMSE {f['rmse']:.3f} {unit}{crb}; MSE {f['mse']:.4f} {unit}²"
            else:
                o = "not run yet"
            lines.append(f"| {kind} {a} (paper's \"MSE\", an RMS) | {paper} {unit} | {o} |")
    return "\n".join(lines)


def _render_line(what: str, r: dict) -> list[str]:
    if not r.get("frames"):
        return []
    return [f"- {what}: {r['active_wall_s'] / 3600:.2f} h of active wall time "
            f"({r['segments']} stretches; pauses over {PAUSE_S / 60:.0f} min left out; timing rows of "
            f"{r['frames']} frames), {r['s_per_frame']:.2f} s/frame, {r['frames_per_hour']:.0f} frames/hour, "
            f"median Cycles {r['median_cycles_s']:.2f} s/frame, peak worker RSS {r['peak_worker_rss_mb']:.0f} MB"]


def render_section(dataset: dict, render: dict, rerender: dict | None = None) -> list[str]:
    """The dataset's identity and its render figures (wall time without the pauses between runs)."""
    lines = ["## Dataset", "", f"- version id: `{dataset['version_id']}`"
             f"{'' if dataset['complete'] else ' (no manifest yet: incomplete or not verified)'}",
             f"- manifest sha256: `{dataset['manifest_sha256']}`"]
    if dataset.get("rerender_of"):
        lines.append(f"- the figures below were measured on a re-render of the published dataset (manifest "
                     f"sha256 `{dataset['rerender_of']}`), checked against it with `dataset verify --manifest`")
    lines += _render_line("render (published)" if dataset.get("rerender_of") else "render", render)
    lines += _render_line("re-render", rerender or {})
    return lines + [""]


def ranking_section(ranking: list[dict], boxes: str) -> list[str]:
    """The paper's ranking (SE > ECA > A2 > plain, by mAP50:95), pair by pair, in pooled seed stds."""
    if not ranking:
        return []
    lines = [f"## The paper's ranking (mAP50:95, {boxes})", "",
             "| pair | difference | pooled seed std | sigmas | Welch's t | holds |", "| --- | --- | --- | --- | --- | --- |"]
    lines += [f"| {p['pair']} | {p['difference']:+.4f} | {_cell(p['pooled_std'], '{:.4f}')} | "
              f"{_cell(p['sigmas'], '{:+.1f}')} | {_cell(p.get('welch_t'), '{:+.1f}')} | "
              f"{'yes' if p['holds'] else 'no'} |" for p in ranking]
    return lines + [""]


def _map_figures(det: dict) -> str:
    v5 = det.get("yolov5", {})
    return (f"mAP50 {_cell(det.get('mAP50'))}, mAP50:95 {_cell(det.get('mAP50_95'))} "
            f"(COCO; YOLOv5's {_cell(v5.get('mAP50'))}, {_cell(v5.get('mAP50_95'))})")


def detector_section(name: str, d: dict) -> list[str]:
    """One detector: its weights, detection figures per split and its acceptance run."""
    if "weights_sha256" not in d:
        return [f"## Detector {name}", "", f"- weights `{d['weights']}`: not trained yet", ""]
    lines = [f"## Detector {name}", "", f"- weights `{d['weights']}`: sha256 `{d['weights_sha256']}`, "
             f"{d['weights_bytes'] / 1e6:.2f} MB",
             f"- inference: {_cell(d.get('inference_ms_per_image'), '{:.1f}')} ms per 1280 x 960 image (median)"]
    for split, det in d.get("detection", {}).items():
        cond = ", ".join(f"{k} {v['median_px']:.3f}" for k, v in det.get("centre_error_by_condition", {}).items())
        net = f"{_map_figures(det['network_boxes'])} on the network's own boxes; refined boxes: " \
            if "network_boxes" in det else ""
        lines.append(f"- {split} split ({det.get('frames')} frames): {net}{_map_figures(det)}; "
                     f"median centre error (px) {cond}")
    if "accepted" in d:
        lines += ["", f"Acceptance: **{'ACCEPTED' if d['accepted'] else 'REJECTED'}**", "",
                  "| criterion | value | threshold | pass |", "| --- | --- | --- | --- |"]
        lines += [f"| {c['name']} | {_cell(c['value'], '{:.4f}')} {c.get('unit') or ''} | "
                  f"{_cell(c['threshold'], '{:.4f}')} | {'yes' if c['pass'] else 'no'} |" for c in d["criteria"]]
    return lines + [""]


def report_markdown(doc: dict, table: str) -> str:
    """report.md: the paper-against-ours table, then the dataset, the ranking and each detector."""
    lines = ["# The paper's dataset: results", "", f"Commit `{doc['commit']}`.", "", table, ""]
    lines += (render_section(doc["dataset"], doc["render"], doc.get("rerender"))
              + ranking_section(doc.get("ranking_network", []), "the network's boxes, the paper's measure")
              + ranking_section(doc["ranking"], "the refined boxes our pipeline outputs"))
    for name, d in doc["detectors"].items():
        lines += detector_section(name, d)
    return "\n".join(lines)


def _version_id(manifest: Path, info: Path) -> str | None:
    """The dataset's version id: from its manifest once published, else from dataset.json."""
    for path in (manifest, info):
        if path.is_file():
            return json.loads(path.read_text())["version_id"]
    return None


def dataset_and_render(dataset: Path, rows: list[dict], published: Path | None, previous: dict) -> dict:
    """{"dataset", "render"[, "rerender"]}: the dataset's identity and render figures; for a
    re-render of ``published``, the published render's figures come from ``previous`` (the last
    metrics.json), never from the re-render."""
    manifest, info = dataset / "manifest.json", dataset / "dataset.json"
    doc = {"dataset": {"path": str(dataset), "version_id": _version_id(manifest, info),
                       "manifest_sha256": sha256_file(manifest) if manifest.is_file() else None,
                       "complete": manifest.is_file()}}
    pub_sha = sha256_file(published) if published and published.is_file() else None
    if pub_sha is None or pub_sha == doc["dataset"]["manifest_sha256"]:
        return doc | {"render": render_figures(rows)}
    doc["dataset"]["rerender_of"] = pub_sha
    prev = previous.get("dataset", {})
    kept = previous.get("render", {}) if pub_sha in (prev.get("manifest_sha256"), prev.get("rerender_of")) else {}
    return doc | {"render": kept, "rerender": render_figures(rows)}


def _git_commit() -> str:
    try:
        return subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--dataset", type=Path, required=True)
    ap.add_argument("--out", type=Path, default=Path("results/paper"))
    ap.add_argument("--table1", type=Path)
    ap.add_argument("--published", type=Path, help="the published manifest.json (see the module docstring)")
    ap.add_argument("--detector", action="append", default=[], metavar="NAME=EVAL_DIR:BENCH_JSON:WEIGHTS")
    args = ap.parse_args(argv)
    timings = args.dataset / "logs" / "timings.jsonl"
    rows = [json.loads(line) for line in timings.read_text().splitlines() if line.strip()] if timings.is_file() else []
    previous = json.loads((args.out / "metrics.json").read_text()) if (args.out / "metrics.json").is_file() else {}
    records = [json.loads(p.read_text()) for p in sorted(args.table1.glob("*.json"))] if args.table1 else []
    t1 = table1(records)
    detectors = {}
    for spec in args.detector:
        name, _, paths = spec.partition("=")
        eval_dir, bench_json, weights = (Path(p) for p in paths.split(":"))
        detectors[name] = detector_figures(eval_dir, bench_json, weights)
    doc = {"commit": _git_commit(), **dataset_and_render(args.dataset, rows, args.published, previous),
           "table1": t1, "ranking": ranking_check(t1), "ranking_network": ranking_check(t1, key="network_mAP50_95"),
           "detectors": detectors}
    table = readme_table(t1, detectors)
    write_json_atomic(args.out / "metrics.json", doc)
    write_text_atomic(args.out / "report.md", report_markdown(doc, table))
    print(table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
