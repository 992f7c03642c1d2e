"""How much more a thin disc's centre errs across it than the disc noise model says, against the
disc's thickness in edge widths: the measurement behind ``solver.disc_noise.thin_disc_factor``.

    python -m bench.sensor.thin_disc_noise DATASET [DATASET ...] [--effects three-chip,blur1.2]
                                    [--frames N] [--weights W.pt]

Each DATASET keeps its linear renders (bench/configs/sensor_scene_a.toml, sensor_scene_b.toml).
Per delivered test frame (``sensor_effects.delivered``) the shipped detector and refinement run
(three-chip path, not told any pattern); each fully visible, legible marker's refined centre is
matched to its label (outline centroid, within 2 px). Its error is split along the minor and the
major axis of the label's disc image (``solver.disc_noise.disc_ellipses``) and divided by the
disc noise model's variance along each (``noise_shapes`` without edge widths): z_minor^2,
z_major^2. Per (dataset, effect), z^2 is normalised by the mean z_major^2 (the major axis does not
depend on the thickness), then binned by r = minor semi-axis / the refinement's edge width
(``Refined.edge_px``). Printed: per bin the mean normalised z_minor^2 (the measured factor) beside
1 + (R / r)^P of the shipped constants, and the (R, P) of largest Gaussian likelihood, per input
and pooled over all of them.
"""
from __future__ import annotations

import argparse
import sys

import numpy as np

from bench.sensor import sensor_effects as se
from bench.sensor.centre_bound import disc_geometry

from dockfactory.solver.disc_noise import THIN_DISC_POWER, THIN_DISC_RATIO, noise_shapes
BINS = (0.0, 2.5, 3.5, 4.5, 6.0, 8.0, 12.0, 20.0, np.inf)
GRID_R = np.arange(1.0, 8.01, 0.25)
GRID_P = np.arange(0.5, 6.01, 0.25)


def frame_rows(detector, ds, fid: str, effect: str) -> list[tuple[float, float, float]]:
    """(r, z_minor^2, z_major^2) of each matched marker of one delivered frame."""
    from dockfactory.generator.exr import read_passes
    label = ds.labels[fid]
    image = se.delivered(read_passes(ds.root / "exr" / f"{fid}.exr").rgb, label, effect)
    dets = [d for d in detector.detect(image) if d.get("edge_px") is not None]
    marks = [m for m in label["markers"] if m.get("visibility") == 2 and m.get("legible", True)]
    if not marks or not dets:
        return []
    ellipses = disc_geometry(label, marks)
    rows = []
    for m, s in zip(marks, ellipses):
        truth = np.array(m["outline_centroid_px"])
        near = [d for d in dets if d["class_id"] == m["class_id"]
                and np.hypot(*(np.array(d["center_px"]) - truth)) < 2.0]
        if not near:
            continue
        d = min(near, key=lambda d: np.hypot(*(np.array(d["center_px"]) - truth)))
        lam, vec = np.linalg.eigh(s)
        t = noise_shapes(s[None])[0]
        e = np.array(d["center_px"]) - truth
        minor, major = vec[:, 0], vec[:, 1]
        rows.append((np.sqrt(lam[0]) / d["edge_px"], (e @ minor) ** 2 / (minor @ t @ minor),
                     (e @ major) ** 2 / (major @ t @ major)))
    return rows


def normalised(rows: np.ndarray) -> np.ndarray:
    """(n, 2): r and z_minor^2 over the mean z_major^2 of the same input."""
    return np.stack([rows[:, 0], rows[:, 1] / rows[:, 2].mean()], 1)


def best_law(data: list[np.ndarray]) -> tuple[float, float]:
    """(R, P) on the grid that maximise the Gaussian likelihood of z_minor^2 ~ f chi^2_1,
    f = 1 + (R / r)^P, over the inputs ``data`` (each (n, 2) of :func:`normalised`)."""
    r = np.concatenate([d[:, 0] for d in data])
    z2 = np.concatenate([d[:, 1] for d in data])
    best = None
    for big_r in GRID_R:
        for p in GRID_P:
            f = 1.0 + (big_r / r) ** p
            nll = float(np.mean(np.log(f) + z2 / f))
            if best is None or nll < best[0]:
                best = (nll, float(big_r), float(p))
    return best[1], best[2]


def table(name: str, d: np.ndarray) -> list[str]:
    """Markdown rows: per bin of r, markers, measured factor, the shipped law's factor."""
    out = []
    for lo, hi in zip(BINS[:-1], BINS[1:]):
        k = d[(d[:, 0] >= lo) & (d[:, 0] < hi)]
        if len(k) >= 10:
            law = float(np.mean(1.0 + (THIN_DISC_RATIO / k[:, 0]) ** THIN_DISC_POWER))
            out.append(f"| {name} | {lo:g}-{hi:g} | {len(k)} | {k[:, 1].mean():.2f} | {law:.2f} |")
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("datasets", nargs="+")
    ap.add_argument("--effects", default="three-chip,blur1.2")
    ap.add_argument("--frames", type=int, default=0, help="first N test frames only (0: all)")
    ap.add_argument("--weights", default=None)
    args = ap.parse_args(argv)
    import torch
    torch.set_num_threads(2)
    from dockfactory.core.resources import shipped_weights
    from dockfactory.detector.infer import MarkerDetector
    from dockfactory.generator.datasets.reader import Dataset
    detector = MarkerDetector(args.weights or shipped_weights())
    data, lines = [], []
    for root in args.datasets:
        ds = Dataset.open(root, full=False)
        for effect in args.effects.split(","):
            frames = ds.frames("test")[: args.frames or None]
            rows = [r for fid in frames for r in frame_rows(detector, ds, fid, effect)]
            d = normalised(np.array(rows, dtype=float))
            name = f"{ds.config.dataset.name}@{ds.version_id} {effect}"
            big_r, p = best_law([d])
            lines += table(name, d) + [f"| {name} | best R {big_r:.2f}, P {p:.2f} | {len(d)} | | |"]
            data.append(d)
            print(f"{name}: {len(d)} markers", file=sys.stderr, flush=True)
    big_r, p = best_law(data)
    print(f"shipped law: R {THIN_DISC_RATIO}, P {THIN_DISC_POWER}; pooled best: R {big_r:.2f}, P {p:.2f}\n")
    print("| input | r = minor / edge width | markers | measured factor | law |")
    print("| --- | --- | --- | --- | --- |")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
