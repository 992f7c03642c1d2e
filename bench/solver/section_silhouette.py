"""A rendered dataset's section silhouettes against Cycles' index pass: the labels' ``pixels_all``
(as rendered), the convex hull of all the section's circles and the union of flange and body
(generator.silhouette, the current label), each filled at pixel centres.

    .venv/bin/python -m bench.solver.section_silhouette DATASET   (a dataset rendered with [render] keep_exr)

Prints, summed over every section of every frame with a kept EXR: each silhouette's pixel count
and the index pass's section pixels (the section and its markers) inside it, as fractions of the
index pass's count; and how many of the sliver's pixel centres (inside the hull, outside flange
and body) the render drew as the section.
"""
import json
import sys
from pathlib import Path

import cv2
import numpy as np

from dockfactory.core.layout import SECTION_PASS_INDEX
from dockfactory.generator.bop_images import pinhole_px, section_mask
from dockfactory.generator.datasets.reader import Dataset
from dockfactory.generator.exr import read_compact
from dockfactory.generator.random_draws import static_scene
from dockfactory.generator.silhouette import fill_centres, section_silhouette


def section_counts(lab: dict, static, index: np.ndarray, srec: dict) -> dict:
    """One section's counts (see the module docstring)."""
    sec = srec["section"]
    w, h = lab["image"]["width"], lab["image"]["height"]
    uv = pinhole_px(lab, section_silhouette(static, sec), sec)
    hull = fill_centres(uv[cv2.convexHull(uv.astype(np.float32), returnPoints=False).ravel()], w, h)
    parts = section_mask(lab, static, sec)
    ids = [SECTION_PASS_INDEX[sec]] + [m.pass_index for m in static.markers if m.section == sec]
    drawn = np.isin(index, ids)
    return {"label_as_rendered": srec["pixels_all"], "hull_centres": int(hull.sum()), "flange_or_body": int(parts.sum()),
            "index_pass": int(drawn.sum()), "index_in_hull": int((drawn & hull).sum()),
            "index_in_flange_or_body": int((drawn & parts).sum()), "sliver": int((hull & ~parts).sum()),
            "sliver_drawn": int((hull & ~parts & drawn).sum())}


def main(argv: list[str]) -> int:
    if len(argv) != 1:
        print("usage: section_silhouette.py DATASET", file=sys.stderr)
        return 2
    root = Path(argv[0])
    ds = Dataset.open(root)
    static = static_scene(ds.config)
    total, n = {}, 0
    for fid, lab in sorted(ds.labels.items()):
        exr = root / "exr" / f"{fid}.exr"
        if not exr.is_file():
            continue
        index = read_compact(exr).index
        for srec in lab["sections"]:
            if srec.get("pixels_all"):
                for k, v in section_counts(lab, static, index, srec).items():
                    total[k] = total.get(k, 0) + v
                n += 1
    if not n:
        print(f"{root}: no frame with a kept EXR", file=sys.stderr)
        return 2
    ref = total["index_pass"]
    version = json.loads((root / "dataset.json").read_text())["version_id"]
    print(json.dumps({"dataset": version, "sections": n, "totals": total,
                      "per_index_pass": {k: round(v / ref, 5) for k, v in total.items()},
                      "sliver_drawn_fraction": round(total["sliver_drawn"] / total["sliver"], 4)}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
