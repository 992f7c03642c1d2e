"""mAP (pycocotools) on hand-built cases, matching, centre error and recall."""
import numpy as np
import pytest

from dockfactory.eval.detection_metrics import (
    centre_and_recall,
    coco_map,
    coco_results,
    format_report,
    match_frame,
    network_boxes,
)
from dockfactory.eval.yolov5_ap import correct_matrix, yolov5_map
from dockfactory.generator.exports.coco import coco_from_labels

SIZE = 20.0


def marker(cls, x, y, vf=1.0, mid="m"):
    r = SIZE / 2
    return {"id": mid, "class_id": cls, "center_px": [x, y], "bbox_px": [x - r, y - r, x + r, y + r],
            "visible_pixels": 300, "visible_fraction": vf, "visibility": 2 if vf >= 0.5 else 1,
            "area_in_frame_px": np.pi * r * r}


def labels():
    return [{"frame_id": f"{i:06d}", "image": {"width": 200, "height": 100},
             "spec": {"split": "test", "condition": "normal" if i == 0 else "glare"},
             "markers": [marker(0, 40.0 + i, 30.0), marker(1, 120.0, 60.0 + i)]} for i in range(2)]


def dets_from(labs, shift=0.0, drop=(), score=0.9):
    out = {}
    for lab in labs:
        ds = []
        for k, m in enumerate(lab["markers"]):
            if (lab["frame_id"], k) in drop:
                continue
            x0, y0, x1, y1 = m["bbox_px"]
            ds.append({"class_id": m["class_id"], "score": score, "bbox_px": [x0 + shift, y0, x1 + shift, y1],
                       "center_px": [m["center_px"][0] + shift, m["center_px"][1]]})
        out[lab["frame_id"]] = ds
    return out


def shift_for_iou(iou):
    """Horizontal shift of a SIZE x SIZE box that gives this IoU with the original."""
    return SIZE * (1 - iou) / (1 + iou)


def run_map(labs, dets):
    gt = coco_from_labels(labs, 0.5)
    return coco_map(gt, coco_results(dets, gt))


def test_perfect_detections_give_one():
    m = run_map(labels(), dets_from(labels()))
    assert m["mAP50"] == pytest.approx(1.0) and m["mAP50_95"] == pytest.approx(1.0)
    assert all(v["mAP50"] == pytest.approx(1.0) and v["mAP50_95"] == pytest.approx(1.0)
               for v in m["per_class"].values())


@pytest.mark.parametrize("iou, expected", [(0.72, 0.5), (0.83, 0.7), (0.56, 0.2), (0.97, 1.0)])
def test_known_shift_gives_known_map(iou, expected):
    # every detection has this IoU with its marker: it counts at the thresholds 0.50 ... <= iou
    m = run_map(labels(), dets_from(labels(), shift=shift_for_iou(iou)))
    assert m["mAP50"] == pytest.approx(1.0)
    assert m["mAP50_95"] == pytest.approx(expected)


def test_shift_below_half_gives_zero():
    m = run_map(labels(), dets_from(labels(), shift=shift_for_iou(0.45)))
    assert m["mAP50"] == pytest.approx(0.0) and m["mAP50_95"] == pytest.approx(0.0)


def test_missing_detection_gives_known_map():
    # class 1 finds 1 of its 2 markers: precision 1 up to recall 0.5 -> 51 of 101 recall points
    m = run_map(labels(), dets_from(labels(), drop={("000001", 1)}))
    assert m["per_class"]["RedA"]["mAP50"] == pytest.approx(1.0)
    assert m["per_class"]["BlueB"]["mAP50"] == pytest.approx(51 / 101)
    assert m["mAP50"] == pytest.approx((1 + 51 / 101) / 2)


def test_coco_shift_is_half_pixel():
    gt = coco_from_labels(labels(), 0.5)
    rows = coco_results(dets_from(labels()), gt)
    ann = [a for a in gt["annotations"] if a["image_id"] == 1 and a["category_id"] == 1][0]
    row = [r for r in rows if r["image_id"] == 1 and r["category_id"] == 1][0]
    assert row["bbox"] == pytest.approx(ann["bbox"])
    assert row["bbox"][0] == pytest.approx(labels()[0]["markers"][0]["bbox_px"][0] + 0.5)


def test_crowd_markers_are_ignored():
    labs = labels()
    labs[0]["markers"].append(marker(0, 170.0, 30.0, vf=0.3))
    dets = dets_from(labs)              # also detects the hidden marker: neither helps nor hurts
    assert run_map(labs, dets)["mAP50_95"] == pytest.approx(1.0)
    dets[labs[0]["frame_id"]].pop()     # not detecting it is fine too
    assert run_map(labs, dets)["mAP50_95"] == pytest.approx(1.0)


def test_centre_error_and_recall():
    labs = labels()
    r = centre_and_recall(labs, dets_from(labs, shift=0.25), 0.5)
    assert r["centre_error"]["normal"]["median_px"] == pytest.approx(0.25)
    assert r["centre_error"]["challenging"]["n"] == 2
    by_cond = r["centre_error_by_condition"]      # the same errors, split by each frame's condition
    conds = [lab["spec"]["condition"] for lab in labs]
    assert set(by_cond) == set(conds) and sum(v["n"] for v in by_cond.values()) == 4
    assert all(v["median_px"] == pytest.approx(0.25) for v in by_cond.values())
    assert r["recall_visible50"] == pytest.approx(1.0)
    r = centre_and_recall(labs, dets_from(labs, drop={("000000", 0)}), 0.5)
    assert r["recall_visible50"] == pytest.approx(0.75)
    r = centre_and_recall(labs, dets_from(labs, score=0.1), 0.5, recall_conf=0.25)
    assert r["recall_visible50"] == pytest.approx(0.0)


def test_match_frame_greedy_by_score_and_class():
    gt = np.array([[0, 0, 10, 10], [20, 0, 30, 10]], float)
    det = np.array([[1, 0, 11, 10], [0, 0, 10, 10], [20, 0, 30, 10]], float)
    m = match_frame(gt, [0, 0], det, [0.5, 0.9, 0.8], [0, 0, 1])
    assert m.tolist() == [1, -1]       # the higher score wins; the class-1 box matches nothing
    with pytest.raises(ValueError, match="lengths"):
        match_frame(gt, [0], det, [0.5], [0, 0, 1])


def test_illegible_markers_are_ignored():
    labs = labels()
    labs[1]["markers"][0]["legible"] = False                         # washed out by glare
    dets = dets_from(labs, drop={("000001", 0)})                      # and not found
    assert run_map(labs, dets)["mAP50_95"] == pytest.approx(1.0)
    r = centre_and_recall(labs, dets, 0.5)
    assert r["recall_visible50"] == pytest.approx(1.0) and r["recall_markers"] == 3


# YOLOv5's mAP (eval/yolov5_ap.py): the same cases, against YOLOv5's interpolation
def run_v5(labs, dets):
    gt = coco_from_labels(labs, 0.5)
    return yolov5_map(gt, coco_results(dets, gt))


def many_labels(n=50):
    """n frames with one marker of each class: 50 ground-truth boxes per class."""
    return [{"frame_id": f"{i:06d}", "image": {"width": 200, "height": 100},
             "spec": {"split": "test", "condition": "normal"},
             "markers": [marker(0, 40.0, 30.0), marker(1, 120.0, 60.0)]} for i in range(n)]


def test_yolov5_perfect_detections_give_its_ceiling():
    m = run_v5(labels(), dets_from(labels()))
    # the last trapezoid (recall 0.99 to 1.00) falls to the closing point (1, 0): 1 - 0.01 / 2
    assert m["mAP50"] == pytest.approx(0.995) and m["mAP50_95"] == pytest.approx(0.995)


def test_one_missed_box_caps_coco_but_not_yolov5():
    labs = many_labels(100)
    dets = dets_from(labs, drop={("000007", 1)})          # BlueB finds 99 of 100
    coco, v5 = run_map(labs, dets), run_v5(labs, dets)
    assert coco["per_class"]["BlueB"]["mAP50"] == pytest.approx(100 / 101)
    assert v5["per_class"]["BlueB"]["mAP50"] == pytest.approx(0.995)
    assert v5["per_class"]["RedA"]["mAP50"] == pytest.approx(0.995)


def test_yolov5_half_recall_and_known_shift():
    # BlueB finds 1 of 2: precision 1 up to recall 0.5, then the straight line to (1, 0): 0.75
    m = run_v5(labels(), dets_from(labels(), drop={("000001", 1)}))
    assert m["per_class"]["BlueB"]["mAP50"] == pytest.approx(0.75)
    # every box at IoU 0.72 counts at the thresholds 0.50 ... 0.70: 5 of 10
    m = run_v5(labels(), dets_from(labels(), shift=shift_for_iou(0.72)))
    assert m["mAP50"] == pytest.approx(0.995) and m["mAP50_95"] == pytest.approx(0.995 * 0.5)


def test_yolov5_counts_a_detection_on_an_ignored_marker():
    labs = labels()
    labs[0]["markers"].append(marker(0, 170.0, 30.0, vf=0.3))      # crowd in COCO, absent in YOLO
    low = dets_from(labs)
    low[labs[0]["frame_id"]][-1]["score"] = 0.5                     # below every true positive
    assert run_v5(labs, low)["per_class"]["RedA"]["mAP50"] == pytest.approx(0.995)
    high = dets_from(labs)
    high[labs[0]["frame_id"]][-1]["score"] = 0.99                   # above them: precision drops
    assert run_v5(labs, high)["per_class"]["RedA"]["mAP50"] < 0.9
    assert run_map(labs, high)["mAP50"] == pytest.approx(1.0)       # COCO ignores it


def test_yolov5_matching_takes_highest_iou_first():
    gt = np.array([[0, 0, 10, 10]], float)
    det = np.array([[2, 0, 12, 10], [0, 0, 10, 10]], float)        # IoU 0.67 and 1.0
    c = correct_matrix(gt, [1], det, [1, 1])
    assert c[:, 0].tolist() == [False, True]                        # the better box, whatever its score
    assert not correct_matrix(gt, [0], det, [1, 1]).any()           # other class: nothing


def test_a_split_without_challenging_frames_gives_no_figure_not_nan():
    import json
    labs = many_labels(3)                                          # normal frames only (like the repeat split)
    r = centre_and_recall(labs, dets_from(labs), 0.5)
    assert r["centre_error"]["challenging"] == {"n": 0, "median_px": None, "mean_px": None, "p90_px": None}
    json.dumps(r, allow_nan=False)                                 # the results files refuse NaN
    assert centre_and_recall([], {}, 0.5)["recall_visible50"] is None
    report = format_report({**run_map(labs, dets_from(labs)), **r, "frames": 3, "split": "repeat",
                            "dataset_version": "v"})
    assert "centre error challenging: no matched markers" in report and "nan" not in report


def with_network_boxes(dets, shift):
    """Detections whose network box is the refined box moved right by ``shift`` px."""
    return {f: [{**d, "bbox_detector_px": [d["bbox_px"][0] + shift, d["bbox_px"][1], d["bbox_px"][2] + shift,
                                            d["bbox_px"][3]]} for d in ds] for f, ds in dets.items()}


def test_network_boxes_replace_the_refined_ones_only_when_every_detection_has_them():
    dets = with_network_boxes(dets_from(labels()), 1.0)
    net = network_boxes(dets)
    d0, n0 = dets["000000"][0], net["000000"][0]
    assert n0["bbox_px"] == d0["bbox_detector_px"] and n0["center_px"] == d0["center_px"]
    assert dets["000000"][0]["bbox_px"] != n0["bbox_px"]           # the input is not changed
    dets["000001"][1].pop("bbox_detector_px")
    assert network_boxes(dets) is None


def test_evaluate_detections_scores_the_network_boxes_beside_the_refined_ones():
    from types import SimpleNamespace

    from dockfactory.eval.detection_metrics import evaluate_detections
    labs = labels()
    ds = SimpleNamespace(config=SimpleNamespace(labels=SimpleNamespace(visible_threshold=0.5)),
                         labels_of=lambda split: labs, version_id="v")
    doc = {"frames": with_network_boxes(dets_from(labs), shift_for_iou(0.83)), "split": "test"}
    m = evaluate_detections(ds, doc)
    assert m["mAP50_95"] == pytest.approx(1.0)                        # refined boxes: exact
    assert m["network_boxes"]["mAP50"] == pytest.approx(1.0)
    assert m["network_boxes"]["mAP50_95"] == pytest.approx(0.7)      # IoU 0.83: thresholds 0.50-0.80
    assert 0 < m["network_boxes"]["yolov5"]["mAP50_95"] < m["yolov5"]["mAP50_95"]
    assert "the network's boxes, before refinement: mAP50 1.0000, mAP50:95 0.7000" in format_report(m)
    assert "network_boxes" not in evaluate_detections(ds, {"frames": dets_from(labs), "split": "test"})
