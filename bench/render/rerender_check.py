"""How exactly a re-render reproduces a dataset: two renders of the same frames compared.

    python -m bench.render.rerender_check DATASET RERENDER

For every frame RERENDER holds (for example `dockfactory render CONFIG --out RERENDER --frames
...` in a new process, or on another machine): whether its label and image are byte for byte
those of DATASET, and for the images the pixel differences (largest absolute difference in 8-bit
levels, share of differing values) and the largest difference of the 80-px tile means that
`dockfactory dataset verify --manifest` compares (generator/datasets/published.py).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np

from dockfactory.generator.datasets.fingerprints import image_tiles


def compare_frame(a: Path, b: Path, fid: str) -> dict:
    la, lb = (r / "labels" / f"{fid}.json" for r in (a, b))
    ia, ib = (r / "images" / f"{fid}.png" for r in (a, b))
    same_image = ia.read_bytes() == ib.read_bytes()
    row = {"frame": fid, "label": la.read_bytes() == lb.read_bytes(), "image": same_image,
           "max_px": 0, "share": 0.0, "tile": 0.0}
    if not same_image:
        pa, pb = (cv2.imread(str(p), cv2.IMREAD_UNCHANGED).astype(np.int32) for p in (ia, ib))
        d = np.abs(pa - pb)
        row.update(max_px=int(d.max()), share=float((d > 0).mean()),
                   tile=float(np.abs(image_tiles(pa) - image_tiles(pb)).max()))
    return row


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("dataset", type=Path)
    ap.add_argument("rerender", type=Path)
    args = ap.parse_args()
    ids = sorted(p.stem for p in (args.rerender / "labels").glob("*.json"))
    rows = [compare_frame(args.dataset, args.rerender, fid) for fid in ids]
    print(f"{'frame':>10s} {'label':>6s} {'image':>6s} {'max px':>7s} {'share':>7s} {'tile':>6s}")
    for r in rows:
        print(f"{r['frame']:>10s} {'same' if r['label'] else 'DIFF':>6s} {'same' if r['image'] else 'DIFF':>6s} "
              f"{r['max_px']:7d} {r['share']:7.4f} {r['tile']:6.3f}")
    print(f"{len(rows)} frames: labels identical {sum(r['label'] for r in rows)}, images identical "
          f"{sum(r['image'] for r in rows)}; largest pixel difference {max((r['max_px'] for r in rows), default=0)} "
          f"levels, largest tile-mean difference {max((r['tile'] for r in rows), default=0.0):.3f} levels")
    return 0


if __name__ == "__main__":
    sys.exit(main())
