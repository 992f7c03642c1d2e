"""COCO detection/keypoint JSON from a dataset's labels (loads in pycocotools).

- one image per frame of the split, ids from 1 in frame order;
- categories 1 RedA and 2 BlueB (ids start at 1: pycocotools treats 0 as unmatched);
- one annotation per marker that has visible pixels: ``bbox`` [x, y, w, h] is the projected
  marker outline clipped to the image, ``keypoints`` [x, y, v] its projected centre, ``area``
  the projected disc area inside the image; a marker whose visible fraction is below the
  dataset's ``visible_threshold``, or whose colour is washed out (label ``legible`` false), gets
  ``iscrowd`` 1 (an ignore region: finding it neither helps nor hurts mAP); fully hidden and
  out-of-frame markers get no annotation.
- COCO's pixel convention: (0, 0) is the top-left corner of the top-left pixel, so every
  coordinate is the label's (OpenCV convention) + 0.5.
"""
from __future__ import annotations

import json
from pathlib import Path

from dockfactory.core.io import load_labels, write_json_atomic
from dockfactory.core.layout import CLASS_NAMES

COCO_SHIFT = 0.5  # OpenCV pixel centres -> COCO pixel corners


def categories() -> list[dict]:
    return [{"id": i + 1, "name": name, "supercategory": "marker", "keypoints": ["centre"],
             "skeleton": []} for i, name in enumerate(CLASS_NAMES)]


def coco_from_labels(labels: list[dict], visible_threshold: float = 0.5) -> dict:
    images, annotations = [], []
    for image_id, lab in enumerate(labels, start=1):
        images.append({"id": image_id, "file_name": f"{lab['frame_id']}.png", "frame_id": lab["frame_id"],
                       "width": lab["image"]["width"], "height": lab["image"]["height"],
                       "condition": lab["spec"]["condition"], "split": lab["spec"]["split"]})
        for m in lab["markers"]:
            if not m.get("visible_pixels") or m["bbox_px"] is None:
                continue
            x0, y0, x1, y1 = m["bbox_px"]
            u, v = m["center_px"]
            visible = m["visible_fraction"] >= visible_threshold and m.get("legible", True)
            annotations.append({
                "id": len(annotations) + 1, "image_id": image_id, "category_id": m["class_id"] + 1,
                "bbox": [x0 + COCO_SHIFT, y0 + COCO_SHIFT, x1 - x0, y1 - y0],
                "area": m["area_in_frame_px"], "iscrowd": 0 if visible else 1,
                "keypoints": [u + COCO_SHIFT, v + COCO_SHIFT, 2 if m["visibility"] == 2 else 1],
                "num_keypoints": 1, "marker_id": m["id"], "visible_fraction": m["visible_fraction"],
            })
    return {"info": {"description": "dockfactory markers", "pixel_convention":
                     "COCO: (0,0) is the top-left corner of the top-left pixel"},
            "images": images, "annotations": annotations, "categories": categories()}


def write_coco(root, split: str, out_path) -> Path:
    root = Path(root)
    ident = json.loads((root / "dataset.json").read_text())
    threshold = ident["config"]["labels"]["visible_threshold"]
    coco = coco_from_labels(load_labels(root, split), threshold)
    write_json_atomic(out_path, coco, indent=None)
    return Path(out_path)


def export_coco(root, out) -> Path:
    for split in ("train", "test", "repeat"):
        write_coco(root, split, Path(out) / f"{split}.json")
    return Path(out)
