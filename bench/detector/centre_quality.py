"""Does a refined centre's quality mean something? Every refined detection of a labelled dataset
against the exact centroid of the marker it belongs to: how many are over 1 px off at a quality
above the refinement's gate, by condition and by how much of the marker is hidden.

    python -m bench.detector.centre_quality DATASET DETECTIONS.json [DATASET DETECTIONS.json ...]
        [--min-score 0.25] [--out FILE.json]
    python -m bench.detector.centre_quality DATASET [DATASET ...] --camera three-chip|bayer|jpeg90|mp4v|mp4v-colour
        [--weights W] [--out FILE.json]

Detections: a ``dockfactory detect --split all`` document of the dataset (refined centres); with
``--camera`` the bench detects every frame itself after the camera's effect (``bayer``: an RGGB
mosaic demosaiced by VNG, refined with the pattern known, as ``measure --cfa RGGB``; ``jpeg90``:
a JPEG of quality 90 with 4:2:0 chroma, refined as ``measure`` refines a .jpg; ``three-chip``:
the frame as rendered; ``mp4v``: one frame of an MPEG-4 video, 4:2:0, refined on the luma as
``measure --video`` refines a lossy stream, ``mp4v-colour`` the same frame refined on the colour).
A detection is matched to the nearest label marker of its class (visibility >= 1) whose
``outline_centroid_px`` lies within the marker's apparent radius (sqrt(area_px / pi)); unmatched
detections are counted apart (false positives or centres more than a radius off). Per dataset
and overall: refined detections (quality at or above the gate, ``refined`` true), those over
1 px off (the share and its 95 % Wilson interval), over 0.5 px, by condition and by visible
fraction (< 0.9 / >= 0.9), unrefined ones and their errors; the worst refined detections listed
with their quality, condition, visible fraction and edge width.
"""
from __future__ import annotations

import os

import dockfactory

dockfactory.pin_label_arithmetic(os.environ)   # before numpy loads: labels as the command computes them

import argparse
import json
import math
import sys
import tempfile
from collections import defaultdict
from pathlib import Path

import numpy as np

from dockfactory.core.camera_chain.cfa import mosaic
from dockfactory.core.cv import cv2
from dockfactory.core.camera_chain.demosaic import demosaic
from dockfactory.core.io import write_json_atomic
from dockfactory.core.camera_chain import jpeg_round_trip
from dockfactory.generator.datasets.reader import Dataset


def wilson(k: int, n: int, z: float = 1.96) -> list:
    """95 % Wilson interval of a share k / n."""
    if n == 0:
        return [0.0, 1.0]
    p = k / n
    c = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    mid = (p + z * z / (2 * n)) / (1 + z * z / n)
    return [max(0.0, mid - c), min(1.0, mid + c)]


def match_rows(label: dict, dets: list, min_score: float) -> tuple[list, int]:
    """([row per matched detection], unmatched detections) of one frame."""
    marks = [m for m in label["markers"] if m.get("visibility", 0) >= 1 and m.get("area_px")]
    rows, unmatched = [], 0
    for d in dets:
        if d.get("score", 1.0) < min_score:
            continue
        best = None
        for m in marks:
            if m["class_id"] != d["class_id"]:
                continue
            c = m.get("outline_centroid_px") or m["center_px"]
            dist = float(np.hypot(d["center_px"][0] - c[0], d["center_px"][1] - c[1]))
            if dist <= math.sqrt(m["area_px"] / math.pi) and (best is None or dist < best[0]):
                best = (dist, m)
        if best is None:
            unmatched += 1
            continue
        m = best[1]
        rows.append({"frame": label["frame_id"], "marker": m["id"], "error_px": best[0],
                     "quality": d.get("refine_quality", 0.0), "refined": bool(d.get("refined")),
                     "edge_px": d.get("edge_px"), "condition": label["spec"]["condition"],
                     "visible_fraction": m.get("visible_fraction", 1.0),
                     "radius_px": math.sqrt(m["area_px"] / math.pi)})
    return rows, unmatched


def summary(rows: list) -> dict:
    """Counts and shares of one group of matched rows."""
    ref = [r for r in rows if r["refined"]]
    over1 = sum(r["error_px"] > 1.0 for r in ref)
    return {"refined": len(ref), "over_1px": over1, "share_over_1px": over1 / max(len(ref), 1),
            "wilson95": wilson(over1, len(ref)), "over_0_5px": sum(r["error_px"] > 0.5 for r in ref),
            "median_px": float(np.median([r["error_px"] for r in ref])) if ref else None,
            "p90_px": float(np.percentile([r["error_px"] for r in ref], 90)) if ref else None,
            "unrefined": len(rows) - len(ref),
            "unrefined_over_1px": sum(r["error_px"] > 1.0 for r in rows if not r["refined"])}


def dataset_rows(root: Path, dets: dict, min_score: float) -> tuple[list, int]:
    """(matched rows, unmatched detections) of the dataset at ``root`` and its detections
    ``dets`` ({frame id: [detection]})."""
    ds = Dataset.open(root)
    rows, unmatched = [], 0
    for fid, frame_dets in sorted(dets.items()):
        r, u = match_rows(ds.labels[fid], frame_dets, min_score)
        rows += r
        unmatched += u
    return rows, unmatched


CAMERAS = ("three-chip", "bayer", "jpeg90", "mp4v", "mp4v-colour")


def mp4v_round_trip(image: np.ndarray) -> np.ndarray:
    """``image`` (H, W, 3) uint8 RGB as one frame of an MPEG-4 Part 2 video (OpenCV's mp4v, 4:2:0
    chroma, as ``dataset export --format video`` writes runs) decodes."""
    with tempfile.TemporaryDirectory() as tmp:
        path = str(Path(tmp) / "f.mp4")
        writer = cv2.VideoWriter(path, cv2.VideoWriter_fourcc(*"mp4v"), 10.0, (image.shape[1], image.shape[0]))
        writer.write(cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
        writer.release()
        ok, frame = cv2.VideoCapture(path).read()
    if not ok:
        raise RuntimeError("OpenCV could not round-trip a frame through mp4v")
    return cv2.cvtColor(frame, cv2.COLOR_BGR2RGB)


def camera_image(image: np.ndarray, camera: str) -> tuple[np.ndarray, str | None, bool]:
    """(the frame ``image`` (H, W, 3) uint8 RGB through ``camera``, its Bayer pattern, whether
    the refinement is told the colour is subsampled). ``mp4v`` is refined as a stream of it is
    (dockfactory.measure.chroma), ``mp4v-colour`` on the colour score as it was before."""
    if camera == "bayer":
        return demosaic(mosaic(image, "RGGB"), "RGGB", "vng"), "RGGB", False
    if camera == "jpeg90":
        return jpeg_round_trip(image, 90, "420"), None, True
    if camera.startswith("mp4v"):
        return mp4v_round_trip(image), None, camera == "mp4v"
    return image, None, False


def camera_detections(root: Path, camera: str, weights: Path | None) -> dict:
    """{frame id: detections} of every frame of the dataset at ``root`` through ``camera``."""
    from dockfactory.detector.infer import MarkerDetector
    from dockfactory.core.resources import shipped_weights
    detector = MarkerDetector(weights or shipped_weights())
    out = {}
    for fid in sorted(Dataset.open(root).labels):
        bgr = cv2.imread(str(root / "images" / f"{fid}.png"), cv2.IMREAD_COLOR)
        image, cfa, jpeg = camera_image(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), camera)
        out[fid] = detector.detect(image, cfa=cfa, jpeg=jpeg)
    return out


def report(name: str, rows: list, unmatched: int) -> dict:
    groups = defaultdict(list)
    for r in rows:
        groups[r["condition"]].append(r)
        groups["visible < 0.9" if r["visible_fraction"] < 0.9 else "visible >= 0.9"].append(r)
    out = {"all": summary(rows), "unmatched": unmatched, **{k: summary(v) for k, v in sorted(groups.items())}}
    worst = sorted((r for r in rows if r["refined"]), key=lambda r: -r["error_px"])[:15]
    out["worst"] = [{k: (round(v, 4) if isinstance(v, float) else v) for k, v in r.items()} for r in worst]
    print(f"\n{name}: unmatched detections {unmatched}")
    print(f"{'group':<16}{'refined':>8}{'> 1 px':>7}{'share %':>9}{'95 %':>16}{'> 0.5':>7}{'unrefined':>10}{'(> 1 px)':>9}")
    for k, s in out.items():
        if isinstance(s, dict) and "refined" in s:
            lo, hi = s["wilson95"]
            print(f"{k:<16}{s['refined']:>8}{s['over_1px']:>7}{100 * s['share_over_1px']:>9.2f}"
                  f"{f'[{100 * lo:.2f}-{100 * hi:.2f}]':>16}{s['over_0_5px']:>7}{s['unrefined']:>10}{s['unrefined_over_1px']:>9}")
    for r in worst[:8]:
        print(f"   {r['frame']} {r['marker']:<4} {r['error_px']:.2f} px  q {r['quality']:.2f}  {r['condition']:<9}"
              f" visible {r['visible_fraction']:.2f}  edge {r['edge_px']}")
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("pairs", nargs="+", help="DATASET DETECTIONS.json, repeated (with --camera: DATASET ...)")
    ap.add_argument("--camera", choices=CAMERAS, help="detect every frame through this camera")
    ap.add_argument("--weights", type=Path, help="with --camera (default: the shipped weights)")
    ap.add_argument("--min-score", type=float, default=0.25)
    ap.add_argument("--out", type=Path)
    args = ap.parse_args(argv)
    if args.camera is None and len(args.pairs) % 2:
        ap.error("give DATASET DETECTIONS.json pairs")
    sources = ([(root, lambda r=root: camera_detections(Path(r), args.camera, args.weights)) for root in args.pairs]
               if args.camera else
               [(root, lambda d=det: json.loads(Path(d).read_text())["frames"])
                for root, det in zip(args.pairs[0::2], args.pairs[1::2])])
    result, every = {"camera": args.camera or "detections files"}, []
    for root, dets in sources:
        rows, unmatched = dataset_rows(Path(root), dets(), args.min_score)
        every += rows
        result[root] = report(root, rows, unmatched)
    if len(result) > 2:
        result["overall"] = report("overall", every, sum(r["unmatched"] for r in result.values() if isinstance(r, dict)))
    if args.out:
        write_json_atomic(args.out, result)
    return 0


if __name__ == "__main__":
    sys.exit(main())
