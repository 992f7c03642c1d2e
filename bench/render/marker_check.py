"""How far a rendered dataset's images sit from the marker check's bounds (generator/datasets/marker_check.py).

    python -m bench.render.marker_check DATASET [DATASET ...] [--frames N]

Per dataset: the markers judged, the distribution of each marker's colour count over its label's
visible pixels (bounds COUNT_RATIO) and of its colour centroid's distance from the label's outline
centroid (bound CENTROID_TOLERANCE_PX), and the problems found (a faithful dataset: none). Run it
on datasets of different geometry, sensors and lens effects before changing a bound.
"""
from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import cv2
import numpy as np

from dockfactory.generator.datasets.marker_check import _checked, marker_colour, marker_problems


def dataset_figures(root: Path, frames: int | None) -> str:
    ratios, offsets, problems, n = [], [], [], 0
    for lp in sorted((root / "labels").glob("*.json"))[:frames]:
        label = json.loads(lp.read_text())
        image = cv2.cvtColor(cv2.imread(str(root / "images" / f"{lp.stem}.png")), cv2.COLOR_BGR2RGB)
        n += 1
        problems += marker_problems(image, label, lp.stem)[1]
        for m in label["markers"]:
            count, centroid = marker_colour(image, m) if _checked(m) else (-1, None)
            if count < 0:
                continue
            ratios.append(count / m["visible_pixels"])
            if centroid is not None:
                offsets.append(math.hypot(centroid[0] - m["outline_centroid_px"][0],
                                          centroid[1] - m["outline_centroid_px"][1]))
    r, d = np.array(ratios), np.array(offsets)
    version = json.loads((root / "dataset.json").read_text())["version_id"]
    lines = [f"{root} ({version}): {n} frames, {len(r)} markers judged; count ratio min {r.min():.3f} "
             f"p50 {np.median(r):.3f} max {r.max():.3f}; centroid offset p50 {np.median(d):.3f} "
             f"p99 {np.percentile(d, 99):.3f} max {d.max():.3f} px; problems {len(problems)}"]
    return "\n".join(lines + [f"  {p}" for p in problems[:10]])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("datasets", nargs="+", type=Path)
    ap.add_argument("--frames", type=int, default=None, help="the first N frames of each (default: all)")
    args = ap.parse_args()
    for root in args.datasets:
        print(dataset_figures(root, args.frames), flush=True)


if __name__ == "__main__":
    main()
