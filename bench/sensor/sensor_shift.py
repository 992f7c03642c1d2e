"""The section shift through real colour cameras: measured on one scene, carried on the other.

    python -m bench.sensor.sensor_shift RESULTS.json DATASET_A DATASET_B [--out SHIFT.json]

RESULTS.json is a bench/sensor/sensor_effects.py output whose rows keep their detections (``dets``,
``used``: every run since the section shift exists). Per effect, the common offset of a section's
centres in a frame (eval.section_shift: what no fit's residuals show) is measured on each scene's
frames through that camera, and the other scene's frames are solved again with it
(solver.section_shift, the pinhole per frame as the sensor bench solves them): a user renders
frames of their camera class, measures the shift on them, and measures other frames with it. Per
effect and scene: the shift measured there, the RMS z (error / reported std) of X, Y and alpha as
the sensor bench solved them and with the other scene's shift, each with its bootstrap interval
(95 %, frames resampled). The errors do not change; only the reported std does.
"""
from __future__ import annotations

import argparse
import json
import sys

import numpy as np

from dockfactory.core.io import write_json_atomic
from dockfactory.detector.noise_card import centre_noise_px
from dockfactory.eval.section_shift import section_groups, section_shift_stats
from dockfactory.eval.solve_frames import detection_arrays, docking_options, lens_prior_for, solve_frame
from dockfactory.generator.datasets.reader import Dataset

from bench.sensor.sensor_effects import COMPONENTS, pose_errors, rms_z_bootstrap_interval

MIN_SCORE = 0.25   # the sensor bench's


def scene_shift(ds: Dataset, rows: list[dict]) -> dict:
    """:func:`section_shift_stats` over the solved rows of one scene and effect."""
    groups = []
    for r in rows:
        if r["ok"] and r.get("dets") is not None:
            groups += section_groups(ds.labels[r["frame"]], r["dets"], r.get("used"), MIN_SCORE)
    return section_shift_stats(groups)


def resolved_z(ds: Dataset, rows: list[dict], shift, floor) -> dict:
    """{"z_<c>": [...]} of every row solved again from its detections with ``shift`` (x, y) px."""
    w, h = ds.config.image.width, ds.config.image.height
    options = docking_options(floor, lens_prior_for(ds.config), shift)
    out, markers = {f"z_{c}": [] for c in COMPONENTS}, ds.markers()
    for r in rows:
        rec = solve_frame(markers, ((w - 1) / 2.0, (h - 1) / 2.0), detection_arrays(r["dets"], MIN_SCORE),
                          None, "pinhole", options)[0]
        if rec["ok"]:
            for k, v in pose_errors(rec, ds.labels[r["frame"]]).items():
                if k.startswith("z_") and v is not None:
                    out[k].append(v)
    return out


def z_summary(zs: dict) -> dict:
    """{c: [RMS z, low, high]}."""
    out = {}
    for c in COMPONENTS:
        z = np.array(zs[f"z_{c}"], dtype=float)
        out[c] = [float(np.sqrt(np.mean(z ** 2))), *(rms_z_bootstrap_interval(z) or [None, None])]
    return out


def effect_rows(results: dict, key: str, effect: str) -> list[dict] | None:
    rows = results["datasets"].get(key, {}).get(effect, {}).get("rows")
    return rows if rows and all("dets" in r for r in rows) else None


def compare_effect(scenes, results: dict, effect: str, floor) -> dict | None:
    """The shift of each scene and both scenes' RMS z before and with the other's shift."""
    rows = [effect_rows(results, key, effect) for _, key in scenes]
    if any(r is None for r in rows):
        return None
    shifts = [scene_shift(ds, r) for (ds, _), r in zip(scenes, rows)]
    out = {}
    for i, ((ds, key), r) in enumerate(zip(scenes, rows)):
        other = shifts[1 - i]["shift_axis_px"]
        before = {f"z_{c}": [x[f"z_{c}"] for x in r if x["ok"] and x.get(f"z_{c}") is not None] for c in COMPONENTS}
        out[key] = {"shift_measured_here": shifts[i], "shift_used": other, "frames": len(r),
                    "before": z_summary(before), "with_other_shift": z_summary(resolved_z(ds, r, other, floor))}
    return out


def _cell(v) -> str:
    rms, lo, hi = v
    flag = "**" if not 0.85 <= rms <= 1.2 else ""
    return f"{flag}{rms:.2f}{flag} [{lo:.2f}-{hi:.2f}]" if lo is not None else f"{flag}{rms:.2f}{flag}"


def table(out: dict) -> str:
    lines = ["| effect | scene | shift measured here x / y px | shift used (other scene) | RMS z X / Y / alpha before "
             "| RMS z X / Y / alpha with the other scene's shift |", "| --- | --- | --- | --- | --- | --- |"]
    for effect, per in out["effects"].items():
        for key, v in per.items():
            here, used = v["shift_measured_here"]["shift_axis_px"], v["shift_used"]
            lines.append(f"| {effect} | {key} | {here[0]:.3f} / {here[1]:.3f} | {used[0]:.3f} / {used[1]:.3f} | "
                         + " / ".join(_cell(v["before"][c]) for c in COMPONENTS) + " | "
                         + " / ".join(_cell(v["with_other_shift"][c]) for c in COMPONENTS) + " |")
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("results")
    p.add_argument("datasets", nargs=2)
    p.add_argument("--out")
    a = p.parse_args(argv)
    results = json.loads(open(a.results).read())
    scenes = []
    for root in a.datasets:
        ds = Dataset.open(root, full=False)
        scenes.append((ds, f"{ds.config.dataset.name}@{ds.version_id}"))
    floor = centre_noise_px(results["weights"])
    effects = list(dict.fromkeys(e for _, key in scenes for e in results["datasets"].get(key, {})))
    out = {"results": a.results, "weights": results["weights"], "floor_px": floor, "effects": {}}
    for effect in effects:
        res = compare_effect(scenes, results, effect, floor)
        if res is not None:
            out["effects"][effect] = res
            print(f"{effect} done", file=sys.stderr, flush=True)
    if a.out:
        write_json_atomic(a.out, out)
    print(table(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
