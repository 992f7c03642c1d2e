"""Exports read back the way users' tools read them, from a copied and moved export folder.

The dataset is built without rendering: planned frames of a small config, labels from
generator.labels.frame_labels on a rasterised index pass (markers' projected outlines), and a
flat image with the markers painted in their colours. One frame has its principal point shifted
so that a marker's centre falls outside the image while part of its disc stays in view; some
markers are mostly hidden (crowd) and one is washed out (not legible).
"""
import dataclasses
import json
import os
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from pipeline_data import seal_hand_made

from dockfactory.core.config import config_from_dict
from dockfactory.core.geometry import (
    polygon_area_centroid,
    project_points,
    transform_points,
)
from dockfactory.core.io import write_bytes_atomic, write_json_atomic
from dockfactory.core.layout import CLASS_NAMES, marker_outline
from dockfactory.generator.datasets import tools as dt
from dockfactory.generator.datasets.folder import prepare
from dockfactory.generator.datasets.reader import Dataset
from dockfactory.generator.random_draws import static_scene
from dockfactory.generator.exports.coco import (
    KPT_OKS_SIGMAS,
    POLYGON_TOLERANCE_PX,
    outline_px,
    read_layout,
)
from dockfactory.generator.exports.yolo import data_yaml, parse_yolo_line
from dockfactory.generator.labels import frame_labels
from dockfactory.generator.sampler import frame_plan, sample_frame

CONFIG = {"dataset": {"name": "exports", "seed": 3, "frames": 16, "train_fraction": 0.75, "val_fraction": 0.25},
          "conditions": {"normal": 1, "low_light": 1, "occlusion": 1, "glare": 1},
          "repeatability": {"poses": 1, "captures": 2},
          "image": {"width": 320, "height": 240}, "camera": {"focal_px": [300.0, 750.0], "margin_px": 12.0},
          "export": {"formats": ["coco", "yolo", "bop"]}}
THRESHOLD = 0.5
OUT_OF_IMAGE_FRAME = "000003"


def shift_marker_out(frame, static):
    """The frame with its principal point moved so its leftmost marker's centre is 0.4 radius left
    of the image (the rest of that disc stays in view)."""
    base = frame_labels(frame, static, None, THRESHOLD)["markers"]
    m = min(base, key=lambda r: r["center_px"][0])
    radius = (m["bbox_px"][2] - m["bbox_px"][0]) / 2
    cx, cy = frame.camera.principal_point
    cx -= m["center_px"][0] + 0.5 + 0.4 * radius
    return dataclasses.replace(frame, camera=dataclasses.replace(frame.camera, principal_point=(cx, cy)))


def index_and_image(frame, static, hide: dict, washed: set):
    """Index pass (H, W) int32 with every marker's outline filled; ``hide``: marker id -> share of
    its pixels (left part) set to background; image (H, W, 3) uint8 with markers in their colour
    (``washed`` ones white)."""
    cam = frame.camera
    index = np.zeros((cam.height, cam.width), np.int32)
    for m in static.markers:
        d_from_s = frame.d_from_b_array() if m.section == "B" else np.eye(4)
        uv, _ = project_points(cam.k(), cam.cam_from_d_array(), transform_points(d_from_s, marker_outline(m)))
        cv2.fillPoly(index, [np.round(uv * 16).astype(np.int32)], int(m.pass_index), cv2.LINE_8, 4)
    for m in static.markers:
        ys, xs = np.nonzero(index == m.pass_index)
        if m.id in hide and len(xs):
            cut = np.quantile(xs, hide[m.id])
            index[ys[xs <= cut], xs[xs <= cut]] = 0
    image = np.full((cam.height, cam.width, 3), 90, np.uint8)
    for m in static.markers:
        colour = (250, 250, 250) if m.id in washed else ((200, 20, 30) if m.section == "A" else (20, 30, 200))
        image[index == m.pass_index] = colour
    return index, image


def write_dataset(root, config: dict = CONFIG):
    cfg = config_from_dict(config)
    static = static_scene(cfg)
    prepare(root, cfg, f"# the exports test config, as JSON: {json.dumps(config)}\n")
    for k, spec in enumerate(frame_plan(cfg)):
        frame = sample_frame(cfg, spec)
        if spec.frame_id == OUT_OF_IMAGE_FRAME:
            frame = shift_marker_out(frame, static)
        hide = {static.markers[k % len(static.markers)].id: 0.8} if k % 3 == 0 else {}
        washed = {static.markers[(k + 5) % len(static.markers)].id} if k == 4 else set()
        index, image = index_and_image(frame, static, hide, washed)
        label = frame_labels(frame, static, index, THRESHOLD, {}, image)
        _, png = cv2.imencode(".png", cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
        write_bytes_atomic(root / "images" / f"{spec.frame_id}.png", png.tobytes())
        write_json_atomic(root / "labels" / f"{spec.frame_id}.json", label)
    seal_hand_made(root, cfg)   # meta records and manifest: a complete dataset
    return root


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    root = write_dataset(tmp_path_factory.mktemp("exports") / "ds")
    for fmt in ("coco", "yolo", "bop"):
        dt.export(root, fmt)
    return root


@pytest.fixture
def moved(dataset, tmp_path):
    """The exports copied elsewhere, with the dataset itself renamed away: nothing may still
    point into the original folder."""
    dst = tmp_path / "elsewhere" / "exports"
    shutil.copytree(dataset / "exports", dst)
    labels = {lab["frame_id"]: lab for lab in Dataset.open(dataset).labels_of()}
    gone = dataset.with_name(dataset.name + "-gone")
    os.rename(dataset, gone)
    yield dst, labels
    os.rename(gone, dataset)


def test_synthetic_dataset_has_the_cases(dataset):
    labels = Dataset.open(dataset).labels_of()
    assert {lab["spec"]["split"] for lab in labels} == {"train", "val", "test", "repeat"}
    markers = [m for lab in labels for m in lab["markers"]]
    assert any(m["visible_pixels"] and not m["in_frame"] for m in markers)      # centre outside
    assert any(m["visible_pixels"] and m["visible_fraction"] < THRESHOLD for m in markers)
    assert any(m["visible_pixels"] and not m["legible"] for m in markers)


# ----------------------------------------------------------------------------- COCO

def coco_files(root):
    files = sorted((root / "coco" / "annotations").glob("person_keypoints_*.json"))
    return {p.stem.removeprefix("person_keypoints_"): p for p in files}


def test_coco_layout_and_ids(moved):
    from pycocotools.coco import COCO
    root, labels = moved
    files = coco_files(root)
    assert set(files) == {"train", "val", "test", "repeat"}
    image_ids, ann_ids = [], []
    for split, path in files.items():
        coco = COCO(str(path))
        info = coco.dataset["info"]
        assert info["kpt_oks_sigmas"] == list(KPT_OKS_SIGMAS)
        assert "top-left corner" in info["pixel_conventions"]["bbox"]
        assert "centre of the top-left pixel" in info["pixel_conventions"]["keypoints"]
        assert [c["name"] for c in coco.loadCats(coco.getCatIds())] == list(CLASS_NAMES)
        assert all(c["keypoints"] == ["centre"] for c in coco.dataset["categories"])
        for img in coco.loadImgs(coco.getImgIds()):
            assert labels[img["frame_id"]]["spec"]["split"] == split
            assert (root / "coco" / "images" / split / img["file_name"]).is_file()
        image_ids += coco.getImgIds()
        ann_ids += coco.getAnnIds()
    assert len(image_ids) == len(set(image_ids)) == len(labels)     # unique across the split files
    assert len(ann_ids) == len(set(ann_ids))


def detectron2_keypoints(ann):
    """detectron2's load_coco_json: COCO keypoints are pixel indices; it adds 0.5 to x and y."""
    kp = [v + 0.5 if i % 3 != 2 else v for i, v in enumerate(ann["keypoints"])]
    return np.array(kp, dtype=np.float64).reshape(-1, 3)


def test_coco_boxes_keypoints_and_polygons_match_the_labels(moved):
    from pycocotools.coco import COCO
    root, labels = moved
    n_outside = n_checked = 0
    for path in coco_files(root).values():
        coco = COCO(str(path))
        for img in coco.loadImgs(coco.getImgIds()):
            lab = labels[img["frame_id"]]
            by_id = {m["id"]: m for m in lab["markers"]}
            anns = coco.loadAnns(coco.getAnnIds(imgIds=img["id"]))
            assert len(anns) == sum(1 for m in lab["markers"] if m["visible_pixels"])
            for a in anns:
                m = by_id[a["marker_id"]]
                x, y, w, h = a["bbox"]
                assert np.allclose([x - 0.5, y - 0.5, x + w - 0.5, y + h - 0.5], m["bbox_px"], rtol=0, atol=1e-9)
                assert a["category_id"] == m["class_id"] + 1 and a["area"] == m["area_in_frame_px"] > 0
                assert a["iscrowd"] == (0 if m["visible_fraction"] >= THRESHOLD and m["legible"] else 1)
                kp = detectron2_keypoints(a)
                if m["in_frame"]:
                    assert a["num_keypoints"] == 1 and kp[0, 2] == m["visibility"] > 0
                    # read as detectron2 does, the keypoint is the continuous centre: label + 0.5
                    assert np.abs(kp[0, :2] - (np.array(m["center_px"]) + 0.5)).max() < 1e-6
                else:
                    assert a["keypoints"] == [0, 0, 0] and a["num_keypoints"] == 0
                    n_outside += 1
                check_polygon(a, m, img)
                n_checked += 1
    assert n_outside >= 1 and n_checked > 100


def check_polygon(a, m, img):
    (poly,) = a["segmentation"]
    xy = np.array(poly).reshape(-1, 2) - 0.5
    assert len(xy) >= 3
    w, h = img["width"], img["height"]
    assert xy.min() >= -0.5 - 1e-9 and xy[:, 0].max() <= w - 0.5 + 1e-9 and xy[:, 1].max() <= h - 0.5 + 1e-9
    tol = POLYGON_TOLERANCE_PX + 1e-3
    box = [xy[:, 0].min(), xy[:, 1].min(), xy[:, 0].max(), xy[:, 1].max()]
    assert np.allclose(box, m["bbox_px"], rtol=0, atol=tol)
    perimeter = 2 * (m["bbox_px"][2] - m["bbox_px"][0] + m["bbox_px"][3] - m["bbox_px"][1])
    assert polygon_area_centroid(xy)[0] == pytest.approx(m["area_in_frame_px"], abs=tol * perimeter)


def test_outline_is_the_labels_polygon(dataset):
    """The exporter's outline (before simplification) is exactly the one the label's box came from."""
    layout = read_layout(dataset)
    n = 0
    for lab in Dataset.open(dataset).labels_of():
        for m in lab["markers"]:
            poly = outline_px(lab, layout[m["id"]])
            if m["bbox_px"] is None:
                assert len(poly) == 0
                continue
            box = [poly[:, 0].min(), poly[:, 1].min(), poly[:, 0].max(), poly[:, 1].max()]
            assert box == m["bbox_px"]
            n += 1
    assert n > 100


def perfect_keypoint_results(coco):
    rows = []
    for a in coco.loadAnns(coco.getAnnIds()):
        if not a["iscrowd"] and a["num_keypoints"] > 0:
            rows.append({"image_id": a["image_id"], "category_id": a["category_id"],
                         "keypoints": list(a["keypoints"]), "score": 1.0})
    return rows


def test_keypoint_cocoeval_with_perfect_detections_gives_one(moved):
    import contextlib
    import io

    from pycocotools.coco import COCO
    from pycocotools.cocoeval import COCOeval
    root, _ = moved
    for split, path in coco_files(root).items():
        with contextlib.redirect_stdout(io.StringIO()):
            gt = COCO(str(path))
            rows = perfect_keypoint_results(gt)
            assert rows, split
            ev = COCOeval(gt, gt.loadRes(rows), iouType="keypoints")
            ev.params.kpt_oks_sigmas = np.array(gt.dataset["info"]["kpt_oks_sigmas"])
            ev.evaluate()
            ev.accumulate()
            ev.summarize()
        assert ev.stats[0] == pytest.approx(1.0), split      # AP, OKS 0.50:0.95
        # the OKS sigma has a scale: a 0.1-radius error keeps OKS near 0.5
        a = next(a for a in gt.loadAnns(gt.getAnnIds()) if not a["iscrowd"] and a["num_keypoints"])
        radius = np.sqrt(a["area"] / np.pi)
        d = 0.1 * radius
        oks = np.exp(-d ** 2 / (2 * a["area"] * (2 * KPT_OKS_SIGMAS[0]) ** 2))
        assert 0.3 < oks < 0.7


def test_coco_masks_rasterise_near_the_marker_area(moved):
    from pycocotools.coco import COCO
    root, _ = moved
    coco = COCO(str(coco_files(root)["test"]))
    for a in coco.loadAnns(coco.getAnnIds()):
        mask = coco.annToMask(a)
        assert mask.shape == (coco.imgs[a["image_id"]]["height"], coco.imgs[a["image_id"]]["width"])
        assert mask.sum() == pytest.approx(a["area"], rel=0.25, abs=6)


# ----------------------------------------------------------------------------- YOLO

IMG_SUFFIXES = {".bmp", ".jpeg", ".jpg", ".png", ".tif", ".tiff", ".webp"}


def ultralytics_dataset(yaml_path):
    """The rules of ultralytics' check_det_dataset and YOLODataset, re-implemented:
    'train' and 'val' keys are required; names and nc must agree; without 'path' the root is
    the yaml's folder; split entries are directories (searched recursively) or list files; an
    image's label is found by replacing the last '/images/' with '/labels/' and the suffix with
    '.txt'; 'val' must exist."""
    data = yaml.safe_load(yaml_path.read_text())
    for k in ("train", "val"):
        assert k in data, f"'{k}:' key missing"
    names = data["names"]
    names = [names[i] for i in sorted(names)] if isinstance(names, dict) else list(names)
    assert "nc" not in data or data["nc"] == len(names)
    assert "path" not in data        # a copied export must not read the original
    root = yaml_path.parent.resolve()
    splits = {}
    for k in ("train", "val", "test"):
        if not data.get(k):
            continue
        p = (root / data[k]).resolve()
        if k == "val":
            assert p.exists()
        if p.is_dir():
            files = sorted(str(f) for f in p.rglob("*") if f.suffix.lower() in IMG_SUFFIXES)
        elif p.is_file():
            lines = p.read_text().strip().splitlines()
            files = [str(p.parent / x[2:]) if x.startswith("./") else x for x in lines]
        else:
            files = []
        sa, sb = f"{os.sep}images{os.sep}", f"{os.sep}labels{os.sep}"
        splits[k] = [(f, sb.join(f.rsplit(sa, 1)).rsplit(".", 1)[0] + ".txt") for f in files]
    return names, splits


def test_yolo_reads_back_like_ultralytics(moved):
    root, labels = moved
    names, splits = ultralytics_dataset(root / "yolo" / "data.yaml")
    assert names == list(CLASS_NAMES)
    n = 0
    for key, pairs in splits.items():
        frames = sorted(os.path.basename(img)[:-4] for img, _ in pairs)
        assert frames == sorted(f for f, lab in labels.items() if lab["spec"]["split"] == key), key
        for img, txt in pairs:
            assert img.startswith(str(root.resolve())) and os.path.isfile(txt)
            lab = labels[os.path.basename(img)[:-4]]
            w, h = lab["image"]["width"], lab["image"]["height"]
            assert cv2.imread(img).shape[:2] == (h, w)
            expected = [m for m in lab["markers"] if m["bbox_px"] and m["visible_fraction"] >= THRESHOLD and m["legible"]]
            lines = Path(txt).read_text().splitlines()
            assert len(lines) == len(expected)
            for line, m in zip(lines, expected):
                values = [float(v) for v in line.split()]
                assert len(values) == 5 and 0 <= values[0] < len(names)
                assert all(0.0 <= v <= 1.0 for v in values[1:])
                c, box = parse_yolo_line(line, w, h)
                assert c == m["class_id"] and np.allclose(box, m["bbox_px"], rtol=0, atol=1e-5)
                n += 1
    assert set(splits) == {"train", "val", "test"} and n > 50
    val = {os.path.basename(i) for i, _ in splits["val"]}
    assert val and val.isdisjoint(os.path.basename(i) for i, _ in splits["test"])


def yaml_keys(counts):
    return {k: v for k, v in yaml.safe_load(data_yaml("v", counts)).items() if k in ("train", "val", "test")}


def test_yolo_val_is_never_test_while_there_is_training_data():
    assert yaml_keys({"train": 8, "val": 2, "test": 3}) == {"train": "images/train", "val": "images/val",
                                                             "test": "images/test"}
    assert yaml_keys({"train": 8, "test": 3})["val"] == "images/train"
    assert yaml_keys({"test": 3})["val"] == "images/test"          # evaluation-only dataset


def test_empty_splits_leave_existing_empty_folders(tmp_path):
    from dockfactory.generator.exports.yolo import export_yolo
    root = write_dataset(tmp_path / "ds", {**CONFIG, "dataset": {**CONFIG["dataset"], "frames": 0}})
    out = export_yolo(root, tmp_path / "yolo")   # the repeatability frames only: no YOLO split
    _, splits = ultralytics_dataset(out / "data.yaml")
    assert splits == {"train": [], "val": [], "test": []} and not list(out.glob("*.txt"))


# ----------------------------------------------------------------------------- BOP

def test_bop_has_one_scene_per_split(moved):
    root, labels = moved
    bop = root / "bop"
    for split in ("train", "val", "test", "repeat"):
        ids = json.loads((bop / split / "000000" / "frame_ids.json").read_text())
        assert sorted(ids.values()) == sorted(f for f, lab in labels.items() if lab["spec"]["split"] == split)
        assert all((bop / split / "000000" / "rgb" / f"{int(im):06d}.png").is_file() for im in ids)


def test_polygon_simplification_stays_within_tolerance():
    from dockfactory.generator.exports.coco import simplify_closed
    a = np.linspace(0, 2 * np.pi, 256, endpoint=False)
    circle = np.stack([100 + 30 * np.cos(a), 80 + 12 * np.sin(a)], 1)
    simple = simplify_closed(circle, POLYGON_TOLERANCE_PX)
    assert 8 < len(simple) < len(circle)
    # every original vertex lies within the tolerance of the simplified outline
    p, q = simple, np.roll(simple, -1, axis=0)
    d = q - p
    t = np.clip(np.einsum("mk,nmk->nm", d, circle[:, None] - p) / np.einsum("mk,mk->m", d, d), 0, 1)
    dist = np.linalg.norm(circle[:, None] - (p + t[..., None] * d), axis=2).min(1)
    assert dist.max() <= POLYGON_TOLERANCE_PX
    sliver = np.array([[0.0, 0.0], [3.0, 0.001], [6.0, 0.001], [10.0, 0.0], [6.0, -0.001], [3.0, -0.001]])
    assert len(simplify_closed(sliver, POLYGON_TOLERANCE_PX)) == 2   # segmentation() keeps the full polygon then
