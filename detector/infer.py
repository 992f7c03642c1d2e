"""Full-image inference: letterbox, network, NMS (plain torch), mapping back, centre refinement.

Coordinates:
- image px, OpenCV convention: pixel centres at integers, the image spans [-0.5, W - 0.5];
- network px, corner convention of the letterboxed input: ``net = (cv + 0.5) * scale + pad``.
``LetterboxMap.to_image`` is the exact inverse of ``to_network`` (float64).
"""
from __future__ import annotations

import hashlib
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from dockfactory.core.io import write_json_atomic
from dockfactory.core.progress import Progress
from dockfactory.core.names import CLASS_NAMES, MIN_SCORE, NMS_IOU
from dockfactory.detector.centre_camera import refine_centre_camera
from dockfactory.detector.data import resize_exact
from dockfactory.detector.noise_card import card_figures


@dataclass(frozen=True)
class LetterboxMap:
    """Image (W x H, OpenCV px) <-> network input (net_w x net_h, corner px)."""
    width: int
    height: int
    scale_x: float   # network px per image px (exact resized size / original size)
    scale_y: float
    pad_x: int       # left padding, network px
    pad_y: int       # top padding
    net_width: int
    net_height: int

    def to_network(self, pts) -> np.ndarray:
        """``pts: (N, 2)`` image px (OpenCV) -> ``(N, 2)`` network px (corner convention)."""
        p = np.asarray(pts, dtype=np.float64).reshape(-1, 2)
        return (p + 0.5) * (self.scale_x, self.scale_y) + (self.pad_x, self.pad_y)

    def to_image(self, pts) -> np.ndarray:
        """``pts: (N, 2)`` network px -> ``(N, 2)`` image px (OpenCV)."""
        p = np.asarray(pts, dtype=np.float64).reshape(-1, 2)
        return (p - (self.pad_x, self.pad_y)) / (self.scale_x, self.scale_y) - 0.5

    def boxes_to_image(self, boxes) -> np.ndarray:
        """``boxes: (N, 4)`` [x0, y0, x1, y1] network px -> image px (OpenCV)."""
        b = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
        return np.concatenate((self.to_image(b[:, :2]), self.to_image(b[:, 2:])), 1)

    def boxes_to_network(self, boxes) -> np.ndarray:
        b = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
        return np.concatenate((self.to_network(b[:, :2]), self.to_network(b[:, 2:])), 1)


def letterbox(image: np.ndarray, scale: float, stride: int = 32, pad_value: int = 114):
    """Resize ``image: (H, W, 3) uint8`` by ``scale`` and pad (centred) to multiples of ``stride``.

    Returns ``(net_image (H', W', 3) uint8, LetterboxMap)``.
    """
    if image.ndim != 3 or image.shape[2] != 3:
        raise ValueError(f"image must be (H, W, 3), got {image.shape}")
    if not 0 < scale <= 4:
        raise ValueError(f"scale must be in (0, 4], got {scale}")
    h, w = image.shape[:2]
    resized, sx, sy = resize_exact(image, scale)
    rh, rw = resized.shape[:2]
    nh, nw = -(-rh // stride) * stride, -(-rw // stride) * stride
    top, left = (nh - rh) // 2, (nw - rw) // 2
    if (nh, nw) != (rh, rw):
        out = np.full((nh, nw, 3), pad_value, dtype=image.dtype)
        out[top:top + rh, left:left + rw] = resized
    else:
        out = np.ascontiguousarray(resized)
    return out, LetterboxMap(w, h, sx, sy, left, top, nw, nh)


def box_iou(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """IoU matrix of ``a: (N, 4)`` and ``b: (M, 4)`` [x0, y0, x1, y1] -> ``(N, M)``."""
    area_a = (a[:, 2] - a[:, 0]).clamp(min=0) * (a[:, 3] - a[:, 1]).clamp(min=0)
    area_b = (b[:, 2] - b[:, 0]).clamp(min=0) * (b[:, 3] - b[:, 1]).clamp(min=0)
    iw = (torch.min(a[:, None, 2], b[None, :, 2]) - torch.max(a[:, None, 0], b[None, :, 0])).clamp_(min=0)
    ih = (torch.min(a[:, None, 3], b[None, :, 3]) - torch.max(a[:, None, 1], b[None, :, 1])).clamp_(min=0)
    inter = iw.mul_(ih)
    return inter / (area_a[:, None] + area_b[None] - inter).clamp(min=1e-12)


def _overlapping_pairs(b: np.ndarray, iou_threshold: float) -> tuple[np.ndarray, np.ndarray]:
    """Index pairs (i, j), i != j, of ``b: (N, 4)`` whose IoU is above the threshold (each pair once)."""
    order = np.argsort(b[:, 0], kind="stable")
    x0 = b[order, 0]
    end = np.searchsorted(x0, b[order, 2], side="left")           # boxes starting before my right edge
    start = np.arange(len(b)) + 1
    counts = np.maximum(end - start, 0)
    if counts.sum() == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    i = np.repeat(np.arange(len(b)), counts)
    j = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts) + np.repeat(start, counts)
    i, j = order[i], order[j]
    iw = np.minimum(b[i, 2], b[j, 2]) - np.maximum(b[i, 0], b[j, 0])
    ih = np.minimum(b[i, 3], b[j, 3]) - np.maximum(b[i, 1], b[j, 1])
    inter = np.clip(iw, 0, None) * np.clip(ih, 0, None)
    area = np.clip(b[:, 2] - b[:, 0], 0, None) * np.clip(b[:, 3] - b[:, 1], 0, None)
    iou = inter / np.maximum(area[i] + area[j] - inter, 1e-12)
    hit = iou > iou_threshold
    return i[hit], j[hit]


def nms(boxes: torch.Tensor, scores: torch.Tensor, iou_threshold: float) -> torch.Tensor:
    """Greedy NMS. ``boxes: (N, 4)``, ``scores: (N,)`` -> kept indices ``(K,) int64`` by falling score.

    A box is dropped when its IoU with a kept, higher-scoring box is above ``iou_threshold``;
    ties in score keep the lower index first. Overlapping pairs are found with a sweep over the
    boxes sorted by x0, so the cost follows the number of overlaps, not N^2.
    """
    if boxes.ndim != 2 or boxes.shape[1] != 4 or scores.shape != boxes.shape[:1]:
        raise ValueError(f"boxes must be (N, 4) and scores (N,), got {tuple(boxes.shape)}, {tuple(scores.shape)}")
    if boxes.shape[0] == 0:
        return torch.zeros(0, dtype=torch.long)
    order = torch.sort(scores, descending=True, stable=True).indices.numpy()
    b = boxes.detach().double().numpy()[order]
    i, j = _overlapping_pairs(b, iou_threshold)                   # ranks in score order
    lo, hi = np.minimum(i, j), np.maximum(i, j)                   # lo outranks hi
    srt = np.argsort(lo, kind="stable")
    lo, hi = lo[srt], hi[srt]
    bounds = np.searchsorted(lo, np.arange(len(b) + 1))
    sup = np.zeros(len(b), dtype=bool)
    for r in np.unique(lo):
        if not sup[r]:
            sup[hi[bounds[r]:bounds[r + 1]]] = True
    return torch.from_numpy(order[~sup].copy())


def batched_nms(boxes, scores, classes, iou_threshold: float) -> torch.Tensor:
    """NMS within each class (boxes of different classes never suppress each other)."""
    if boxes.shape[0] == 0:
        return torch.zeros(0, dtype=torch.long)
    offset = classes.to(boxes.dtype)[:, None] * (boxes.max() - boxes.min() + 1)
    return nms(boxes + offset, scores, iou_threshold)


def postprocess(pred: torch.Tensor, conf_threshold: float = MIN_SCORE, iou_threshold: float = NMS_IOU,
                max_det: int = 300, max_nms: int = 3000) -> list[torch.Tensor]:
    """``pred: (B, N, 5 + nc)`` decoded [cx, cy, w, h, obj, cls...] -> per image ``(K, 6)``
    [x0, y0, x1, y1, score, class] network px, score = obj x class probability (best class)."""
    if pred.ndim != 3 or pred.shape[2] < 6:
        raise ValueError(f"pred must be (B, N, 5 + nc), got {tuple(pred.shape)}")
    out = []
    for x in pred:
        x = x[x[:, 4] > conf_threshold]
        cls_conf, cls = (x[:, 5:] * x[:, 4:5]).max(1)
        x, cls_conf, cls = x[cls_conf > conf_threshold], cls_conf[cls_conf > conf_threshold], cls[cls_conf > conf_threshold]
        if x.shape[0] > max_nms:
            top = cls_conf.topk(max_nms).indices
            x, cls_conf, cls = x[top], cls_conf[top], cls[top]
        box = torch.cat((x[:, :2] - x[:, 2:4] / 2, x[:, :2] + x[:, 2:4] / 2), 1)
        keep = batched_nms(box, cls_conf, cls, iou_threshold)[:max_det]
        out.append(torch.cat((box[keep], cls_conf[keep, None], cls[keep, None].to(box.dtype)), 1))
    return out


def sha256_of(path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        while block := fh.read(1 << 20):
            h.update(block)
    return h.hexdigest()


class MarkerDetector:
    """Loaded weights + inference settings. ``detect(image)`` -> list of detection dicts.

    Raises CheckpointError (one line naming the file) for weights that cannot be used, those of a
    detector whose classes are not the markers' (RedA, BlueB) included."""

    def __init__(self, weights, conf_threshold: float = MIN_SCORE, iou_threshold: float = NMS_IOU,
                 max_det: int = 100, refine: bool = True, backend: str = "torch"):
        from dockfactory.detector.checkpoint import CheckpointError, load_model
        from dockfactory.detector.onnx_runtime import OnnxNetwork, resolve_backend
        self.weights = Path(weights)
        self.model, self.meta = load_model(self.weights, fuse=True)
        if self.model.detect.nc != len(CLASS_NAMES):
            raise CheckpointError(f"{self.weights}: a detector of {self.model.detect.nc} classes, not the "
                                  f"markers' {len(CLASS_NAMES)} ({', '.join(CLASS_NAMES)})")
        self.backend = resolve_backend(backend)
        card = card_figures(self.weights)   # the weights' noise card (None where there is none)
        self.centre_noise_px, self.section_shift_px = card.centre_noise_px, card.section_shift_px
        self.noise_core_px = card.core_px
        if self.backend == "onnx":
            self.network = OnnxNetwork(self.model)
        else:
            self.model = self.model.to(memory_format=torch.channels_last)  # about 25 % faster on CPU
            self.network = self.model
        self.scale = float(self.meta["data_config"]["input_scale"])
        self.conf, self.iou, self.max_det, self.refine = conf_threshold, iou_threshold, max_det, refine
        self.names = CLASS_NAMES

    def raw(self, image: np.ndarray) -> tuple[np.ndarray, LetterboxMap]:
        """Network detections ``(K, 6)`` [x0, y0, x1, y1, score, class] in image px (OpenCV)."""
        net, lb = letterbox(image, self.scale)
        x = torch.from_numpy(net).permute(2, 0, 1)[None].float().div_(255.0)
        x = x.contiguous(memory_format=torch.channels_last if self.backend == "torch" else torch.contiguous_format)
        with torch.inference_mode():
            det = postprocess(self.network(x), self.conf, self.iou, self.max_det)[0].double().numpy()
        det[:, :4] = lb.boxes_to_image(det[:, :4])
        return det, lb

    def detect(self, image: np.ndarray, cfa: str | None = None, jpeg: bool = False) -> list[dict]:
        """``image: (H, W, 3) uint8`` RGB -> detections sorted by falling score. What is known of
        the camera steers the centre refinement (``detector.centre_camera``): ``cfa``, the Bayer
        pattern of the camera whose demosaiced image this is (None: three-chip or unknown);
        ``jpeg``, the image was JPEG-encoded."""
        det, _ = self.raw(image)
        out = []
        for x0, y0, x1, y1, score, cls in det:
            c = int(cls)
            box = np.array([x0, y0, x1, y1])
            entry = {"class_id": c, "class_name": self.names[c], "score": round(float(score), 5)}
            if self.refine:
                r = refine_centre_camera(image, box, c, cfa, jpeg)
                entry.update(bbox_px=[round(float(v), 4) for v in r.box],
                             center_px=[round(float(v), 4) for v in r.center],
                             refine_quality=round(float(r.quality), 4), refined=bool(r.refined),
                             edge_px=round(float(r.edge_px), 4) if np.isfinite(r.edge_px) else None,
                             bbox_detector_px=[round(float(v), 4) for v in box])
            else:
                entry.update(bbox_px=[round(float(v), 4) for v in box],
                             center_px=[round(float((x0 + x1) / 2), 4), round(float((y0 + y1) / 2), 4)],
                             refine_quality=0.0, refined=False, bbox_detector_px=[round(float(v), 4) for v in box])
            out.append(entry)
        return drop_nested(out)


def drop_nested(dets: list[dict]) -> list[dict]:
    """Drop a detection whose centre lies inside the box of a higher-scoring detection of the
    same class. Markers sit in dark rings and never inside each other's outline, so such a pair
    is one marker seen twice (a part of a partly hidden disc and the whole of it, whose thin
    boxes overlap too little for NMS). ``dets`` sorted by falling score."""
    kept: list[dict] = []
    for d in dets:
        u, v = d["center_px"]
        if not any(k["class_id"] == d["class_id"] and k["bbox_px"][0] <= u <= k["bbox_px"][2]
                   and k["bbox_px"][1] <= v <= k["bbox_px"][3] for k in kept):
            kept.append(d)
    return kept


def detect_dataset(dataset, weights, out, split: str | None = "test", conf_threshold: float = MIN_SCORE,
                   iou_threshold: float = NMS_IOU, refine: bool = True, progress: bool = True,
                   camera=None) -> dict:
    """Run the detector over the frames of one split of a dataset and write the detections JSON.

    Parameters
    ----------
    dataset : detector.data.FrameSource
        The opened dataset (generator.datasets.reader.Dataset or a folder of frames).
    weights : str or Path
        A weights file or training checkpoint (loaded with ``weights_only=True``).
    out : str, Path or None
        Where the detections JSON is written atomically; None: returned only.
    split : str or None
        ``train``, ``val``, ``test``, or None for every frame.
    conf_threshold, iou_threshold : float
        The detection score kept and the NMS overlap (0-1).
    refine, progress : bool
        Refine each centre on the image (refine_centre); a progress line on stderr.
    camera : callable or None
        Frame id -> (Bayer pattern or None, JPEG-encoded?) of the camera that took it (what its
        maker knows; ``MarkerDetector.detect``); None: three-chip PNG.

    Returns
    -------
    dict
        ``{"format", "dataset", "dataset_version", "split", "weights", "weights_sha256",
        "conf_threshold", "iou_threshold", "pixel_convention", "timing", "frames": {frame_id:
        [det]}}``, each det ``{class_id, class_name, score, bbox_px, center_px, refine_quality,
        refined, edge_px, bbox_detector_px}`` (pixels in the OpenCV convention; ``edge_px``: the
        edge fit's edge width, null without one).

    Raises
    ------
    CheckpointError
        Weights missing, foreign, inconsistent, or of a detector whose classes are not the markers'.
    DockfactoryError
        A split without frames, or a frame image that cannot be read (one line naming it).
    """
    from dockfactory.detector.data import load_frames
    frames = load_frames(dataset, split)
    det = MarkerDetector(weights, conf_threshold, iou_threshold, refine=refine)
    if det.meta["dataset_version"] != dataset.version_id and progress:
        print(f"note: weights trained on dataset version {det.meta['dataset_version']}, "
              f"detecting on {dataset.version_id}", file=sys.stderr)
    results, times = _detect_frames(det, frames, camera, progress)
    doc = _detections_doc(dataset, split, weights, det, camera is not None, results, times)
    if out is not None:
        write_json_atomic(out, doc)
    return doc


def _detect_frames(det: "MarkerDetector", frames, camera, progress: bool) -> tuple[dict, list[float]]:
    """Each frame's detections (frame id -> list) and each frame's seconds of detection (the
    image read left out), the camera told as :func:`detect_dataset` says."""
    from dockfactory.detector.data import read_rgb
    results, times = {}, []
    bar = Progress(len(frames), "detect", enabled=progress, per="s")
    for i, f in enumerate(frames):
        img = read_rgb(f.image_path)
        t = time.perf_counter()
        cfa, jpeg = camera(f.frame_id) if camera is not None else (None, False)
        results[f.frame_id] = det.detect(img, cfa=cfa, jpeg=jpeg)
        times.append(time.perf_counter() - t)
        bar.update(i + 1, extra=f"{1000 * np.mean(times):.0f} ms/image")
    bar.close()
    return results, times


def _detections_doc(dataset, split, weights, det: "MarkerDetector", camera_told: bool, results: dict,
                    times: list[float]) -> dict:
    """The detections JSON of :func:`detect_dataset` (its Returns)."""
    return {"format": "dockfactory.detections/1", "dataset": str(dataset.root), "dataset_version": dataset.version_id,
            "split": split, "weights": str(weights), "weights_sha256": sha256_of(weights),
            "weights_dataset_version": det.meta["dataset_version"], "centre_noise_px": det.centre_noise_px,
            "centre_noise_core_px": det.noise_core_px, "section_shift_px": det.section_shift_px and list(det.section_shift_px),
            "conf_threshold": det.conf, "iou_threshold": det.iou, "camera_told": camera_told,
            "pixel_convention": "opencv: (0,0) is the centre of the top-left pixel",
            "timing": {"frames": len(times), "mean_ms": round(1000 * float(np.mean(times)), 2),
                       "median_ms": round(1000 * float(np.median(times)), 2)},
            "frames": results}
