"""Attention ablation: train every variant under the same budget and seeds, evaluate on the test
split, and write the layout of the paper's Table 1 (mAP50 and mAP50:95, all and per class) with the mean
and spread (sample standard deviation) over seeds and the budget stated.

Two scores per run: the boxes our pipeline outputs (refined by the edge fit, ``detector.centre``)
and the network's own boxes (``network_boxes``): the paper's Table 1 scores a network.

Why and how: docs/detector.md, "The attention ablation's runs".
"""
from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from dockfactory.core.errors import DockfactoryError
from dockfactory.core.io import make_output_folder
from dockfactory.core.io import write_json_atomic, write_text_atomic
from dockfactory.eval.detection_metrics import evaluate_detections

LABELS = {"none": "YOLOv5", "se": "+ SE", "eca": "+ ECA", "cbam": "+ CBAM", "a2": "+ A2"}


def _fmt(values) -> str:
    v = np.asarray(values, dtype=np.float64)
    if len(v) == 1:
        return f"{v[0]:.3f}"
    return f"{v.mean():.3f} ± {v.std(ddof=1):.3f}"


def _train_and_evaluate(dataset, run: Path, att: str, seed: int, cfg, conf: float, progress: bool) -> dict:
    """Train one variant into ``run``, detect on the test split and evaluate; its metrics record."""
    from dockfactory.detector.infer import detect_dataset
    from dockfactory.detector.train import train
    t0 = time.monotonic()
    summary = train(dataset, run, cfg, resume=(run / "last.pt").is_file(), progress=progress)
    train_s = time.monotonic() - t0
    doc = detect_dataset(dataset, run / "weights.pt", run / "dets_test.json", split="test",
                         conf_threshold=conf, progress=progress)
    m = evaluate_detections(dataset, doc)
    return {"attention": att, "seed": seed, "train_seconds": round(train_s, 1),
            "epochs": summary["epochs"], "images_per_s": summary["history"][-1]["images_per_s"],
            "mAP50": m["mAP50"], "mAP50_95": m["mAP50_95"], "per_class": m["per_class"], "yolov5": m["yolov5"],
            "network_boxes": m["network_boxes"],
            "centre_error": m["centre_error"], "recall_visible50": m["recall_visible50"]}


def _network_cells(rs: list[dict]) -> list[str]:
    """mAP50 and mAP50:95 of the network's own boxes over the runs that have them ("k of n"
    when some lack them, "—" when none has them)."""
    have = [r["network_boxes"] for r in rs if r.get("network_boxes")]
    if not have:
        return ["—", "—"]
    note = "" if len(have) == len(rs) else f" ({len(have)} of {len(rs)})"
    return [_fmt([n[k] for n in have]) + note for k in ("mAP50", "mAP50_95")]


def _table_lines(runs: list[dict], attentions, scale: str) -> list[str]:
    """Markdown rows of Table 1: one per attention variant with a finished run, mean ± std over
    its seeds."""
    classes = list(runs[0]["per_class"])
    head = (["model", "seeds", "refined mAP50", "refined mAP50:95", "network boxes mAP50", "network boxes mAP50:95"]
            + [f"{c} {k}" for c in classes for k in ("mAP50", "mAP50:95")])
    lines = ["| " + " | ".join(head) + " |", "|" + " --- |" * len(head)]
    for att in attentions:
        rs = [r for r in runs if r["attention"] == att]
        if not rs:
            continue
        cells = [f"YOLOv5{scale} {LABELS[att]}".replace("YOLOv5n YOLOv5", "YOLOv5n").replace(
            "YOLOv5s YOLOv5", "YOLOv5s"), str(len(rs)), _fmt([r["mAP50"] for r in rs]),
            _fmt([r["mAP50_95"] for r in rs])] + _network_cells(rs)
        for c in classes:
            cells += [_fmt([r["per_class"][c]["mAP50"] for r in rs]), _fmt([r["per_class"][c]["mAP50_95"] for r in rs])]
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def _recorded(record_dir, name: str, dataset, cfg) -> dict | None:
    """The record of run ``name`` in ``record_dir`` when it is of this dataset version and config."""
    path = Path(record_dir) / f"{name}.json" if record_dir else None
    if path is None or not path.is_file():
        return None
    rec = json.loads(path.read_text())
    same = rec.get("dataset_version") == dataset.version_id and rec.get("config") == cfg.to_dict()
    return rec if same else None


LATER_FIGURES = ("yolov5", "network_boxes")    # figures older records may lack


def _run_one(dataset, out: Path, att: str, seed: int, cfg, conf: float, progress: bool, record_dir,
             train: bool = True) -> dict | None:
    """One (attention, seed) run: from the record folder, from OUT, or trained and evaluated now
    (None when it is not finished and ``train`` is False)."""
    name = f"{att}_seed{seed}"
    run = out / name
    rec = _recorded(record_dir, name, dataset, cfg)
    if rec is not None and (all(k in rec for k in LATER_FIGURES) or not (run / "dets_test.json").is_file()):
        return rec
    if rec is None and (run / "metrics.json").is_file() and (run / "weights.pt").is_file():
        rec = _same_run(json.loads((run / "metrics.json").read_text()), run, dataset, cfg)
    elif rec is None and not train:
        return None
    elif rec is None:
        rec = _train_and_evaluate(dataset, run, att, seed, cfg, conf, progress)
        rec.update(dataset_version=dataset.version_id, config=cfg.to_dict())
    return _save(_with_later_figures(rec, run, dataset), run, name, record_dir)


def _same_run(rec: dict, run: Path, dataset, cfg) -> dict:
    """``rec`` (a finished run's metrics.json) when it is of this dataset version and training
    config (a record without them is taken as it is); else a one-line error, never a silent reuse."""
    if rec.get("dataset_version", dataset.version_id) != dataset.version_id or \
            rec.get("config", cfg.to_dict()) != cfg.to_dict():
        raise DockfactoryError(f"{run}: a finished run of another dataset version or training config; "
                               "use another --out (or remove the run) to train this one")
    return rec


def _with_later_figures(rec: dict, run: Path, dataset) -> dict:
    """A record made before a figure of ``LATER_FIGURES`` was measured gets it from the run's saved
    test detections (when they are still there and carry what it needs)."""
    dets = run / "dets_test.json"
    if all(k in rec for k in LATER_FIGURES) or not dets.is_file():
        return rec
    m = evaluate_detections(dataset, dets)
    return {**rec, **{k: m[k] for k in LATER_FIGURES if k not in rec and k in m}}


def _save(rec: dict, run: Path, name: str, record_dir) -> dict:
    """Write the run's metrics.json (when its folder exists) and its record."""
    if run.is_dir():
        write_json_atomic(run / "metrics.json", rec)
    if record_dir:
        Path(record_dir).mkdir(parents=True, exist_ok=True)
        write_json_atomic(Path(record_dir) / f"{name}.json", rec)
    return rec


def run_ablation(dataset, out, attentions, seeds, make_config, conf: float = 0.001, progress: bool = True,
                 record_dir=None, train: bool = True) -> dict:
    """Train/evaluate every (attention, seed) on the opened ``dataset`` (generator.datasets.reader.Dataset);
    ``make_config(attention, seed) -> TrainConfig``; ``record_dir``, ``train``: see the module
    docstring. ``DockfactoryError`` when no run is finished and ``train`` is False."""
    from dockfactory.detector.attention import ATTENTIONS
    from dockfactory.detector.data import load_frames
    bad = [a for a in attentions if a not in ATTENTIONS]
    if bad or not attentions:
        raise DockfactoryError(f"--attention: variants must be among {', '.join(ATTENTIONS)}, got "
                               f"{','.join(attentions) or 'none'}")
    if not seeds:
        raise DockfactoryError("--seeds: need at least one seed")
    out = make_output_folder(out, "--out")   # both folders checked before any training
    if record_dir:
        make_output_folder(record_dir, "--record")
    runs = []
    for seed in seeds:          # seed by seed: an interrupted ablation has every variant's first seeds
        for att in attentions:
            runs.append(_run_one(dataset, out, att, seed, make_config(att, seed), conf, progress, record_dir,
                                 train))
    planned, runs = len(runs), [r for r in runs if r is not None]
    if not runs:
        raise DockfactoryError(f"ablate --no-train: no run of the ablation is finished in {out} or in the record "
                               f"folder {record_dir}")
    cfg0 = make_config(attentions[0], seeds[0])
    n_train = len(load_frames(dataset, "train"))
    n_test = len(load_frames(dataset, "test"))
    lines = _table_lines(runs, attentions, cfg0.model.scale)
    wall = sum(r["train_seconds"] for r in runs)
    budget = (f"Budget per run: {cfg0.epochs} epochs x {n_train} train frames x {cfg0.data.crops_per_frame} crops "
              f"of {cfg0.data.crop} px (input scale {cfg0.data.input_scale}), batch {cfg0.batch_size}, from scratch; "
              f"seeds {list(seeds)} (mean ± sample std over seeds); test split {n_test} frames of dataset "
              f"{dataset.version_id}, COCOeval at score >= {conf}; {len(runs)} of {planned} runs finished; "
              f"total training wall time {wall / 60:.1f} min.")
    table = "\n".join(lines) + "\n\n" + budget
    write_text_atomic(out / "ablation.md", "# Attention ablation (the paper's Table 1; per class: refined boxes)\n\n" + table + "\n")
    write_json_atomic(out / "ablation.json", {"dataset_version": dataset.version_id, "runs": runs,
                                              "config": cfg0.to_dict(), "budget": budget})
    return {"table": table, "runs": runs}
