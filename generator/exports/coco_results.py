"""Detections as a COCO results file: the list ``COCO.loadRes`` and ``COCOeval`` (and FiftyOne's
COCO importers) take, with the image and category ids of the dataset's COCO export.

One row per detection::

    {"image_id", "category_id", "bbox": [x, y, w, h], "score", "keypoints": [x, y, v]}

Why and how: docs/datasets.md, "COCO results rows".
"""
from __future__ import annotations

from dockfactory.core.errors import DockfactoryError
from dockfactory.generator.exports.coco import COCO_SHIFT, coco_image_ids

RESULT_DECIMALS = 4   # 1e-4 px: far below any detector's error, and a compact file


def detection_row(image_id: int, det: dict) -> dict:
    """The COCO results row of one detection record (detector.infer's ``{class_id, score, bbox_px,
    center_px, ...}``, OpenCV pixels) of image ``image_id``."""
    x0, y0, x1, y1 = (float(v) for v in det["bbox_px"])
    u, v = (float(c) for c in det["center_px"])
    r = RESULT_DECIMALS
    return {"image_id": image_id, "category_id": int(det["class_id"]) + 1,
            "bbox": [round(x0 + COCO_SHIFT, r), round(y0 + COCO_SHIFT, r), round(x1 - x0, r), round(y1 - y0, r)],
            "score": round(float(det["score"]), 6), "keypoints": [round(u, r), round(v, r), 2]}


def coco_results(splits: dict[str, str], detections: dict) -> list[dict]:
    """The COCO results rows of a detections document.

    Parameters
    ----------
    splits : dict
        Frame id -> split in plan order (``Dataset.splits``) of the dataset detected on.
    detections : dict
        The detections document (``{"frames": {frame_id: [det, ...]}}``, detector.infer.detect_dataset's JSON).

    Returns
    -------
    list of dict
        One row per detection: frames in image id order, each frame's detections in their order.

    Raises
    ------
    DockfactoryError
        When the document has no frames object, or naming the frame when a frame id is not one of the dataset's.
    """
    ids = coco_image_ids(splits)
    frames = detections.get("frames") if isinstance(detections, dict) else None
    if not isinstance(frames, dict):
        raise DockfactoryError("detections: no 'frames' object (not a dockfactory detections document)")
    unknown = sorted(set(frames) - set(ids))
    if unknown:
        raise DockfactoryError(f"detections: frame {unknown[0]!r} is not a frame of the dataset")
    return [detection_row(ids[fid], det) for fid in ids if fid in frames for det in frames[fid]]
