"""Letterbox mapping, NMS against a brute-force reference, post-processing."""
import os

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from dockfactory.detector.infer import batched_nms, box_iou, letterbox, nms, postprocess


@settings(max_examples=60, deadline=None)
@given(w=st.integers(8, 1500), h=st.integers(8, 1500), scale=st.sampled_from([0.25, 0.4, 0.5, 0.75, 1.0, 1.3]),
       seed=st.integers(0, 2**31))
def test_letterbox_round_trip_exact(w, h, scale, seed):
    img = np.zeros((h, w, 3), np.uint8)
    net, lb = letterbox(img, scale)
    assert net.shape[0] % 32 == 0 and net.shape[1] % 32 == 0
    assert (lb.net_height, lb.net_width) == net.shape[:2]
    pts = np.random.default_rng(seed).uniform([-0.5, -0.5], [w - 0.5, h - 0.5], (20, 2))
    back = lb.to_image(lb.to_network(pts))
    assert np.abs(back - pts).max() < 1e-9
    boxes = np.concatenate((pts[:10], pts[10:]), 1)
    assert np.abs(lb.boxes_to_image(lb.boxes_to_network(boxes)) - boxes).max() < 1e-9
    # the image outline maps to the resized (unpadded) area
    corners = lb.to_network([[-0.5, -0.5], [w - 0.5, h - 0.5]])
    assert np.allclose(corners[0], [lb.pad_x, lb.pad_y])
    assert np.allclose(corners[1], [lb.pad_x + round(w * scale), lb.pad_y + round(h * scale)])


def test_letterbox_pixel_content_follows_mapping():
    img = np.zeros((50, 70, 3), np.uint8)
    img[13, 41] = 255                      # OpenCV pixel (x=41, y=13)
    net, lb = letterbox(img, 1.0)
    x, y = lb.to_network([[41.0, 13.0]])[0]   # corner coordinates of that pixel's centre
    assert net[int(np.floor(y)), int(np.floor(x))].tolist() == [255, 255, 255]
    assert (x % 1, y % 1) == (0.5, 0.5)
    img = np.zeros((64, 64, 3), np.uint8)
    img[20:22, 30:32] = 200               # a 2x2 block becomes one pixel at scale 0.5
    net, lb = letterbox(img, 0.5)
    x, y = lb.to_network([[30.5, 20.5]])[0]
    assert net[int(y), int(x)].tolist() == [200, 200, 200] and (x % 1, y % 1) == (0.5, 0.5)


def test_letterbox_bad_input():
    with pytest.raises(ValueError, match="image"):
        letterbox(np.zeros((10, 10), np.uint8), 1.0)
    with pytest.raises(ValueError, match="scale"):
        letterbox(np.zeros((10, 10, 3), np.uint8), 0.0)


def brute_nms(boxes, scores, thr):
    order = sorted(range(len(scores)), key=lambda k: (-float(scores[k]), k))
    keep = []
    for k in order:
        if all(float(box_iou(boxes[k:k + 1], boxes[q:q + 1])[0, 0]) <= thr for q in keep):
            keep.append(k)
    return keep


@pytest.mark.slow   # 80 examples against an O(n^2) reference: about 10 s
@settings(max_examples=80, deadline=None)
@given(n=st.integers(0, 60), seed=st.integers(0, 2**31), thr=st.sampled_from([0.3, 0.45, 0.6, 0.9]),
       ties=st.booleans())
def test_nms_matches_brute_force(n, seed, thr, ties):
    g = np.random.default_rng(seed)
    xy = g.uniform(0, 80, (n, 2))
    wh = g.uniform(1, 25, (n, 2))
    boxes = torch.from_numpy(np.concatenate((xy, xy + wh), 1))
    scores = torch.from_numpy(g.uniform(0, 1, n).round(1) if ties else g.uniform(0, 1, n))
    assert nms(boxes, scores, thr).tolist() == brute_nms(boxes, scores, thr)


def test_batched_nms_keeps_other_classes():
    boxes = torch.tensor([[0, 0, 10, 10], [0, 0, 10, 10], [1, 0, 11, 10]], dtype=torch.float64)
    scores = torch.tensor([0.9, 0.8, 0.7], dtype=torch.float64)
    assert batched_nms(boxes, scores, torch.tensor([0, 1, 0]), 0.5).tolist() == [0, 1]
    assert nms(boxes, scores, 0.5).tolist() == [0]


def test_nms_bad_input():
    with pytest.raises(ValueError, match="boxes"):
        nms(torch.zeros(3, 3), torch.zeros(3), 0.5)


def test_postprocess_decodes_boxes_and_scores():
    pred = torch.zeros(1, 4, 7)
    pred[0, 0] = torch.tensor([50, 40, 20, 10, 0.9, 0.1, 0.8])   # class 1, score 0.72
    pred[0, 1] = torch.tensor([51, 40, 20, 10, 0.8, 0.1, 0.7])   # suppressed by row 0
    pred[0, 2] = torch.tensor([10, 10, 4, 4, 0.9, 0.9, 0.1])     # class 0, score 0.81
    pred[0, 3] = torch.tensor([90, 90, 4, 4, 0.1, 0.9, 0.1])     # below threshold
    out = postprocess(pred, conf_threshold=0.25, iou_threshold=0.45)[0]
    assert out.shape == (2, 6)
    assert torch.allclose(out[0], torch.tensor([8, 8, 12, 12, 0.81, 0]))
    assert torch.allclose(out[1], torch.tensor([40, 35, 60, 45, 0.72, 1]))


def test_drop_nested_keeps_one_detection_per_marker():
    from dockfactory.detector.infer import drop_nested

    def det(c, score, box, centre):
        return {"class_id": c, "score": score, "bbox_px": box, "center_px": centre}
    dets = [det(0, 0.9, [10, 10, 30, 20], [20, 15]),
            det(0, 0.5, [6, 8, 26, 18], [16, 13]),       # same class, centre inside the first box
            det(1, 0.4, [12, 11, 28, 19], [20, 15]),     # other class: kept (the solver decides)
            det(0, 0.3, [40, 10, 60, 20], [50, 15])]     # another marker
    kept = drop_nested(dets)
    assert [d["score"] for d in kept] == [0.9, 0.4, 0.3]
    assert drop_nested([]) == []
