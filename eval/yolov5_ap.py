"""mAP as YOLOv5's ``val.py`` computes it, beside the COCO figure, for comparing with papers that
report YOLOv5's numbers (ours: reference.md, Table 1).

Why and how: docs/detector.md, "YOLOv5's mAP".
"""
from __future__ import annotations

import numpy as np

from dockfactory.eval.boxes import iou_matrix

IOU_THRESHOLDS = np.linspace(0.5, 0.95, 10)
RECALL_POINTS = np.linspace(0.0, 1.0, 101)


def correct_matrix(gt_boxes, gt_classes, det_boxes, det_classes) -> np.ndarray:
    """``(D, 10) bool``: detection d is a true positive at IoU threshold t (YOLOv5's rule)."""
    gt_boxes = np.asarray(gt_boxes, dtype=np.float64).reshape(-1, 4)
    det_boxes = np.asarray(det_boxes, dtype=np.float64).reshape(-1, 4)
    correct = np.zeros((len(det_boxes), len(IOU_THRESHOLDS)), dtype=bool)
    if len(gt_boxes) == 0 or len(det_boxes) == 0:
        return correct
    iou = iou_matrix(gt_boxes, det_boxes)
    same = np.asarray(gt_classes).reshape(-1, 1) == np.asarray(det_classes).reshape(1, -1)
    for t, thr in enumerate(IOU_THRESHOLDS):
        g, d = np.nonzero((iou >= thr) & same)
        order = np.argsort(-iou[g, d], kind="stable")
        used_g, used_d = set(), set()
        for gi, di in zip(g[order], d[order]):
            if gi not in used_g and di not in used_d:
                used_g.add(gi)
                used_d.add(di)
                correct[di, t] = True
    return correct


def interpolated_ap(recall: np.ndarray, precision: np.ndarray) -> float:
    """YOLOv5's ``compute_ap`` ('interp'): envelope, 101 points, trapezoid rule."""
    mrec = np.concatenate(([0.0], recall, [1.0]))
    mpre = np.concatenate(([1.0], precision, [0.0]))
    mpre = np.flip(np.maximum.accumulate(np.flip(mpre)))
    y = np.interp(RECALL_POINTS, mrec, mpre)
    return float(np.sum((y[1:] + y[:-1]) * np.diff(RECALL_POINTS)) / 2.0)


def class_ap(correct: np.ndarray, scores: np.ndarray, n_gt: int) -> np.ndarray:
    """``(10,)`` AP of one class at each IoU threshold; zeros without detections or ground truth."""
    if n_gt == 0 or len(scores) == 0:
        return np.zeros(len(IOU_THRESHOLDS))
    tp = correct[np.argsort(-scores, kind="stable")].astype(np.float64)
    tpc, fpc = tp.cumsum(0), (1.0 - tp).cumsum(0)
    recall, precision = tpc / (n_gt + 1e-16), tpc / (tpc + fpc)
    return np.array([interpolated_ap(recall[:, t], precision[:, t]) for t in range(tp.shape[1])])


def _frame_arrays(coco_gt: dict, results: list[dict]):
    """Per image: (gt boxes, gt classes) and (det boxes, det classes, scores), boxes as corners."""
    gts: dict[int, list] = {img["id"]: [] for img in coco_gt["images"]}
    for a in coco_gt["annotations"]:
        if not a.get("iscrowd", 0):
            x, y, w, h = a["bbox"]
            gts.setdefault(a["image_id"], []).append((x, y, x + w, y + h, a["category_id"]))
    dts: dict[int, list] = {}
    for r in results:
        x, y, w, h = r["bbox"]
        dts.setdefault(r["image_id"], []).append((x, y, x + w, y + h, r["category_id"], r["score"]))
    for img in gts:
        g = np.asarray(gts[img], dtype=np.float64).reshape(-1, 5)
        d = np.asarray(dts.get(img, []), dtype=np.float64).reshape(-1, 6)
        yield g[:, :4], g[:, 4], d[:, :4], d[:, 4], d[:, 5]


def yolov5_map(coco_gt: dict, results: list[dict]) -> dict:
    """``{"mAP50", "mAP50_95", "per_class": {name: {...}}}`` the way YOLOv5's val.py computes them,
    from the same COCO ground truth and result rows (COCO bbox [x, y, w, h]) as ``coco_map``."""
    corr, cls, conf, gt_cls = [], [], [], []
    for gb, gc, db, dc, ds in _frame_arrays(coco_gt, results):
        corr.append(correct_matrix(gb, gc, db, dc))
        cls.append(dc)
        conf.append(ds)
        gt_cls.append(gc)
    corr_all = np.concatenate(corr) if corr else np.zeros((0, len(IOU_THRESHOLDS)), bool)
    cls_all = np.concatenate(cls) if cls else np.zeros(0)
    conf_all = np.concatenate(conf) if conf else np.zeros(0)
    gt_all = np.concatenate(gt_cls) if gt_cls else np.zeros(0)
    per, aps = {}, []
    for cat in coco_gt["categories"]:
        sel = cls_all == cat["id"]
        ap = class_ap(corr_all[sel], conf_all[sel], int(np.sum(gt_all == cat["id"])))
        aps.append(ap)
        per[cat["name"]] = {"mAP50": float(ap[0]), "mAP50_95": float(ap.mean())}
    aps = np.asarray(aps).reshape(-1, len(IOU_THRESHOLDS))
    return {"mAP50": float(aps[:, 0].mean()) if len(aps) else 0.0,
            "mAP50_95": float(aps.mean()) if len(aps) else 0.0, "per_class": per}
