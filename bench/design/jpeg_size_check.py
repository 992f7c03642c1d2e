"""Does a JPEG's centre noise follow the disc's size as the lossless image's does? The design card
takes one JPEG factor per ring and camera class (no size term); this checks it per centre, against
the disc's minor semi-axis b, on two kinds of renders:

- a design space rendered by ``dockfactory design --verify`` (its ``verify/*/run`` folders): each
  JPEG design against the PNG design of the same camera, geometry and markers;
- the sensor bench's rows (``bench.sensor.sensor_effects --out ROWS``, written with its rows): each
  JPEG effect against the three-chip camera on the same frames (the datasets as arguments).

Per centre: the refined centre's distance from the label's outline centroid (fully visible markers);
b from the label's area and box (pi a b). Per bin of b: the median error of each and their ratio;
then the slope of log(ratio) on log(b) (0: the JPEG's noise scales with the disc as the lossless
image's, the card's assumption).

    python -m bench.design.jpeg_size_check --space out/s26/confirm7_quick [--space ...]
    python -m bench.design.jpeg_size_check --rows ROWS.json --dataset out/s24/sens_a [--dataset ...]
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from bench.sensor.sensor_effects import matched_centres

BINS = (3, 5, 6, 7, 8, 9, 10, 12, 15, 25)
MIN_CENTRES = 20


def centre_points(dets_by_frame: dict, label_of) -> np.ndarray:
    """(n, 2): (b px, error px) of every fully visible matched centre."""
    pts = []
    for fid, dets in dets_by_frame.items():
        label = label_of(fid)
        if label is None:
            continue
        for m, truth, c in matched_centres(dets, label):
            if m.get("visible_fraction", 1.0) < 0.99:
                continue
            x0, y0, x1, y1 = m["bbox_unclipped_px"]
            a = max(x1 - x0, y1 - y0) / 2.0
            pts.append((m["area_px"] / (np.pi * a), float(np.hypot(*(c - truth)))))
    return np.array(pts).reshape(-1, 2)


def ratio_by_bin(jpeg: np.ndarray, plain: np.ndarray) -> list[tuple[float, float, int]]:
    """[(bin centre b, median error ratio, centres)] over BINS with enough centres in both."""
    out = []
    for lo, hi in zip(BINS[:-1], BINS[1:]):
        sel = [p[(p[:, 0] >= lo) & (p[:, 0] < hi), 1] for p in (jpeg, plain)]
        if min(len(s) for s in sel) >= MIN_CENTRES:
            out.append((float(np.sqrt(lo * hi)), float(np.median(sel[0]) / np.median(sel[1])), min(len(s) for s in sel)))
    return out


def slope(rows) -> float:
    """Least-squares slope of log(ratio) on log(b), weighted by the centres."""
    b, r, n = (np.array(v, dtype=float) for v in zip(*rows))
    w = np.sqrt(n)
    x = np.c_[np.ones_like(b), np.log(b)] * w[:, None]
    return float(np.linalg.lstsq(x, np.log(r) * w, rcond=None)[0][1])


def _label_reader(folder: Path):
    def read(fid):
        path = folder / "labels" / f"{fid}.json"
        return json.loads(path.read_text()) if path.exists() else None
    return read


def space_pairs(space: Path):
    """(name, jpeg points, png points) of each JPEG design of a verified space with its PNG twin."""
    designs = {}
    for run in sorted(space.glob("verify/*/run")):
        name = (run.parent / "config.toml").read_text().splitlines()[0].lstrip("# ").strip()
        frames = json.loads((run / "detections.json").read_text())["frames"]
        designs[name] = centre_points(frames, _label_reader(run / "dataset"))
    for name, pts in designs.items():
        twin = name.rsplit("|", 1)[0] + "| png"
        if not name.endswith("png") and twin in designs:
            yield name, pts, designs[twin]


def rows_pairs(rows_path: Path, datasets: list[Path]):
    """(name, jpeg points, three-chip points) of each JPEG effect of a sensor bench rows file."""
    results = json.loads(rows_path.read_text())["datasets"]
    for key, effects in results.items():
        folder = next((d for d in datasets if json.loads((d / "dataset.json").read_text()).get("version_id") in key), None)
        if folder is None or "three-chip" not in effects:
            continue
        pts = {e: centre_points({r["frame"]: r["dets"] for r in v["rows"]}, _label_reader(folder)) for e, v in effects.items()}
        for effect in (e for e in pts if "jpeg" in e):
            base = "bayer-bilinear" if effect.startswith("bayer") and "bayer-bilinear" in pts else "three-chip"
            yield f"{key}: {effect} / {base}", pts[effect], pts[base]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--space", action="append", type=Path, default=[])
    ap.add_argument("--rows", type=Path)
    ap.add_argument("--dataset", action="append", type=Path, default=[])
    args = ap.parse_args(argv)
    pairs = [p for s in args.space for p in space_pairs(s)]
    if args.rows:
        pairs += list(rows_pairs(args.rows, args.dataset))
    print("| pair | median error ratio by b bin (b px: ratio) | slope of log ratio on log b |\n| --- | --- | --- |")
    for name, jpeg, plain in pairs:
        rows = ratio_by_bin(jpeg, plain)
        cells = " ".join(f"{b:.1f}: {r:.2f}" for b, r, _ in rows)
        print(f"| {name} | {cells} | {slope(rows):+.2f} |" if len(rows) >= 2 else f"| {name} | {cells} | |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
