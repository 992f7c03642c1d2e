"""The disc noise law's measurement: how a refined centre's error grows as its disc's image thins,
per camera, and whether the poses' reported std follows their errors under the shipped law
(``solver.disc_noise.noise_shapes``: variance (R0 / b)^p + floor, b the minor semi-axis).

    python -m bench.sensor.disc_noise_law ROWS.json DATASET [DATASET ...] [--poses] [--law P,FLOOR] [--json OUT]

ROWS.json is a ``bench.sensor.sensor_effects`` output with its rows (the detections of every
delivered frame per effect); each DATASET one of the sensor scenes it was run on (their labels).
No detector runs here: the rows' detections are matched to the labels (fully visible, legible
markers; the nearest detection of the class inside the marker's box) and each error is taken
about its section's mean in that frame (the section offset, a separate term of the model:
eval.section_shift), times sqrt(n / (n - 1)). Centres over 1 px off are left out of the law's fit
(gross errors: the robust refit's business).

Printed: per input (scene, effect) and bin of b, the markers, the mean squared error per axis
(px^2) over the input's scale and the law's mean there; the (p, floor) of largest Gaussian
likelihood per input and pooled over all (grid ``GRID_P`` x ``GRID_FLOOR``, each input's scale
free, errors isotropic). With ``--poses``: every row's frame solved as ``measure`` solves an
image of its camera class (eval.camera_classes: factor and section shift, the shipped card) under
the shipped law, per input the frames solved / refused, RMS z and RMSE of X, Y, Z, alpha.
"""
from __future__ import annotations

import argparse
import json
from collections import defaultdict

import numpy as np

from dockfactory.solver.disc_noise import MINOR_EXPONENT, NOISE_FLOOR, REFERENCE_RADIUS_PX

BINS = (0.0, 3.0, 4.0, 5.0, 6.0, 8.0, 10.0, 14.0, 20.0, np.inf)
GRID_P = np.arange(1.0, 4.01, 0.25)
GRID_FLOOR = np.array([0.0, 0.1, 0.25, 0.5, 1.0, 1.5, 2.0, 3.0, 5.0])
GROSS_PX = 1.0
AXES = ("x_mm", "y_mm", "z_mm", "alpha_deg")


def frame_markers(row: dict, label: dict) -> list[dict]:
    """{section, minor (px), ex, ey (px)} of each matched marker of one sensor-bench row."""
    from bench.sensor.centre_bound import disc_geometry
    marks = [m for m in label["markers"] if m.get("visibility") == 2 and m.get("legible", True)]
    if not marks:
        return []
    out = []
    for m, s in zip(marks, disc_geometry(label, marks)):
        truth = np.array(m.get("outline_centroid_px") or m["center_px"])
        x0, y0, x1, y1 = m["bbox_px"]
        near = [d for d in row["dets"] if d["class_id"] == m["class_id"]
                and x0 <= d["center_px"][0] <= x1 and y0 <= d["center_px"][1] <= y1]
        if near:
            d = min(near, key=lambda d: np.hypot(*(np.array(d["center_px"]) - truth)))
            e = np.array(d["center_px"]) - truth
            out.append({"section": m["section"], "minor": float(np.sqrt(max(np.linalg.eigvalsh(s)[0], 0.0))),
                        "ex": float(e[0]), "ey": float(e[1])})
    return out


def about_section_means(markers: list[dict]) -> np.ndarray:
    """(n, 3) rows (minor px, ex, ey) with each error taken about its section's mean in the frame
    (sections of at least 3 markers; the rest dropped), times sqrt(n / (n - 1))."""
    rows = []
    for sec in ("A", "B"):
        ms = [m for m in markers if m["section"] == sec]
        if len(ms) < 3:
            continue
        e = np.array([[m["ex"], m["ey"]] for m in ms])
        e = (e - e.mean(0)) * np.sqrt(len(ms) / (len(ms) - 1))
        rows += [(m["minor"], *ee) for m, ee in zip(ms, e)]
    return np.array(rows, dtype=float).reshape(-1, 3)


def law_variance(minor, p: float, floor: float) -> np.ndarray:
    """The law's relative variance per axis of discs of minor semi-axis ``minor`` px."""
    return ((REFERENCE_RADIUS_PX / np.asarray(minor, dtype=float)) ** p + floor) / (1.0 + floor)


def nll(data: list[np.ndarray], p: float, floor: float) -> float:
    """Mean negative Gaussian log-likelihood (per axis, constants dropped) of the inputs ``data``
    (each (n, 3) of :func:`about_section_means`) under the law, each input's scale at its maximum."""
    total, count = 0.0, 0
    for d in data:
        v = law_variance(d[:, 0], p, floor)
        e2 = np.concatenate([d[:, 1] ** 2 / v, d[:, 2] ** 2 / v])
        k = e2.mean()
        total += float(np.sum(np.log(k * np.r_[v, v])) + e2.sum() / k)
        count += e2.size
    return total / max(count, 1)


def best_law(data: list[np.ndarray]) -> tuple[float, float]:
    """(p, floor) on the grid of largest likelihood over the inputs ``data``."""
    cells = [(nll(data, p, f), float(p), float(f)) for p in GRID_P for f in GRID_FLOOR]
    return min(cells)[1:]


def bin_rows(name: str, d: np.ndarray) -> list[str]:
    """Markdown rows: per bin of b (10 markers or more), markers, measured mean square per axis
    over the input's scale (mean of e^2 / law at the shipped constants), and the law's mean."""
    v = law_variance(d[:, 0], MINOR_EXPONENT, NOISE_FLOOR)
    scale = np.mean(np.r_[d[:, 1] ** 2, d[:, 2] ** 2] / np.r_[v, v])
    out = []
    for lo, hi in zip(BINS[:-1], BINS[1:]):
        k = (d[:, 0] >= lo) & (d[:, 0] < hi)
        if k.sum() >= 10:
            measured = np.mean(np.r_[d[k, 1] ** 2, d[k, 2] ** 2]) / scale
            out.append(f"| {name} | {lo:g}-{hi:g} | {int(k.sum())} | {measured:.2f} | {v[k].mean():.2f} |")
    return out


def input_poses(ds, effect: str, rows: list[dict], card) -> dict:
    """Frames solved / refused, RMS z, RMSE (AXES order) and frames beyond 3 reported std in X, Y or
    Z of the rows of one input, each frame solved as measure solves an image of the effect's camera
    class (the shipped card's floor, section shift and noise prior, each the class's)."""
    from bench.verdict.gate_classes import effect_class
    from dockfactory.eval.camera_classes import CAMERA_CLASS_FACTORS, class_section_shift
    from dockfactory.eval.solve_frames import detection_arrays, docking_options, lens_prior_for, solve_frame
    cls = effect_class(effect)
    prior = None if card.core_px is None else card.core_px * CAMERA_CLASS_FACTORS[cls]
    options = docking_options(card.centre_noise_px, lens_prior_for(ds.config),
                              class_section_shift(cls, card.section_shift_px), prior)
    pp = ((ds.config.image.width - 1) / 2.0, (ds.config.image.height - 1) / 2.0)
    errs, zs, refused = [], [], 0
    for row in rows:
        arr = detection_arrays(row["dets"], 0.25)
        if len(arr[0]) == 0:
            refused += 1
            continue
        rec = solve_frame(ds.markers(), pp, arr, None, "pinhole", options, CAMERA_CLASS_FACTORS[cls])[0]
        if not rec["ok"]:
            refused += 1
            continue
        truth = ds.labels[row["frame"]]["pose_b_in_d"]
        e = np.array([rec["pose"][k] - truth[k] for k in AXES])
        errs.append(e)
        zs.append(e / np.sqrt(np.diag(np.array(rec["covariance"]))[[0, 1, 2, 3]]))
    rms = (lambda a: np.sqrt(np.mean(np.square(a), axis=0)).tolist() if len(a) else None)
    beyond = int(np.sum(np.any(np.abs(np.array(zs).reshape(-1, 4)[:, :3]) > 3, axis=1)))
    return {"solved": len(errs), "refused": refused, "rms_z": rms(zs), "rmse": rms(errs), "beyond_3": beyond}


def pose_line(name: str, r: dict) -> str:
    """A markdown row of :func:`input_poses`' result."""
    if r["rms_z"] is None:
        return f"| {name} | 0 / {r['refused']} | | | |"
    z = " / ".join(f"{v:.2f}" for v in r["rms_z"])
    e = " / ".join(f"{v:.4f}" for v in r["rmse"])
    return f"| {name} | {r['solved']} / {r['refused']} | {z} | {e} | {r['beyond_3']} |"


def inputs(rows_path: str, roots: list[str]):
    """[(name, dataset, effect, rows)] of every (scene, effect) of ROWS.json with rows; a dataset
    of ROWS.json not among ``roots`` is an error naming it."""
    from dockfactory.core.errors import DockfactoryError
    from dockfactory.generator.datasets.reader import Dataset
    res = json.loads(open(rows_path).read())["datasets"]
    opened = {f"{d.config.dataset.name}@{d.version_id}": d for d in (Dataset.open(r, full=False) for r in roots)}
    out = []
    for key, effects in res.items():
        if key not in opened:
            raise DockfactoryError(f"{rows_path}: dataset {key} is not among the DATASET arguments")
        out += [(f"{key.split('@')[0]} {eff}", opened[key], eff, r["rows"]) for eff, r in effects.items() if "rows" in r]
    return out


def law_data(items) -> dict:
    """{name: (n, 3) rows of :func:`about_section_means`} of every input, gross errors left out."""
    data = defaultdict(list)
    for name, ds, _, rows in items:
        for row in rows:
            data[name].append(about_section_means(frame_markers(row, ds.labels[row["frame"]])))
    out = {}
    for name, parts in data.items():
        d = np.concatenate(parts)
        out[name] = d[np.hypot(d[:, 1], d[:, 2]) < GROSS_PX]
    return out


def use_law(text: str | None) -> tuple[float, float]:
    """(p, floor) the poses are solved under: the shipped law, or ``text`` "P,FLOOR" set in
    solver.disc_noise for this process (the table's law column stays the shipped one)."""
    if text is None:
        return MINOR_EXPONENT, NOISE_FLOOR
    import dockfactory.solver.disc_noise as disc_noise
    disc_noise.MINOR_EXPONENT, disc_noise.NOISE_FLOOR = (float(v) for v in text.split(","))
    return disc_noise.MINOR_EXPONENT, disc_noise.NOISE_FLOOR


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("rows")
    ap.add_argument("datasets", nargs="+")
    ap.add_argument("--poses", action="store_true", help="solve every row's frame under the shipped law")
    ap.add_argument("--json", default=None, help="write the figures to this file")
    ap.add_argument("--law", default=None, metavar="P,FLOOR",
                    help="solve the poses under this law instead of the shipped one (a law tried, not shipped)")
    args = ap.parse_args(argv)
    law = use_law(args.law)
    items = inputs(args.rows, args.datasets)
    data = law_data(items)
    lines = ["| input | b px | markers | measured | law |", "| --- | --- | --- | --- | --- |"]
    fits = {}
    for name, d in data.items():
        fits[name] = best_law([d])
        lines += bin_rows(name, d) + [f"| {name} | best p {fits[name][0]:.2f}, floor {fits[name][1]:.2f} | {len(d)} | | |"]
    pooled = best_law(list(data.values()))
    print(f"shipped law: p {MINOR_EXPONENT}, floor {NOISE_FLOOR}; poses under p {law[0]}, floor {law[1]}; "
          f"pooled best: p {pooled[0]:.2f}, floor {pooled[1]:.2f}\n")
    print("\n".join(lines))
    out = {"shipped": [MINOR_EXPONENT, NOISE_FLOOR], "poses_law": list(law), "pooled": pooled, "per_input": fits}
    if args.poses:
        from dockfactory.core.resources import shipped_weights
        from dockfactory.detector.noise_card import card_figures
        card = card_figures(shipped_weights())
        out["poses"] = {name: input_poses(ds, eff, rows, card) for name, ds, eff, rows in items}
        print("\n| input | solved / refused | RMS z X / Y / Z / alpha | RMSE X / Y / Z mm, alpha deg | beyond 3 std |")
        print("| --- | --- | --- | --- | --- |")
        print("\n".join(pose_line(n, r) for n, r in out["poses"].items()))
    if args.json:
        from dockfactory.core.io import write_json_atomic
        write_json_atomic(args.json, out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
