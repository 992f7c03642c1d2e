"""COCO results of detections, evaluated by pycocotools' COCOeval against the COCO export.

Detections are made from the labels of test_exports' painted dataset (every split, crowd and
washed-out markers, a marker centre outside the image): perfect ones must score AP 1.0, and
detections moved by a known amount must score exactly what COCO's thresholds give them.
"""
import contextlib
import io
import json

import numpy as np
import pytest
from test_exports import THRESHOLD, write_dataset

from dockfactory.core.errors import DockfactoryError
from dockfactory.core.names import SPLITS
from dockfactory.generator.datasets import tools as dt
from dockfactory.generator.datasets.reader import Dataset
from dockfactory.generator.exports.coco import KPT_OKS_SIGMAS
from dockfactory.generator.exports.coco_results import coco_results

SHIFT = 0.1        # boxes moved by a tenth of their width: IoU (1 - 0.1) / (1 + 0.1) = 0.818
TARGET_OKS = 0.725  # keypoints moved so that OKS is 0.725: matched at thresholds 0.50 .. 0.70


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    root = write_dataset(tmp_path_factory.mktemp("results") / "ds")
    dt.export(root, "coco")
    ds = Dataset.open(root)
    return root / "exports" / "coco", ds


def annotated(m) -> bool:
    """The marker is a non-crowd annotation of the COCO export."""
    return bool(m["visible_pixels"]) and m["bbox_px"] is not None and m["visible_fraction"] >= THRESHOLD and m["legible"]


def detections(ds, keep=annotated, move=lambda m, box, centre: (box, centre)):
    """A detections document from the labels: one detection per marker ``keep`` accepts, its box
    and centre passed through ``move``."""
    frames = {}
    for lab in ds.labels_of():
        frames[lab["frame_id"]] = []
        for m in lab["markers"]:
            if keep(m):
                box, centre = move(m, list(m["bbox_px"]), list(m["center_px"]))
                frames[lab["frame_id"]].append({"class_id": m["class_id"], "score": 0.9, "bbox_px": box,
                                                "center_px": centre})
    return {"frames": frames}


def evaluate(coco_dir, rows, iou_type: str) -> dict:
    """AP (IoU or OKS 0.50:0.95) per split file of ``rows`` against the export, as a user runs it."""
    from pycocotools.coco import COCO
    from pycocotools.cocoeval import COCOeval
    aps = {}
    for split in SPLITS:
        with contextlib.redirect_stdout(io.StringIO()):
            gt = COCO(str(coco_dir / "annotations" / f"person_keypoints_{split}.json"))
            mine = [r for r in rows if r["image_id"] in set(gt.getImgIds())]
            ev = COCOeval(gt, gt.loadRes(mine), iouType=iou_type)
            ev.params.kpt_oks_sigmas = np.array(gt.dataset["info"]["kpt_oks_sigmas"])
            ev.evaluate()
            ev.accumulate()
            ev.summarize()
        aps[split] = float(ev.stats[0])
    return aps


def test_rows_have_the_exports_ids_and_conventions(exported):
    coco_dir, ds = exported
    rows = coco_results(ds.splits, detections(ds))
    by_frame = {}
    for split in SPLITS:
        coco = json.loads((coco_dir / "annotations" / f"person_keypoints_{split}.json").read_text())
        by_frame.update({img["frame_id"]: img["id"] for img in coco["images"]})
        for a in coco["annotations"]:
            if a["iscrowd"] == 0 and a["num_keypoints"]:
                mine = [r for r in rows if r["image_id"] == a["image_id"] and r["category_id"] == a["category_id"]]
                row = min(mine, key=lambda r: np.abs(np.subtract(r["bbox"], a["bbox"])).max())
                # the same box (continuous) and keypoint (pixel indices) as the export, to the 1e-4 px written
                assert np.abs(np.subtract(row["bbox"], a["bbox"])).max() <= 0.5e-4 + 1e-9
                assert np.abs(np.subtract(row["keypoints"][:2], a["keypoints"][:2])).max() <= 0.5e-4 + 1e-9
                assert row["keypoints"][2] == a["keypoints"][2] == 2
    labels = {lab["frame_id"]: lab for lab in ds.labels_of()}
    for r in rows:
        assert set(r) == {"image_id", "category_id", "bbox", "score", "keypoints"}
    frame_of = {i: f for f, i in by_frame.items()}
    assert {frame_of[r["image_id"]] for r in rows} == {f for f, lab in labels.items()
                                                       if any(annotated(m) for m in lab["markers"])}


def test_perfect_detections_score_one(exported):
    coco_dir, ds = exported
    rows = coco_results(ds.splits, detections(ds))
    assert evaluate(coco_dir, rows, "bbox") == pytest.approx(dict.fromkeys(SPLITS, 1.0), abs=1e-12)
    # a marker whose centre is outside the image has no keypoint (COCO ignores it for OKS); a
    # detection of it is a false positive there, so the keypoint run leaves those out
    in_frame = coco_results(ds.splits, detections(ds, keep=lambda m: annotated(m) and m["in_frame"]))
    assert evaluate(coco_dir, in_frame, "keypoints") == pytest.approx(dict.fromkeys(SPLITS, 1.0), abs=1e-12)


def test_moved_boxes_and_keypoints_score_what_coco_thresholds_give(exported):
    coco_dir, ds = exported

    def shift_box(m, box, centre):
        dx = SHIFT * (box[2] - box[0])
        return [box[0] + dx, box[1], box[2] + dx, box[3]], centre

    rows = coco_results(ds.splits, detections(ds, move=shift_box))
    # IoU 0.818 passes 7 of the 10 thresholds 0.50, 0.55, ..., 0.95
    assert evaluate(coco_dir, rows, "bbox") == pytest.approx(dict.fromkeys(SPLITS, 0.7), abs=1e-9)

    def shift_keypoint(m, box, centre):
        # OKS = exp(-d^2 / (2 area (2 sigma)^2)), area the annotation's (the marker's in-frame area)
        d = np.sqrt(-np.log(TARGET_OKS) * 2 * m["area_in_frame_px"] * (2 * KPT_OKS_SIGMAS[0]) ** 2)
        return box, [centre[0] + d, centre[1]]

    keep = lambda m: annotated(m) and m["in_frame"]   # noqa: E731
    rows = coco_results(ds.splits, detections(ds, keep=keep, move=shift_keypoint))
    assert evaluate(coco_dir, rows, "keypoints") == pytest.approx(dict.fromkeys(SPLITS, 0.5), abs=1e-9)


def test_a_frame_not_in_the_dataset_is_refused(exported):
    _, ds = exported
    with pytest.raises(DockfactoryError, match="'999999' is not a frame of the dataset"):
        coco_results(ds.splits, {"frames": {"999999": []}})
    with pytest.raises(DockfactoryError, match="no 'frames' object"):
        coco_results(ds.splits, [])
