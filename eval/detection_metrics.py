"""Detection metrics: COCO mAP (pycocotools COCOeval), centre error, recall of visible markers.

Also YOLOv5's mAP (``"yolov5"``) and the network's own boxes' (``"network_boxes"``); illegible markers are ignored.

Why and how: docs/detector.md, "Detection metrics".
"""
from __future__ import annotations

import contextlib
import io
import json
from pathlib import Path

import numpy as np
from pycocotools.coco import COCO
from pycocotools.cocoeval import COCOeval

from dockfactory.core.errors import DockfactoryError
from dockfactory.core.names import MIN_SCORE
from dockfactory.eval.boxes import iou_matrix
from dockfactory.eval.yolov5_ap import yolov5_map
from dockfactory.generator.exports import coco_from_labels

COCO_SHIFT = 0.5
NORMAL_CONDITIONS = ("normal", "ideal")


def coco_results(frames_dets: dict, coco_gt: dict) -> list[dict]:
    """COCO result rows from ``{frame_id: [det]}`` (OpenCV px) for the images of ``coco_gt``."""
    ids = {img["frame_id"]: img["id"] for img in coco_gt["images"]}
    rows = []
    for fid, dets in frames_dets.items():
        if fid not in ids:
            continue
        for d in dets:
            x0, y0, x1, y1 = (float(v) for v in d["bbox_px"])
            rows.append({"image_id": ids[fid], "category_id": int(d["class_id"]) + 1,
                         "bbox": [x0 + COCO_SHIFT, y0 + COCO_SHIFT, x1 - x0, y1 - y0], "score": float(d["score"])})
    return rows


def network_boxes(frames_dets: dict) -> dict | None:
    """``{frame_id: [det]}`` with each detection's box replaced by the network's own
    (``bbox_detector_px``, before the edge-fit refinement), or None when a detection lacks it."""
    out = {}
    for fid, dets in frames_dets.items():
        if any("bbox_detector_px" not in d for d in dets):
            return None
        out[fid] = [{**d, "bbox_px": d["bbox_detector_px"]} for d in dets]
    return out


def coco_map(coco_gt: dict, results: list[dict]) -> dict:
    """``{"mAP50", "mAP50_95", "per_class": {name: {"mAP50", "mAP50_95"}}}`` with COCOeval."""
    names = {c["id"]: c["name"] for c in coco_gt["categories"]}
    empty = {"mAP50": 0.0, "mAP50_95": 0.0, "per_class": {n: {"mAP50": 0.0, "mAP50_95": 0.0} for n in names.values()}}
    if not results:
        return empty
    with contextlib.redirect_stdout(io.StringIO()):
        gt = COCO()
        gt.dataset = json.loads(json.dumps(coco_gt))
        gt.createIndex()
        dt = gt.loadRes(json.loads(json.dumps(results)))
        ev = COCOeval(gt, dt, "bbox")
        ev.evaluate()
        ev.accumulate()
        ev.summarize()
    prec = ev.eval["precision"]  # (T iou, R recall, K class, A area, M maxdets)
    per = {}
    for k, cat in enumerate(ev.params.catIds):
        p_all = prec[:, :, k, 0, -1]
        p50 = prec[0, :, k, 0, -1]
        per[names[cat]] = {"mAP50": float(p50[p50 > -1].mean()) if (p50 > -1).any() else float("nan"),
                           "mAP50_95": float(p_all[p_all > -1].mean()) if (p_all > -1).any() else float("nan")}
    return {"mAP50": float(ev.stats[1]), "mAP50_95": float(ev.stats[0]), "per_class": per}


def match_frame(gt_boxes, gt_classes, det_boxes, det_scores, det_classes, iou_threshold: float = 0.5):
    """Greedy one-to-one matching by falling score within each class.

    ``gt_boxes: (G, 4)``, ``gt_classes: (G,)``, ``det_boxes: (D, 4)``, ``det_scores: (D,)``,
    ``det_classes: (D,)``. Returns ``(G,) int64``: the matched detection index or -1.
    """
    gt_boxes = np.asarray(gt_boxes, dtype=np.float64).reshape(-1, 4)
    det_boxes = np.asarray(det_boxes, dtype=np.float64).reshape(-1, 4)
    gt_classes, det_classes = np.asarray(gt_classes).reshape(-1), np.asarray(det_classes).reshape(-1)
    det_scores = np.asarray(det_scores, dtype=np.float64).reshape(-1)
    if len(gt_classes) != len(gt_boxes) or not (len(det_boxes) == len(det_scores) == len(det_classes)):
        raise ValueError("match_frame: boxes, scores and classes must have matching lengths")
    match = np.full(len(gt_boxes), -1, dtype=np.int64)
    if len(gt_boxes) == 0 or len(det_boxes) == 0:
        return match
    iou = iou_matrix(det_boxes, gt_boxes)
    iou[det_classes[:, None] != gt_classes[None, :]] = -1
    for d in np.argsort(-det_scores, kind="stable"):
        cand = np.where(match == -1, iou[d], -1)
        g = int(np.argmax(cand))
        if cand[g] >= iou_threshold:
            match[g] = d
    return match


def evaluate_detections(ds, detections, split: str | None = None, recall_conf: float = MIN_SCORE) -> dict:
    """Every detection metric of a detections document against a dataset's labels.

    Parameters
    ----------
    ds : Dataset
        The opened dataset; its planned frames are the labelled ones (never a folder listing).
    detections : dict, str or Path
        A detections document (``detect``) or its file.
    split, recall_conf : str or None, float
        The split scored (None: the detections'); the score a detection needs to count for recall.

    Returns
    -------
    dict
        COCO mAP (and YOLOv5's), the network's boxes alone, centre errors and recall, with the
        frame count, split and versions.

    Raises
    ------
    DockfactoryError
        Not a detections document, or no labelled frame of the split has detections (one line).
    """
    doc = json.loads(Path(detections).read_text()) if isinstance(detections, (str, Path)) else detections
    if "frames" not in doc:
        raise DockfactoryError("detections: no 'frames' (not a dockfactory detections file?)")
    split = split if split is not None else doc.get("split")
    threshold = ds.config.labels.visible_threshold
    labels = [lab for lab in ds.labels_of(split) if lab["frame_id"] in doc["frames"]]
    if not labels:
        raise DockfactoryError(f"no labelled frame of split {split!r} has detections")
    gt = coco_from_labels(labels, threshold)
    rows = coco_results(doc["frames"], gt)
    result = coco_map(gt, rows)
    result["yolov5"] = yolov5_map(gt, rows)
    net = network_boxes(doc["frames"])
    if net is not None:     # the network's boxes alone: what the paper's detector tables score
        net_rows = coco_results(net, gt)
        result["network_boxes"] = {**coco_map(gt, net_rows), "yolov5": yolov5_map(gt, net_rows)}
    result.update(centre_and_recall(labels, doc["frames"], threshold, recall_conf))
    result.update({"frames": len(labels), "split": split, "dataset_version": ds.version_id,
                   "detections_dataset_version": doc.get("dataset_version"),
                   "weights_sha256": doc.get("weights_sha256")})
    return result


def centre_and_recall(labels: list[dict], frames_dets: dict, threshold: float = 0.5, recall_conf: float = MIN_SCORE) -> dict:
    errs = {"normal": [], "challenging": []}
    by_condition: dict[str, list] = {}
    seen = found = 0
    for lab in labels:
        ms = [m for m in lab["markers"] if m.get("visible_pixels") and m.get("bbox_px") is not None
              and m["visible_fraction"] >= threshold and m.get("legible", True)]
        dets = frames_dets.get(lab["frame_id"], [])
        gb = np.array([m["bbox_px"] for m in ms], dtype=np.float64).reshape(-1, 4)
        gc = np.array([m["class_id"] for m in ms], dtype=np.int64)
        db = np.array([d["bbox_px"] for d in dets], dtype=np.float64).reshape(-1, 4)
        ds = np.array([d["score"] for d in dets], dtype=np.float64)
        dc = np.array([d["class_id"] for d in dets], dtype=np.int64)
        match = match_frame(gb, gc, db, ds, dc)
        group = "normal" if lab["spec"]["condition"] in NORMAL_CONDITIONS else "challenging"
        for m, d in zip(ms, match):
            if d >= 0:
                e = np.hypot(*(np.asarray(dets[d]["center_px"]) - np.asarray(m["center_px"])))
                errs[group].append(float(e))
                by_condition.setdefault(lab["spec"]["condition"], []).append(float(e))
        strong = match[(match >= 0)]
        seen += len(ms)
        found += int(sum(ds[d] >= recall_conf for d in strong))

    def stats(v):
        v = np.asarray(v)
        if len(v) == 0:     # no such markers (the repeat split has no challenging frames): no figure
            return {"n": 0, "median_px": None, "mean_px": None, "p90_px": None}
        return {"n": int(len(v)), "median_px": float(np.median(v)), "mean_px": float(v.mean()),
                "p90_px": float(np.percentile(v, 90))}
    return {"centre_error": {k: stats(v) for k, v in errs.items()},
            "centre_error_by_condition": {k: stats(v) for k, v in sorted(by_condition.items())},
            "recall_visible50": found / seen if seen else None, "recall_markers": seen,
            "recall_conf": recall_conf}


def format_report(m: dict) -> str:
    lines = [f"frames {m['frames']} (split {m['split']}, dataset {m['dataset_version']})",
             "| class | mAP50 | mAP50:95 |", "| --- | --- | --- |",
             f"| all | {m['mAP50']:.4f} | {m['mAP50_95']:.4f} |"]
    lines += [f"| {k} | {v['mAP50']:.4f} | {v['mAP50_95']:.4f} |" for k, v in m["per_class"].items()]
    if "yolov5" in m:
        lines.append(f"YOLOv5 val.py's mAP (tops out at 0.995): mAP50 {m['yolov5']['mAP50']:.4f}, "
                     f"mAP50:95 {m['yolov5']['mAP50_95']:.4f}")
    if "network_boxes" in m:
        nb = m["network_boxes"]
        lines.append(f"the network's boxes, before refinement: mAP50 {nb['mAP50']:.4f}, mAP50:95 {nb['mAP50_95']:.4f} "
                     f"(YOLOv5's {nb['yolov5']['mAP50']:.4f}, {nb['yolov5']['mAP50_95']:.4f})")
    for k, v in {**m["centre_error"], **m.get("centre_error_by_condition", {})}.items():
        if not v["n"]:
            lines.append(f"centre error {k}: no matched markers")
            continue
        lines.append(f"centre error {k}: median {v['median_px']:.4f} px, mean {v['mean_px']:.4f}, "
                     f"p90 {v['p90_px']:.4f} (n {v['n']})")
    recall = "—" if m["recall_visible50"] is None else f"{m['recall_visible50']:.4f}"
    lines.append(f"recall (visible fraction >= 0.5, score >= {m['recall_conf']}): {recall} of {m['recall_markers']}")
    return "\n".join(lines)
