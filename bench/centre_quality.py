"""Does a refined centre's quality mean something? Every refined detection of a labelled dataset
against the exact centroid of the marker it belongs to: how many are over 1 px off at a quality
above the refinement's gate, by condition and by how much of the marker is hidden.

    python bench/centre_quality.py DATASET DETECTIONS.json [DATASET DETECTIONS.json ...]
        [--min-score 0.25] [--out FILE.json]

Detections: a ``dockfactory detect --split all`` document of the dataset (refined centres).
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
from collections import defaultdict
from pathlib import Path

import numpy as np

from dockfactory.core.io import write_json_atomic
from dockfactory.generator.dataset_open import Dataset


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
            "unrefined": len(rows) - len(ref),
            "unrefined_over_1px": sum(r["error_px"] > 1.0 for r in rows if not r["refined"])}


def dataset_rows(root: Path, det_path: Path, min_score: float) -> tuple[list, int]:
    ds = Dataset.open(root)
    dets = json.loads(det_path.read_text())["frames"]
    rows, unmatched = [], 0
    for fid, frame_dets in sorted(dets.items()):
        r, u = match_rows(ds.labels[fid], frame_dets, min_score)
        rows += r
        unmatched += u
    return rows, unmatched


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
    ap.add_argument("pairs", nargs="+", help="DATASET DETECTIONS.json, repeated")
    ap.add_argument("--min-score", type=float, default=0.25)
    ap.add_argument("--out", type=Path)
    args = ap.parse_args(argv)
    if len(args.pairs) % 2:
        ap.error("give DATASET DETECTIONS.json pairs")
    result, every = {}, []
    for root, det in zip(args.pairs[0::2], args.pairs[1::2]):
        rows, unmatched = dataset_rows(Path(root), Path(det), args.min_score)
        every += rows
        result[root] = report(root, rows, unmatched)
    if len(result) > 1:
        result["overall"] = report("overall", every, sum(r["unmatched"] for r in result.values()))
    if args.out:
        write_json_atomic(args.out, result)
    return 0


if __name__ == "__main__":
    sys.exit(main())
