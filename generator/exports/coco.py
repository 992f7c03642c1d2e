"""COCO keypoint JSON from a dataset's labels (loads in pycocotools, detectron2 and datumaro).

    exports/coco/
      annotations/person_keypoints_<split>.json   split: train, val, test, repeat (when not empty)
      images/<split>/<frame_id>.png               hard links to the dataset's images (else copies)

Why and how: docs/datasets.md, "The COCO export's annotations".
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from dockfactory.core.io import write_json_atomic
from dockfactory.core.layout import CLASS_NAMES, Marker, marker_outline
from dockfactory.core.names import SPLITS
from dockfactory.generator.datasets.reader import Dataset
from dockfactory.generator.exports.files import place_file, source_image
from dockfactory.generator.exports.registry import ExportFormat
from dockfactory.generator.labels import clip_polygon, image_px, marker_outline_px
from dockfactory.generator.motion import label_rolling_view

COCO_SHIFT = 0.5          # OpenCV pixel centres -> COCO continuous coordinates (boxes, polygons)
KEYPOINTS = ("centre",)
# The sigma COCO gives eyes, its most precisely placed keypoints. With the marker's area A as the
# scale, OKS = exp(-d^2 / (2 A (2 sigma)^2)) falls to 0.5 at d ~ 0.1 marker radius.
KPT_OKS_SIGMAS = (0.025,)
POLYGON_TOLERANCE_PX = 0.02   # the written polygon stays this close to the label's outline
POLYGON_DECIMALS = 3

KEYPOINTS_TO_CONTINUOUS = (
    "keypoints are pixel indices: add 0.5 to x and y of each keypoint with v > 0 to get continuous "
    "coordinates (the frame of bbox) before normalising by the image size; ultralytics' "
    "convert_coco(use_keypoints=True) does not, so add it to the JSON before converting (or use the "
    "yolo-pose export, which has it)")

CONVENTIONS = {
    "bbox": "continuous: (0,0) is the top-left corner of the top-left pixel (label bbox_px + 0.5)",
    "segmentation": "continuous, like bbox: the marker outline clipped to the image (label + 0.5)",
    "keypoints": "pixel indices: OpenCV, (0,0) is the centre of the top-left pixel (label center_px "
                 "unchanged); consumers such as detectron2 add 0.5 on loading",
}


def categories() -> list[dict]:
    return [{"id": i + 1, "name": name, "supercategory": "marker", "keypoints": list(KEYPOINTS),
             "skeleton": []} for i, name in enumerate(CLASS_NAMES)]


def coco_info(**extra) -> dict:
    return {"description": "dockfactory markers", "pixel_conventions": dict(CONVENTIONS),
            "kpt_oks_sigmas": list(KPT_OKS_SIGMAS), "keypoints_to_continuous": KEYPOINTS_TO_CONTINUOUS,
            "segmentation": f"clipped marker outline, within {POLYGON_TOLERANCE_PX} px of the "
                            f"label's outline polygon; amodal (occluders not cut out)", **extra}


# ----------------------------------------------------------------------------- outlines

def read_layout(root) -> dict[str, Marker] | None:
    """Markers of a dataset's layout.json by id (None when the file is missing)."""
    path = Path(root) / "layout.json"
    if not path.exists():
        return None
    recs = json.loads(path.read_text())["markers"]
    return {r["id"]: Marker(r["id"], r["section"], r["index"], tuple(r["center_mm"]), tuple(r["normal"]),
                            r["diameter_mm"]) for r in recs}


def outline_px(label: dict, marker: Marker) -> np.ndarray:
    """The marker's outline in the delivered image clipped to the image, (M, 2) float64 OpenCV px.

    The same computation as the label's ``bbox_px`` (generator.labels.frame_labels), on the
    label's K, lens distortion, ``cam_from_d`` and ``d_from_b`` (a marker of B under a rolling
    shutter: at its points' row times, ``generator.motion``); (0, 2) when the outline is not in
    front of the camera or not in the image.
    """
    w, h = label["image"]["width"], label["image"]["height"]
    cam = label["camera"]
    k = np.asarray(cam["K"], dtype=np.float64)
    rolling = label_rolling_view(label) if marker.section == "B" else None
    if rolling is not None:
        pinhole, z, _ = rolling.project(marker_outline(marker))
        uv = image_px(pinhole, k, cam.get("distortion"))
    else:
        d_from_s = np.asarray(label["d_from_b"], dtype=np.float64) if marker.section == "B" else np.eye(4)
        cam_from_s = np.asarray(cam["cam_from_d"], dtype=np.float64) @ d_from_s
        uv, z = marker_outline_px(marker, k, cam.get("distortion"), cam_from_s)
    if not np.all(z > 0):
        return np.zeros((0, 2))
    bounds = (-0.5, -0.5, w - 0.5, h - 0.5)
    inside = (uv[:, 0].min() >= bounds[0] and uv[:, 1].min() >= bounds[1]
              and uv[:, 0].max() <= bounds[2] and uv[:, 1].max() <= bounds[3])
    return uv if inside else clip_polygon(uv, *bounds)


def simplify_closed(poly: np.ndarray, tolerance: float) -> np.ndarray:
    """Ramer-Douglas-Peucker on a closed polygon (N, 2): every dropped vertex lies within
    ``tolerance`` of the kept outline. Returns (M, 2), M <= N, vertices in their order."""
    n = len(poly)
    if n <= 4:
        return poly
    far = int(np.argmax(np.hypot(*(poly - poly[0]).T)))
    chain = np.vstack([poly, poly[:1]])
    keep = np.zeros(n, dtype=bool)
    keep[[0, far]] = True
    stack = [(0, far), (far, n)]
    while stack:
        a, b = stack.pop()
        if b - a < 2:
            continue
        p, seg = chain[a], chain[a + 1:b] - chain[a]
        d = chain[b] - p
        length = np.hypot(*d)
        dist = np.abs(d[0] * seg[:, 1] - d[1] * seg[:, 0]) / length if length > 0 else np.hypot(*seg.T)
        i = int(np.argmax(dist))
        if dist[i] > tolerance:
            keep[a + 1 + i] = True
            stack += [(a, a + 1 + i), (a + 1 + i, b)]
    return poly[keep]


def segmentation(label: dict, marker: Marker | None) -> list:
    """COCO polygon list of the marker's clipped outline ([] without geometry)."""
    if marker is None or "camera" not in label or "d_from_b" not in label:
        return []
    poly = outline_px(label, marker)
    if len(poly) < 3:
        return []
    simple = simplify_closed(poly, POLYGON_TOLERANCE_PX)
    poly = (simple if len(simple) >= 3 else poly) + COCO_SHIFT
    return [np.round(poly, POLYGON_DECIMALS).ravel().tolist()]


# ----------------------------------------------------------------------------- annotations

def centre_in_image(m: dict, w: int, h: int) -> bool:
    if "in_frame" in m:
        return bool(m["in_frame"])
    u, v = m["center_px"]
    return -0.5 <= u <= w - 0.5 and -0.5 <= v <= h - 0.5


def marker_annotation(label: dict, m: dict, visible_threshold: float, marker: Marker | None) -> dict:
    """One COCO annotation (without ids) of label marker record ``m``."""
    x0, y0, x1, y1 = m["bbox_px"]
    visible = m["visible_fraction"] >= visible_threshold and m.get("legible", True)
    if centre_in_image(m, label["image"]["width"], label["image"]["height"]):
        u, v = m["center_px"]
        keypoints, n_kp = [float(u), float(v), 2 if m.get("visibility", 2) == 2 else 1], 1
    else:
        keypoints, n_kp = [0, 0, 0], 0
    return {"category_id": m["class_id"] + 1,
            "bbox": [x0 + COCO_SHIFT, y0 + COCO_SHIFT, x1 - x0, y1 - y0],
            "segmentation": segmentation(label, marker), "area": m["area_in_frame_px"],
            "iscrowd": 0 if visible else 1, "keypoints": keypoints, "num_keypoints": n_kp,
            "marker_id": m["id"], "visible_fraction": m["visible_fraction"]}


def camera_units_info(labels: list[dict]) -> dict:
    """Per camera unit (id as a string): its lens as the labels record it."""
    units = {}
    for lab in labels:
        if "camera" not in lab:
            continue
        cam = lab["camera"]
        units.setdefault(str(cam.get("unit", 0)), {
            "dist_coeffs": cam.get("distortion", [0.0] * 5), "dist_coeff_names": ["k1", "k2", "p1", "p2", "k3"],
            "principal_point": cam["principal_point"], "aberration_px": cam.get("aberration_px"),
            "depth_of_field": cam.get("depth_of_field"), "jpeg_quality": cam.get("jpeg_quality")})
    return dict(sorted(units.items(), key=lambda kv: int(kv[0])))


def _image_record(image_id: int, lab: dict) -> dict:
    rec = {"id": image_id, "file_name": f"{lab['frame_id']}.png", "frame_id": lab["frame_id"],
           "width": lab["image"]["width"], "height": lab["image"]["height"],
           "condition": lab["spec"]["condition"], "split": lab["spec"]["split"]}
    cam = lab.get("camera")
    if cam is not None:
        rec.update(camera_unit=cam.get("unit", 0), K=cam["K"], dist_coeffs=cam.get("distortion", [0.0] * 5))
    return rec


def coco_from_labels(labels: list[dict], visible_threshold: float = 0.5, *, layout: dict | None = None,
                     first_image_id: int = 1, first_annotation_id: int = 1, info: dict | None = None) -> dict:
    """The COCO keypoints dict of dataset labels.

    Parameters
    ----------
    labels : list of dict
        The frames' labels (``labels/<frame_id>.json``), in image id order.
    visible_threshold : float
        The visible fraction from which a marker is annotated as visible.
    layout : dict, optional
        Marker id -> Marker: gives the polygons (no polygons without it).
    first_image_id, first_annotation_id : int
        The ids of the first image and of the first annotation.
    info : dict, optional
        The ``info`` block (``coco_info()`` without it).

    Returns
    -------
    dict
        ``info``, ``images``, ``annotations``, ``categories``.

    Raises
    ------
    KeyError
        When a label lacks a field the export reads.
    """
    images, annotations = [], []
    for image_id, lab in enumerate(labels, start=first_image_id):
        images.append(_image_record(image_id, lab))
        for m in lab["markers"]:
            if not m.get("visible_pixels") or m["bbox_px"] is None:
                continue
            ann = marker_annotation(lab, m, visible_threshold, (layout or {}).get(m["id"]))
            annotations.append({"id": first_annotation_id + len(annotations), "image_id": image_id, **ann})
    return {"info": info if info is not None else coco_info(), "images": images,
            "annotations": annotations, "categories": categories()}


def coco_image_ids(splits: dict[str, str]) -> dict[str, int]:
    """frame id -> COCO image id of the export: ids run from 1 over the split files in SPLITS order
    (train, val, test, repeat), each split's frames in plan order. ``splits``: frame id -> split in
    plan order (``Dataset.splits``)."""
    order = [fid for split in SPLITS for fid, s in splits.items() if s == split]
    return {fid: i for i, fid in enumerate(order, start=1)}


def export_coco(root, out) -> Path:
    """Write the COCO export of dataset ``root`` into ``out`` (layout in the module docstring).

    Parameters
    ----------
    root : path or Dataset
        The dataset: its folder, or a Dataset already opened (by a caller writing several formats).
    out : path
        The export's folder (created; files in it are replaced).

    Returns
    -------
    Path
        ``out``.

    Raises
    ------
    DatasetError
        When the dataset is not intact and complete, or a file of it cannot be read.
    """
    out = Path(out)
    # intact and complete (opened here, or by the caller that exports several formats): its
    # frames are the plan's, ids and splits checked
    ds = root if isinstance(root, Dataset) else Dataset.open(root)
    root = ds.root
    ident = ds.identity
    threshold = ident["config"]["labels"]["visible_threshold"]
    layout = read_layout(root)
    labels = ds.labels_of()
    image_ids = coco_image_ids(ds.splits)
    next_ann = 1
    for split in SPLITS:
        split_labels = [lab for lab in labels if lab["spec"]["split"] == split]
        if not split_labels:
            continue
        info = coco_info(version=str(ident.get("version_id", "")), dataset=ident.get("name", ""), split=split,
                         cameras=camera_units_info(split_labels))
        coco = coco_from_labels(split_labels, threshold, layout=layout,
                                first_image_id=image_ids[split_labels[0]["frame_id"]],
                                first_annotation_id=next_ann, info=info)
        next_ann += len(coco["annotations"])
        for lab in split_labels:
            place_file(source_image(root, lab["frame_id"]), out / "images" / split / f"{lab['frame_id']}.png")
        write_json_atomic(out / "annotations" / f"person_keypoints_{split}.json", coco, indent=None)
    return out


FORMATS = (
    ExportFormat("coco", export_coco, "COCO keypoints, boxes and outlines, one JSON per split"),
)
