"""The goodness-of-fit gate's level against what cameras deliver: the residual ratio (per-axis RMS
over the noise card's centre noise) of every solved frame, per camera effect and scene, with
the gate off.

    python -m bench.verdict.gate_ratios DATASET [DATASET ...] [--effects three-chip,bayer-vng,...]
        [--out FILE.json]

Each DATASET is a rendered dataset with its EXR passes (as bench/sensor/sensor_effects.py takes
them); every test frame goes through each effect's camera (bench.sensor.sensor_effects.EFFECTS,
the refinement told the Bayer pattern and the JPEG), the shipped detector and the pinhole solve.
Per dataset and effect: the pooled ratio (sqrt of the mean squared ratio), median, 90th and 99th
percentile and max. The gate tests against eval.fit_gate.GATE_NOISE_FACTOR times the card.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

import bench.sensor.sensor_effects as effects
from dockfactory.core.io import write_json_atomic
from dockfactory.core.resources import shipped_weights
from dockfactory.detector.infer import MarkerDetector
from dockfactory.eval import fit_gate
from dockfactory.generator.datasets.reader import Dataset

DEFAULT_EFFECTS = "three-chip,bayer-vng,three-chip-jpeg90,bayer-jpeg90,blur1.2"


def effect_ratios(detector, ds: Dataset, effect: str, frames: list[str]) -> list[float]:
    """The residual ratio of every frame of ``ds`` solved through ``effect``, the gate off."""
    ratios, solve = [], effects.solve_frame

    def capture(*args, **kwargs):
        out = solve(*args, **kwargs)
        ratio = (out[0].get("fit_test") or {}).get("ratio")
        if ratio is not None:
            ratios.append(ratio)
        return out
    effects.solve_frame, level = capture, fit_gate.GATE_P
    fit_gate.GATE_P = 1e-300                        # nothing refused: every frame's ratio counts
    try:
        effects.run_effect(detector, ds, effect, frames, True, True)
    finally:
        effects.solve_frame, fit_gate.GATE_P = solve, level
    return ratios


def summary(ratios: list[float]) -> dict:
    r = np.asarray(ratios)
    return {"frames": len(r), "pooled": float(np.sqrt(np.mean(r ** 2))), "median": float(np.median(r)),
            "p90": float(np.percentile(r, 90)), "p99": float(np.percentile(r, 99)), "max": float(r.max())}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("datasets", nargs="+", type=Path)
    ap.add_argument("--effects", default=DEFAULT_EFFECTS)
    ap.add_argument("--frames", type=int, default=48, help="first N test frames")
    ap.add_argument("--out", type=Path)
    args = ap.parse_args(argv)
    detector = MarkerDetector(shipped_weights())
    out = {"card_px": detector.centre_noise_px, "gate_factor": fit_gate.GATE_NOISE_FACTOR, "datasets": {}}
    print(f"card {detector.centre_noise_px:.4f} px, gate at {fit_gate.GATE_NOISE_FACTOR:g}x")
    print("| dataset | effect | frames | pooled | median | p90 | p99 | max |\n| --- | --- | --- | --- | --- | --- | --- | --- |")
    for root in args.datasets:
        ds = Dataset.open(root)
        rows = out["datasets"][f"{ds.config.dataset.name}@{ds.version_id}"] = {}
        for effect in args.effects.split(","):
            s = rows[effect] = summary(effect_ratios(detector, ds, effect, ds.frames("test")[:args.frames]))
            print(f"| {root.name} | {effect} | {s['frames']} | " + " | ".join(f"{s[k]:.2f}" for k in
                                                                           ("pooled", "median", "p90", "p99", "max")) + " |")
    if args.out:
        write_json_atomic(args.out, out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
