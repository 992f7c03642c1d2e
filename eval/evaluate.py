"""``dockfactory evaluate``: metrics, per-frame CSV and the acceptance verdict.

Writes EVAL/metrics.json and EVAL/frames.csv. Exit status 0 accepted, 1 a gated criterion fails,
2 bad input (for example poses or detections made for another dataset version).
"""
from __future__ import annotations

import csv
import io
import os
from collections import defaultdict
from pathlib import Path

import numpy as np

from dockfactory.core.io import write_json_atomic, write_text_atomic
from dockfactory.core.layout import CLASS_NAMES
from dockfactory.core.names import MIN_SCORE
from dockfactory.eval.uncertainty_budget import budget_block
from dockfactory.eval.acceptance import COMPONENTS, POSE_KEYS, AcceptanceSpec, verdict
from dockfactory.eval.confidence import chi2_bounds
from dockfactory.eval.gate_statistic import gate_statistic
from dockfactory.eval.camera_models_eval import camera_models_block
from dockfactory.eval.model_check import model_check_block
from dockfactory.eval.centre_noise import centre_noise_block, used_sigma
from dockfactory.eval.centre_structure import measure_structure, structured_frame_bound
from dockfactory.eval.centre_noise_disc import (
    disc_noise_block,
    disc_scales,
    frame_noise_px,
    label_noise_shapes,
)
from dockfactory.eval.dataset_access import read_json_for, validate_detections
from dockfactory.eval.detection_metrics import evaluate_detections, match_frame
from dockfactory.eval.envelope import EnvelopeGrid, camera_envelope
from dockfactory.eval.pose_metrics import error_stats, pose_error, repeatability
from dockfactory.eval.solve_frames import solve_dataset
from dockfactory.eval.simulated_cameras import simulated_cameras_block
from dockfactory.eval.uncertainty import calibration_block, reported_std, standard_scores
from dockfactory.generator.datasets.folder import DatasetError
from dockfactory.generator.datasets.reader import Dataset
from dockfactory.eval.pixel_aspect import crb_delivered, label_pixel_aspect
from dockfactory.solver import SolverError

METRICS_FORMAT = "dockfactory.metrics/1"


def frame_bound(label: dict, marker_ids, sigma_px: float, disc_scale_px: float | None = None) -> dict | None:
    """Cramer-Rao std of (X, Y, Z, alpha, beta, gamma) for this frame's exact geometry, and
    ``sigma_px`` the per-axis centre noise it assumed (px, averaged over the points).

    Isotropic noise of std ``sigma_px`` in the delivered image; with ``disc_scale_px`` each
    marker's noise is shaped by its disc's image (solver.disc_noise) at that scale
    (eval.centre_noise_disc), unless the label lacks the disc geometry. A camera with non-square
    pixels (K's fy != fx) is bounded with that noise taken to the square pinhole at fx
    (eval.pixel_aspect.crb_delivered)."""
    by_id = {m["id"]: m for m in label["markers"]}
    ids = [i for i in (marker_ids or []) if i in by_id] or [m["id"] for m in label["markers"] if m.get("visibility") == 2]
    marks = {s: [by_id[i] for i in ids if i.startswith(s)] for s in "AB"}
    pa, pb = (np.array([m["center_section_mm"] for m in marks[s]]).reshape(-1, 3) for s in "AB")
    if len(pa) < 4 or len(pb) < 4 or not sigma_px > 0:
        return None
    cam_from_d = np.array(label["camera"]["cam_from_d"])
    cam_from_b = cam_from_d @ np.array(label["d_from_b"])
    shapes = None
    if disc_scale_px:
        sa, sb = label_noise_shapes(label, marks["A"]), label_noise_shapes(label, marks["B"])
        if sa is not None and sb is not None:
            shapes, sigma_px = (sa, sb), frame_noise_px(np.concatenate([sa, sb]), disc_scale_px)
    try:
        b = crb_delivered(pa, cam_from_d, pb, cam_from_b, label["camera"]["focal_px"],
                          label["camera"]["principal_point"], sigma_px, label_pixel_aspect(label), shapes)
    except SolverError:
        return None
    return {**{c: b.std[POSE_KEYS[c]] for c in COMPONENTS}, "sigma_px": sigma_px}


def _missing_row(spec, reason: str, category: str) -> dict:
    """The row of a planned frame that has no label in the dataset: a failure."""
    return {"frame_id": spec.frame_id, "split": spec.split, "condition": spec.condition,
            "pose_index": spec.pose_index, "ok": False, "reason": reason, "category": category}


def evaluated_frames(ds: Dataset) -> list:
    """The population the verdict is computed over: every frame the dataset's plan puts in the
    test split or the repeatability subset (FrameSpec, plan order), whether or not its label, its
    image or its pose exists. Never a directory listing: a frame that disappears is a failure."""
    return [s for s in ds.plan if s.split in ("test", "repeat")]


def per_frame_rows(ds: Dataset, poses: dict, sigma_px: float, population=None, source="poses",
                   sigma_by_condition: dict | None = None, disc: dict | None = None,
                   structure: dict | None = None) -> list[dict]:
    """One row per frame: the ``population`` (FrameSpecs, default :func:`evaluated_frames`) first,
    then any other frame of the dataset the poses file holds (another split). A planned frame
    without a label or without a pose is a failed row with its reason; a pose for a frame the
    dataset does not have is refused (``source``: the poses file, for the message). The
    isotropic bound of a frame (``crb_iso_*``) uses its condition's centre noise from
    ``sigma_by_condition`` when given, else ``sigma_px``; its ``sigma_px`` column says which.
    With ``disc`` (:func:`eval.centre_noise_disc.disc_scales`: "value", "by_condition") the
    bound ``crb_*`` is that of the disc noise model at the condition's scale (``sigma_disc_px``:
    the per-axis noise it assumed), else the isotropic one. With ``disc`` and a measured
    ``structure`` (eval.centre_structure.measure_structure) a solved row also has the bound under
    that structure (``crb_structured_*``) and the weighted fit's expected std under it
    (``fit_structured_*``), at the same scale."""
    population = evaluated_frames(ds) if population is None else population
    planned = {s.frame_id for s in population}
    order = [s.frame_id for s in population] + [f for f in poses["frames"] if f not in planned]
    spec_of = {s.frame_id: s for s in population}
    rows = []
    for fid in order:
        if fid not in ds.labels:
            if fid in spec_of:
                rows.append(_missing_row(spec_of[fid], "frame missing from the dataset (no label)",
                                         "missing from dataset"))
                continue
            raise DatasetError(f"{source}: frames.{fid}: not a frame of the "
                               f"dataset {ds.root}")
        rec = poses["frames"].get(fid) or {"ok": False, "reason": "no pose in the poses file",
                                           "category": "missing"}
        lab = ds.labels[fid]
        spec = spec_of.get(fid)
        true = lab["pose_b_in_d"]
        row = {"frame_id": fid, "split": spec.split if spec else lab["spec"]["split"],
               "condition": spec.condition if spec else lab["spec"]["condition"],
               "pose_index": spec.pose_index if spec else lab["spec"]["pose_index"], "ok": rec["ok"] is True,
               "reason": rec.get("reason") or "", "category": rec.get("category") or "",
               "focal_true": lab["camera"]["focal_px"], "distance_mm": lab["camera"]["distance_mm"],
               "visible_a": sum(m.get("visibility") == 2 and m["section"] == "A" for m in lab["markers"]),
               "visible_b": sum(m.get("visibility") == 2 and m["section"] == "B" for m in lab["markers"])}
        for c in COMPONENTS:
            row[f"true_{c}"] = true[POSE_KEYS[c]]
        if row["ok"]:
            sigma = (sigma_by_condition or {}).get(row["condition"], sigma_px)
            scale = disc["by_condition"].get(row["condition"], disc["value"]) if disc else None
            row.update(_solved_fields(rec, lab, sigma, f"{source}: frames.{fid}.covariance", scale))
            row.update(_structured_fields(lab, rec.get("marker_ids"), structure, scale))
        rows.append(row)
    return rows


def _solved_fields(rec: dict, lab: dict, sigma_px: float, where: str, disc_scale_px=None) -> dict:
    """The columns of a solved frame: estimate, error, focal, reprojection RMS, the isotropic
    bound at ``sigma_px``, the bound (the disc model's at ``disc_scale_px`` when given, else the
    isotropic one) and, when the record has a covariance, the reported std and z = error / std."""
    true = lab["pose_b_in_d"]
    err = pose_error(rec["pose"], true)
    out = {"focal_est": rec["focal_px"],
           "focal_err_pct": 100.0 * (rec["focal_px"] - lab["camera"]["focal_px"]) / lab["camera"]["focal_px"],
           "rmse_px_a": rec["rmse_px"]["A"], "rmse_px_b": rec["rmse_px"]["B"], "sigma_px": sigma_px}
    iso = frame_bound(lab, rec.get("marker_ids"), sigma_px)
    bound = frame_bound(lab, rec.get("marker_ids"), sigma_px, disc_scale_px) if disc_scale_px else iso
    if disc_scale_px and bound:
        out["sigma_disc_px"] = bound["sigma_px"]
    std = reported_std(rec["covariance"], where) if rec.get("covariance") is not None else {}
    z = standard_scores(err, std)
    for c in COMPONENTS:
        out[f"est_{c}"] = rec["pose"][POSE_KEYS[c]]
        out[f"err_{c}"] = err[c]
        out[f"crb_{c}"] = bound[c] if bound else None
        out[f"crb_iso_{c}"] = iso[c] if iso else None
        out[f"std_{c}"] = std.get(c)
        out[f"z_{c}"] = z[c]
    return out


def _structured_fields(lab: dict, marker_ids, structure: dict | None, scale_px: float | None) -> dict:
    """``crb_structured_*`` and ``fit_structured_*`` of a solved frame (None each where the
    structure, the disc scale or the frame's geometry does not give them)."""
    b = structured_frame_bound(lab, marker_ids, structure, scale_px) if structure and scale_px else None
    return {f"{k}_structured_{c}": (b[name][c] if b else None)
            for k, name in (("crb", "bound"), ("fit", "fit")) for c in COMPONENTS}


def localization_block(rows: list[dict]) -> dict:
    ok = [r for r in rows if r["ok"]]
    out = {"n_frames": len(rows), "n_solved": len(ok)}
    out["overall"] = {c: error_stats([r[f"err_{c}"] for r in ok]) for c in COMPONENTS}
    by_cond = defaultdict(list)
    for r in ok:
        by_cond[r["condition"]].append(r)
    out["by_condition"] = {cond: {c: error_stats([r[f"err_{c}"] for r in rs]) for c in COMPONENTS}
                           for cond, rs in sorted(by_cond.items())}
    out["focal_err_pct"] = error_stats([r["focal_err_pct"] for r in ok])
    out["reprojection_rmse_px"] = {s: error_stats([r[f"rmse_px_{s.lower()}"] for r in ok]) for s in "AB"}
    out["crb"] = bound_ratios(ok, out["overall"], "crb")
    if any(r.get("sigma_disc_px") is not None for r in ok):
        out["crb_isotropic"] = bound_ratios(ok, out["overall"], "crb_iso")
    if any(r.get("crb_structured_x") is not None for r in ok):
        out["crb_structured"] = bound_ratios(ok, out["overall"], "crb_structured")
        out["fit_structured"] = bound_ratios(ok, out["overall"], "fit_structured")
    out["calibration"] = calibration_block(ok)
    return out


RATIO_CONFIDENCE = 0.95   # two-sided: the ratio's interval from the chi-square spread of an RMSE over n frames


def bound_ratios(ok: list[dict], overall: dict, prefix: str) -> dict:
    """{component: bound_rms (RMS over the solved rows of column ``<prefix>_<c>``),
    measured_rmse, ratio, ratio_low, ratio_high}: the ratio's two-sided RATIO_CONFIDENCE interval
    is what the measured RMSE over its n frames can show (chi-square with n degrees of freedom,
    errors about zero), so a ratio under 1 on a few frames is not read as beating the bound."""
    crb = {}
    for c in COMPONENTS:
        b = [r[f"{prefix}_{c}"] for r in ok if r.get(f"{prefix}_{c}") is not None]
        if b:
            bound_rms = float(np.sqrt(np.mean(np.square(b))))
            rmse, n = overall[c]["rmse"], overall[c]["n"]
            ratio = (rmse / bound_rms) if rmse is not None and bound_rms > 0 else None
            spread = chi2_bounds(n * rmse ** 2, n, (1 + RATIO_CONFIDENCE) / 2) if ratio is not None else None
            crb[c] = {"bound_rms": bound_rms, "measured_rmse": rmse, "ratio": ratio,
                      "ratio_low": spread[0] / bound_rms if spread else None,
                      "ratio_high": spread[1] / bound_rms if spread else None}
    return crb


def failures_block(rows: list[dict]) -> dict:
    failed = [r for r in rows if not r["ok"]]
    by_cond = defaultdict(lambda: [0, 0])
    for r in rows:
        by_cond[r["condition"]][1] += 1
        if not r["ok"]:
            by_cond[r["condition"]][0] += 1
    return {"count": len(failed), "frames": len(rows), "rate": len(failed) / len(rows) if rows else None,
            "by_condition": {c: {"failed": f, "frames": n, "rate": f / n} for c, (f, n) in sorted(by_cond.items())},
            "by_category": {cat: sum(r["category"] == cat for r in failed) for cat in sorted({r["category"] for r in failed})},
            "list": [{"frame_id": r["frame_id"], "condition": r["condition"], "reason": r["reason"]} for r in failed]}


def estimation_block(rows: list[dict]) -> dict:
    groups = defaultdict(list)
    for r in rows:
        if r["ok"]:
            groups[f"pose{r['pose_index']:03d}"].append({c: r[f"est_{c}"] for c in COMPONENTS})
    rep = repeatability(groups)
    rep["n_frames"] = len(rows)
    rep["n_solved"] = sum(r["ok"] for r in rows)
    return rep


def statistic_bounds(test: list[dict], rep: list[dict], spec: AcceptanceSpec) -> dict:
    """One-sided ``spec.confidence`` bounds of every component's statistic, each block's by its
    gate's statistic (eval.gate_statistic ``bounds`` / ``spread_bounds``; for rmse and mse the RMS
    bounds of eval.confidence, chi-square and bootstrap, the cautious pair deciding): localization
    over the solved test frames' errors, estimation over the static poses' repeated estimates.
    Bootstrap seeds fixed per component (the same rows give the same bounds)."""
    ok = [r for r in test if r["ok"]]
    groups = defaultdict(list)
    for r in rep:
        if r["ok"]:
            groups[r["pose_index"]].append(r)
    loc, est = gate_statistic(spec.localization.statistic), gate_statistic(spec.estimation.statistic)
    out = {"confidence": spec.confidence, "localization": {}, "estimation": {}}
    for k, c in enumerate(COMPONENTS):
        out["localization"][c] = loc.bounds([r[f"err_{c}"] for r in ok], spec.confidence, seed=k) if ok else {}
        out["estimation"][c] = est.spread_bounds([[r[f"est_{c}"] for r in g] for _, g in sorted(groups.items())],
                                                 spec.confidence, seed=100 + k)
    return out


def evaluate(ds: Dataset, poses_path, spec: AcceptanceSpec, detections_path=None,
             min_score: float = MIN_SCORE, oracle: bool = True, oracle_sigma_px: float | None = None,
             envelope: EnvelopeGrid | None = None, camera_models: bool = False) -> tuple[dict, list[dict]]:
    """Metrics and per-frame rows of a poses file on an opened dataset, with the acceptance verdict.

    Parameters
    ----------
    ds : Dataset
        The opened dataset (generator.datasets.reader).
    poses_path, detections_path : path, path or None
        The poses file (``dockfactory solve``) and the detections file (``dockfactory detect``; every detection
        needs ``bbox_px`` and ``score``: mAP and the measured centre noise); both made for ``ds``'s version.
    spec : AcceptanceSpec
        The tolerances and the confidence the verdict and the bounds use.
    min_score : float
        The detection score threshold of the centre-noise measurements and of the camera models' solves.
    oracle, oracle_sigma_px : bool, float px or None
        ``oracle``: the test split also solved from its labels at the used centre noise (``metrics["oracle"]``);
        ``oracle_sigma_px``: the noise used when no detections measure it (eval.centre_noise.used_sigma).
    envelope : EnvelopeGrid or None
        Also the tolerance envelope of uncalibrated cameras (eval.envelope) at the measured centre noise.
    camera_models : bool
        Also the test split solved with the pinhole and self-calibrated camera models side by side
        (eval.camera_models_eval). The envelope and the camera models are reported, not gated.

    Returns
    -------
    metrics : dict
        metrics.json's content (``metrics["acceptance"]`` the verdict). Every planned frame counts: a frame without a
        pose (failed, absent from the poses file or from the dataset) is a failure with its reason.
    rows : list of dict
        One row per frame (frames.csv).

    Raises
    ------
    DatasetError
        A poses or detections file made for another dataset version, or malformed or unreadable (one line naming file and key).
    """
    return _evaluate(ds, poses_path, spec, detections_path, min_score, oracle, oracle_sigma_px, envelope,
                     camera_models)


def _evaluate(ds: Dataset, poses_path, spec: AcceptanceSpec, detections_path, min_score: float, oracle: bool,
              oracle_sigma_px: float | None, envelope: EnvelopeGrid | None,
              camera_models: bool) -> tuple[dict, list[dict]]:
    """:func:`evaluate`'s work."""
    poses = read_json_for(poses_path, "poses", ds)
    detections = None
    if detections_path:   # mAP needs every detection's box and score
        detections = validate_detections(read_json_for(detections_path, "detections", ds), detections_path,
                                         required=("bbox_px", "score"))
    noise = centre_noise_block(ds, poses, detections, min_score) if detections is not None else None
    used = used_sigma(noise, oracle_sigma_px, poses.get("oracle_sigma_px"))
    sigma = used["value"]
    disc = disc_noise_block(ds, poses, detections, min_score) if detections is not None else None
    structure = measure_structure(ds, detections, min_score) if disc else None
    # the population is the plan: a frame without a pose (failed, absent from the poses file or
    # from the dataset) is a failure with its reason, never silently dropped
    rows = per_frame_rows(ds, poses, sigma, source=str(poses_path), sigma_by_condition=used["by_condition"],
                          disc=disc_scales(disc), structure=structure)
    test = [r for r in rows if r["split"] == "test"]
    rep = [r for r in rows if r["split"] == "repeat"]
    metrics = {"format": METRICS_FORMAT, "dataset": {"root": str(ds.root), "version_id": ds.version_id,
                                                      "name": ds.identity["name"]},
               "poses": {"source": poses.get("source"), "path": str(poses_path)},
               "centre_noise_px": sigma, "centre_noise": {**(noise or {}), "used": used,
                                                           **({"disc_model": disc} if disc else {}),
                                                           **({"structure": structure} if structure else {})},
               "centre_error": {c: {"median_px": s["median_radial_px"], "n": s["n"]}
                                for c, s in ((noise or {}).get("by_condition") or {}).items()},
               "localization": localization_block(test), "estimation": estimation_block(rep),
               "failures_test": failures_block(test), "failures_repeat": failures_block(rep)}
    if detections is not None:
        metrics["detection"] = detection_block(ds, detections)
    if oracle:
        o_poses = solve_dataset(ds, splits=("test",), oracle_sigma_px=float(sigma))
        o_rows = per_frame_rows(ds, o_poses, sigma, [s for s in evaluated_frames(ds) if s.split == "test"])
        metrics["oracle"] = {"sigma_px": sigma, "localization": localization_block(o_rows),
                             "failures": failures_block(o_rows)}
    if envelope is not None:
        metrics["camera_envelope"] = camera_envelope(ds, spec, float(sigma), envelope)
    if camera_models:
        metrics["camera_models"] = camera_models_block(ds, detections, float(sigma), min_score)
    metrics["simulated_cameras"] = simulated_cameras_block(ds, test)
    metrics["model_check"] = model_check_block(poses, test)
    metrics["bounds"] = statistic_bounds(test, rep, spec)
    metrics["uncertainty_budget"] = test_budget(ds, poses, test, noise)
    metrics["acceptance"] = verdict(metrics, spec)
    return metrics, rows


def test_budget(ds: Dataset, poses: dict, test: list[dict], noise: dict | None) -> dict:
    """The uncertainty budget over the solved test frames (eval.uncertainty_budget.budget_block);
    the detector bias term from the measured mean centre offset when detections were measured."""
    bias = ((noise or {}).get("overall") or {}).get("mean_px")
    records = [poses["frames"][r["frame_id"]] for r in test if r["ok"]]
    return budget_block(records, ds.markers(), (ds.config.image.width, ds.config.image.height), bias)


def pr_curves(labels: list[dict], frames_dets: dict, visible_threshold: float, max_points: int = 200) -> dict:
    """Precision-recall at IoU 0.5 per class: {class name: (recall list, precision list)}.

    Ground truth: markers with visible fraction >= ``visible_threshold`` and a legible colour; a
    detection that only overlaps an ignored marker (occluded or washed out) counts neither way.
    """
    curves = {}
    for c, name in enumerate(CLASS_NAMES):
        scored, n_gt = [], 0
        for lab in labels:
            marks = [m for m in lab["markers"] if m["class_id"] == c and m.get("bbox_px")]
            gt = [m for m in marks if m["visible_fraction"] >= visible_threshold and m.get("legible", True)]
            ign = [m for m in marks if m not in gt and m.get("visible_pixels")]
            dets = [d for d in frames_dets.get(lab["frame_id"], []) if d["class_id"] == c]
            n_gt += len(gt)
            if not dets:
                continue
            boxes = np.array([d["bbox_px"] for d in dets])
            scores = np.array([d["score"] for d in dets])
            match = match_frame(np.array([m["bbox_px"] for m in gt]).reshape(-1, 4), np.full(len(gt), c), boxes, scores, np.full(len(dets), c))
            tp = np.zeros(len(dets), bool)
            tp[match[match >= 0]] = True
            ignored = np.zeros(len(dets), bool)
            if ign:
                m_ign = match_frame(np.array([m["bbox_px"] for m in ign]).reshape(-1, 4), np.full(len(ign), c), boxes, scores, np.full(len(dets), c))
                ignored[m_ign[m_ign >= 0]] = True
            scored += [(s, bool(t)) for s, t, i in zip(scores, tp, ignored) if t or not i]
        if not scored or n_gt == 0:
            continue
        scored.sort(key=lambda x: -x[0])
        tps = np.cumsum([t for _, t in scored])
        recall = tps / n_gt
        precision = tps / np.arange(1, len(scored) + 1)
        keep = np.unique(np.linspace(0, len(scored) - 1, min(max_points, len(scored))).astype(int))
        curves[name] = (recall[keep].tolist(), precision[keep].tolist())
    return curves


def detection_block(ds: Dataset, detections: dict) -> dict:
    """mAP50 and mAP50:95 (pycocotools) per class and overall, centre error, recall and
    precision-recall curves (test split)."""
    r = evaluate_detections(ds, detections, split="test")
    out = {k: v for k, v in r.items() if k not in ("mAP50", "mAP50_95", "per_class")}
    out.update({"map50": r["mAP50"], "map50_95": r["mAP50_95"],
                "per_class": {n: {"map50": v["mAP50"], "map50_95": v["mAP50_95"]} for n, v in r["per_class"].items()}})
    labels = [ds.labels[f] for f in ds.frames(("test",))]
    out["pr_curves"] = pr_curves(labels, detections["frames"], ds.config.labels.visible_threshold)
    return out


CSV_FIELDS = (["frame_id", "split", "condition", "pose_index", "ok", "category", "reason", "distance_mm",
               "focal_true", "focal_est", "focal_err_pct", "visible_a", "visible_b", "rmse_px_a", "rmse_px_b"]
              + [f"{k}_{c}" for k in ("true", "est", "err", "crb") for c in COMPONENTS] + ["sigma_px"]
              + [f"{k}_{c}" for k in ("std", "z") for c in COMPONENTS]
              + [f"crb_iso_{c}" for c in COMPONENTS] + ["sigma_disc_px"]
              + [f"{k}_structured_{c}" for k in ("crb", "fit") for c in COMPONENTS])


def json_safe(obj):
    """NaN and inf become None (JSON has no NaN); numpy scalars become Python numbers."""
    if isinstance(obj, dict):
        return {k: json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    if isinstance(obj, (float, np.floating)):
        return float(obj) if np.isfinite(obj) else None
    if isinstance(obj, np.integer):
        return int(obj)
    return obj


def portable_path(path, folder) -> str:
    """``path`` as the evaluation in ``folder`` records it: relative to that folder, so the tree
    (dataset, poses, detections, evaluation) can move as one and ``report`` finds its inputs from
    any current folder (eval.report.document.input_path); absolute where no relative path exists."""
    try:
        return os.path.relpath(os.path.abspath(path), os.path.abspath(folder))
    except ValueError:   # another drive
        return os.path.abspath(path)


def write_outputs(out_dir, metrics: dict, rows: list[dict]) -> None:
    """Write an evaluation's ``frames.csv`` and ``metrics.json`` (atomically) into a folder.

    Parameters
    ----------
    out_dir : str or Path
        The folder (it exists); the metrics' dataset root and poses path are recorded relative to
        it (:func:`portable_path`), so the folder can move.
    metrics, rows : dict, list of dict
        What :func:`evaluate` returned.

    Returns
    -------
    None

    Raises
    ------
    OSError
        A file cannot be written (the one before keeps its bytes).
    """
    out = Path(out_dir)
    metrics = {**metrics, "dataset": {**metrics["dataset"], "root": portable_path(metrics["dataset"]["root"], out)},
               "poses": {**metrics["poses"], "path": portable_path(metrics["poses"]["path"], out)}}
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=CSV_FIELDS, extrasaction="ignore")
    w.writeheader()
    for r in rows:
        w.writerow({k: ("" if r.get(k) is None else r.get(k)) for k in CSV_FIELDS})
    write_text_atomic(out / "frames.csv", buf.getvalue())
    write_json_atomic(out / "metrics.json", json_safe(metrics))
