"""How far the detector's box edges sit from the exact marker outlines: the network's own boxes
(``bbox_detector_px``) and the refined ones (``bbox_px``, after the edge fit of detector.centre).

For every detection at score >= 0.25 whose centre lies within 3 px of a marker of its class that
is at least 99 % visible, the four edge offsets (detection - label outline, px; x0, y0, x1, y1) are
collected. Prints their mean, median and RMS per kind of box, and the mean width and height error.
COCO mAP50:95 of ~25 x 18 px boxes turns on these fractions of a pixel.

Run: python -m bench.detector.box_edges DATASET DETECTIONS.json [--split test]
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from bench.marker_match import nearest_marker

MATCH_PX = 3.0


def matched_outline(det: dict, markers: list[dict]) -> np.ndarray | None:
    """The label outline box of the nearest fully visible marker of the detection's class."""
    hit = nearest_marker(det, markers, MATCH_PX)
    return None if hit is None else np.asarray(hit[1]["bbox_px"])


def edge_offsets(root: Path, frames: dict, split: str) -> tuple[np.ndarray, np.ndarray]:
    """((n, 4) network box - outline, (n, 4) refined box - outline), px."""
    net, ref = [], []
    for fid, dets in sorted(frames.items()):
        label = json.loads((root / "labels" / f"{fid}.json").read_text())
        if label["spec"]["split"] != split:
            continue
        markers = [m for m in label["markers"] if m["in_frame"] and m.get("visible_fraction", 0) >= 0.99]
        for det in dets:
            outline = matched_outline(det, markers) if det["score"] >= 0.25 else None
            if outline is not None and "bbox_detector_px" in det:
                net.append(np.asarray(det["bbox_detector_px"]) - outline)
                ref.append(np.asarray(det["bbox_px"]) - outline)
    return np.asarray(net).reshape(-1, 4), np.asarray(ref).reshape(-1, 4)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("dataset", type=Path)
    ap.add_argument("detections", type=Path)
    ap.add_argument("--split", default="test")
    args = ap.parse_args()
    net, ref = edge_offsets(args.dataset, json.loads(args.detections.read_text())["frames"], args.split)
    if not len(net):
        raise SystemExit(f"{args.detections}: no matched detection with bbox_detector_px in split {args.split!r}")
    print(f"{args.detections}: {len(net)} matched {args.split} boxes; edge offsets x0 y0 x1 y1 (detection - outline, px)")
    for name, off in (("network", net), ("refined", ref)):
        mean, med, rms = off.mean(0), np.median(off, 0), np.sqrt((off ** 2).mean(0))
        fmt = lambda v: " ".join(f"{x:+.3f}" for x in v)  # noqa: E731
        print(f"  {name:8s} mean {fmt(mean)}  median {fmt(med)}  rms {fmt(rms)}  "
              f"width {mean[2] - mean[0]:+.3f} height {mean[3] - mean[1]:+.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
