"""How the detector's centre errors correlate between markers of one frame, per camera effect: the
within-frame half of what the docking run's bias field rests on (``solver.model_error.BIAS_LENGTH``;
the run half, one marker over a run's frames, is ``model_error_runs.py ... correlation``).

    python -m bench.sensor.centre_correlation DATASET [DATASET ...] [--effects three-chip,blur1.2,bayer-jpeg90]
                                       [--frames N]

Each DATASET keeps its linear renders (bench/configs/sensor_scene_a.toml, sensor_scene_b.toml).
Per delivered test frame (``sensor_effects.delivered``) the shipped detector runs as the sensor
bench runs it (told the camera's Bayer pattern and whether it wrote a JPEG); each fully visible,
legible marker's centre is matched to its label (``sensor_effects.matched_centres``) and its error (centre
minus the outline centroid) goes into ``model_error_runs.correlation_table``. Prints one table per
dataset and effect.
"""
from __future__ import annotations

import argparse
import sys


from bench.sensor import sensor_effects as se
from bench.cli.model_error_runs import correlation_table


def frame_rows(detector, ds, fid: str, effect: str) -> list[tuple]:
    """(frame, None, marker id, truth (2,), error (2,)) of each matched marker of one frame."""
    from dockfactory.generator.exr import read_passes
    label = ds.labels[fid]
    cam = se.EFFECTS[effect][0](label["spec"]["index"])
    cfa = se.SAMPLED_AS.get(effect, cam.cfa if cam is not None and cam.cfa != "none" else None)
    image = se.delivered(read_passes(ds.root / "exr" / f"{fid}.exr").rgb, label, effect)
    dets = detector.detect(image, cfa=cfa, jpeg=se.EFFECTS[effect][2] is not None)
    return [(fid, None, m["id"], truth, centre - truth) for m, truth, centre in se.matched_centres(dets, label)]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("datasets", nargs="+")
    p.add_argument("--effects", default="three-chip,blur1.2,bayer-jpeg90")
    p.add_argument("--frames", type=int, default=100, help="first N test frames (0: all)")
    args = p.parse_args(argv)
    import torch
    torch.set_num_threads(2)
    from dockfactory.core.resources import shipped_weights
    from dockfactory.detector.infer import MarkerDetector
    from dockfactory.generator.datasets.reader import Dataset
    detector = MarkerDetector(shipped_weights())
    for root in args.datasets:
        ds = Dataset.open(root, full=False)
        for effect in args.effects.split(","):
            rows = [r for fid in ds.frames("test")[: args.frames or None] for r in frame_rows(detector, ds, fid, effect)]
            print(f"\n{ds.config.dataset.name}@{ds.version_id} {effect}\n\n{correlation_table(rows)}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
