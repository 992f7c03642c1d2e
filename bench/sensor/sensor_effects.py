"""Real colour cameras, side by side: the same frames through each sensor / ISP effect, then the
shipped detector, the centre refinement and the pinhole solver; pose and centre errors per effect.

    python -m bench.sensor.sensor_effects DATASET [DATASET ...] --out RESULTS.json
                                   [--effects NAME,NAME] [--frames N] [--weights W.pt]
                                   [--tell-cfa] [--tell-jpeg]
    python -m bench.sensor.sensor_effects --compare RESULTS.json [RESULTS.json ...]
    python -m bench.sensor.sensor_effects DATASET [DATASET ...] --resolve ROWS.json --out RESULTS.json

Each DATASET must keep its linear renders (``[render] keep_exr = true``; the kept EXR is the
delivered geometry before the sensor): bench/configs/sensor_scene_a.toml and sensor_scene_b.toml
(two geometries, ideal pinhole lens, normal light, 48 test frames each). Every effect sends the
frame's linear image through ``core.camera_chain.expose_frame`` with the frame's own exposure,
vignetting and noise seed (its label's sensor record) and the effect's colour chain, so the
effects differ only in the camera. Geometry never changes: the errors are measured against the
labels. The reference ("three-chip") is a three-chip sensor with the same EMVA 1288 preset, PNG
output. Per effect and dataset: frames solved, X / Y / alpha RMSE, their ratio to the reference
with its paired bootstrap interval (95 %, the frames resampled together), RMS z (error / reported
std) with its bootstrap interval, and the centre error of the detected markers against the labels'
outline centroids (median length, mean dx / dy per class). ``sampling-rggb`` is the three-chip
image refined (with ``--tell-cfa``) as if it came from an RGGB sensor: what the sampling alone costs.

Results land in RESULTS.json after each (dataset, effect) pair (resumable: finished pairs are
skipped), and a markdown table is printed at the end. ``--resolve ROWS.json`` solves the rows of a
results file written with them again by the solver as it is now, from their kept detections (no
detector, no EXR read): the bench's figures after a change of the solver.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np

from dockfactory.core.camera_chain import ColourChain, expose_frame, jpeg_round_trip
from dockfactory.core.camera_chain.colour_sensor import configured_sensor, white_dn
from dockfactory.core.camera_chain.isp import develop_raw
from dockfactory.core.io import write_json_atomic
from dockfactory.core.resources import shipped_weights
from dockfactory.core.scene import SensorParams, from_dict
from dockfactory.eval.confidence import bootstrap_bounds
from dockfactory.eval.pose_metrics import pose_error
from dockfactory.eval.solve_frames import detection_arrays, docking_options, lens_prior_for, solve_frame
from dockfactory.eval.uncertainty import reported_std
from dockfactory.generator.datasets.reader import Dataset
from dockfactory.generator.exr import read_passes

PRESET = "imx273"
UNIT_SEED = 26
COMPONENTS = ("x", "y", "alpha")
INTERVAL_CONFIDENCE = 0.975   # each end of an interval: two-sided 95 %
INTERVAL_SEED = 0


def chain(cfa="none", demosaic="bilinear", wb=(0.0, 0.0), **kw) -> ColourChain:
    """The bench camera: preset PRESET at 12 bits, 10 ms, exact colour correction, sRGB."""
    base = dict(cfa=cfa, sensor=configured_sensor(PRESET, (), 12), unit_seed=UNIT_SEED, crosstalk=0.02,
                exposure_s=0.01, demosaic=demosaic, wb_error=wb, colour_correction=True, tone="srgb",
                denoise="off", sharpen_amount=0.0, sharpen_sigma_px=1.0)
    return ColourChain(**{**base, **kw})


def sensor_with_wells(name: str, wells: float):
    """Preset ``name`` at 12 bits with ``wells`` times its saturation capacity and 1 / ``wells`` its
    gain (the same DN at the same exposure-normalised light; shot variance relative to the signal
    divided by ``wells``, dark noise in electrons kept): the sensor's temporal noise turned down
    without touching the render, the chain or the ISP."""
    base = configured_sensor(name, (), 12)
    return replace(base, saturation_e=base.saturation_e * wells, gain_dn_per_e=base.gain_dn_per_e / wells)


def wb_draw(index: int, limit: float) -> tuple[float, float]:
    """The frame's white-balance error of the red and blue gains: uniform in [-limit, limit]."""
    rng = np.random.default_rng([UNIT_SEED, 7, index])
    return tuple(float(v) for v in rng.uniform(-limit, limit, 2))


# name -> (chain builder (frame index -> ColourChain | None), optical blur sigma px, JPEG (q, subsampling))
EFFECTS = {
    "factory": (lambda i: None, 0.0, None),
    "three-chip": (lambda i: chain(), 0.0, None),
    "bayer-bilinear": (lambda i: chain("RGGB", "bilinear"), 0.0, None),
    "bayer-edge_aware": (lambda i: chain("RGGB", "edge_aware"), 0.0, None),
    "bayer-vng": (lambda i: chain("RGGB", "vng"), 0.0, None),
    "bayer-mhc": (lambda i: chain("RGGB", "mhc"), 0.0, None),
    "bayer-jpeg90": (lambda i: chain("RGGB", "bilinear"), 0.0, (90, "420")),
    "three-chip-jpeg90": (lambda i: chain(), 0.0, (90, "420")),
    "bayer-jpeg95": (lambda i: chain("RGGB", "bilinear"), 0.0, (95, "420")),
    "three-chip-jpeg95": (lambda i: chain(), 0.0, (95, "420")),
    "three-chip-jpeg70": (lambda i: chain(), 0.0, (70, "420")),
    "blur1.2": (lambda i: chain(), 1.2, None),
    "wb20": (lambda i: chain(wb=wb_draw(i, 0.2)), 0.0, None),
    "bayer-wb20": (lambda i: chain("RGGB", "bilinear", wb=wb_draw(i, 0.2)), 0.0, None),
    "bayer-sharpen": (lambda i: chain("RGGB", "bilinear", sharpen_amount=0.8), 0.0, None),
    "sampling-rggb": (lambda i: chain(), 0.0, None),
    "three-chip-imx174": (lambda i: chain(sensor=configured_sensor("imx174", (), 12)), 0.0, None),
    "bayer-imx174": (lambda i: chain("RGGB", "bilinear", sensor=configured_sensor("imx174", (), 12)), 0.0, None),
    "three-chip-imx174-jpeg90": (lambda i: chain(sensor=configured_sensor("imx174", (), 12)), 0.0, (90, "420")),
    "three-chip-wells100-jpeg90": (lambda i: chain(sensor=sensor_with_wells(PRESET, 100.0)), 0.0, (90, "420")),
    "three-chip-wells4": (lambda i: chain(sensor=sensor_with_wells(PRESET, 4.0)), 0.0, None),
    "three-chip-wells100": (lambda i: chain(sensor=sensor_with_wells(PRESET, 100.0)), 0.0, None),
    "bayer-wells100": (lambda i: chain("RGGB", "bilinear", sensor=sensor_with_wells(PRESET, 100.0)), 0.0, None),
    "bayer-raw": (lambda i: chain("RGGB", "vng"), 0.0, None),
}
# Effects whose camera writes its raw mosaic (a 16-bit one-channel frame in DN): the image is what
# ``measure --cfa RGGB --raw-black --raw-white`` develops from it (dockfactory.measure.read), with
# this demosaic; the camera's own ISP (colour correction, tone) never touches the samples.
RAW_DEMOSAIC = {"bayer-raw": "vng"}
# Effects whose image is a three-chip camera's but whose refinement (with --tell-cfa) is told a
# Bayer pattern: it then fits only the values an RGGB sensor would have sampled, with no demosaic and
# the same noise per sample, so the row measures what the 1-in-4 sampling alone costs.
SAMPLED_AS = {"sampling-rggb": "RGGB"}


def delivered(passes_rgb: np.ndarray, label: dict, effect: str) -> np.ndarray:
    """The frame as the effect's camera delivers it: (H, W, 3) uint8 RGB."""
    build, blur, jpeg = EFFECTS[effect]
    params = from_dict(SensorParams, {k: v for k, v in label["sampled"]["sensor"].items() if k != "chain"})
    params = replace(params, chain=build(label["spec"]["index"]))
    linear = passes_rgb
    if blur > 0:
        linear = cv2.GaussianBlur(np.ascontiguousarray(linear, dtype=np.float32), (0, 0), blur)
    image, raw, _ = expose_frame(linear, params)
    if effect in RAW_DEMOSAIC:
        sensor = params.chain.sensor
        return develop_raw(raw, params.chain.cfa, sensor.black_level_dn, white_dn(sensor), RAW_DEMOSAIC[effect])
    return jpeg_round_trip(image, *jpeg) if jpeg else image


def matched_centres(dets: list[dict], label: dict) -> list[tuple[dict, np.ndarray, np.ndarray]]:
    """(marker label, outline centroid (2,), refined centre (2,)) px of each fully visible, legible
    marker and the detection of its class nearest to it (within its box)."""
    out = []
    for m in label["markers"]:
        if m.get("visibility") != 2 or not m.get("legible", True):
            continue
        truth = np.array(m.get("outline_centroid_px") or m["center_px"])
        x0, y0, x1, y1 = m["bbox_px"]
        near = [d for d in dets if d["class_id"] == m["class_id"] and x0 <= d["center_px"][0] <= x1
                and y0 <= d["center_px"][1] <= y1]
        if near:
            c = min(near, key=lambda d: np.hypot(*(np.array(d["center_px"]) - truth)))["center_px"]
            out.append((m, truth, np.array(c, dtype=float)))
    return out


def centre_errors(dets: list[dict], label: dict) -> list[tuple[int, float, float]]:
    """(class, dx, dy) px of each :func:`matched_centres` marker: refined centre minus the label's
    outline centroid."""
    return [(m["class_id"], float(c[0] - t[0]), float(c[1] - t[1])) for m, t, c in matched_centres(dets, label)]


DET_KEYS = ("class_id", "center_px", "bbox_px", "score", "refined")   # what a re-solve needs


def measure_frame(detector, ds: Dataset, fid: str, image: np.ndarray, cfa: str | None, jpeg: bool) -> dict:
    """Detect, refine (told the camera's Bayer pattern ``cfa`` and whether it wrote a JPEG), solve
    one delivered image; errors against its label, the detections (``dets``) and the markers the
    fit used (``used``), so that the frame can be solved again (bench/sensor/sensor_shift.py)."""
    h, w = image.shape[:2]
    dets = [{k: d[k] for k in DET_KEYS if k in d} for d in detector.detect(image, cfa=cfa, jpeg=jpeg)]
    return solved_row(ds, fid, dets, (w, h), detector.centre_noise_px)


def solved_row(ds: Dataset, fid: str, dets: list[dict], size, noise_px: float | None) -> dict:
    """The bench's row of frame ``fid`` of ``ds`` from its detections ``dets`` in an image of
    ``size`` (w, h) px: solved as the bench solves (pinhole, principal point at the centre, the
    card's noise ``noise_px``), errors against the label."""
    label = ds.labels[fid]
    w, h = size
    rec = solve_frame(ds.markers(), ((w - 1) / 2.0, (h - 1) / 2.0), detection_arrays(dets, 0.25), None,
                      "pinhole", docking_options(noise_px, lens_prior_for(ds.config)))[0]
    row = {"frame": fid, "ok": rec["ok"], "centres": centre_errors(dets, label), "dets": dets,
           "used": rec.get("marker_ids")}
    if rec["ok"]:
        row.update(pose_errors(rec, label))
    return row


def resolved(rows_path: str, roots: list[str], noise_px: float | None) -> dict:
    """A results file of this bench whose every row (``rows_path``: written with its rows) is
    solved again from its kept detections by the solver as it is now (no detector: after a change
    of the solver, its figures without a render); each dataset of the file must be among ``roots``
    (DockfactoryError naming it)."""
    from dockfactory.core.errors import DockfactoryError
    results = json.loads(Path(rows_path).read_text())
    opened = {f"{d.config.dataset.name}@{d.version_id}": d for d in (Dataset.open(r, full=False) for r in roots)}
    for key, effects in results["datasets"].items():
        if key not in opened:
            raise DockfactoryError(f"{rows_path}: dataset {key} is not among the DATASET arguments")
        ds = opened[key]
        size = (ds.config.image.width, ds.config.image.height)
        for effect, res in effects.items():
            if "rows" not in res:
                raise DockfactoryError(f"{rows_path}: {key} {effect} was written without its rows")
            rows = [solved_row(ds, r["frame"], r["dets"], size, noise_px) for r in res["rows"]]
            effects[effect] = {**summary(rows), "seconds": res.get("seconds"), "rows": rows}
        add_intervals(effects)
    return results


def pose_errors(rec: dict, label: dict) -> dict:
    """{"err_<c>", "z_<c>"} of a solved record against its label."""
    err = pose_error(rec["pose"], label["pose_b_in_d"])
    std = reported_std(rec["covariance"])
    return {**{f"err_{c}": err[c] for c in COMPONENTS},
            **{f"z_{c}": (err[c] / std[c] if std.get(c) else None) for c in COMPONENTS}}


def rms_z_bootstrap_interval(z: np.ndarray) -> list[float] | None:
    """[low, high]: bootstrap interval (95 %, two-sided, frames resampled) of the RMS of ``z``
    (error / reported std per frame); None under 5 values. Over 48 Gaussian frames it spans about
    0.80-1.20 around a true 1, the width of the issue's band itself."""
    z2 = np.asarray(z, dtype=float) ** 2
    bounds = bootstrap_bounds(lambda idx: float(np.sqrt(z2[idx].mean())), z2.size, INTERVAL_CONFIDENCE,
                              INTERVAL_SEED)
    return None if bounds is None else [round(bounds[0], 3), round(bounds[1], 3)]


def summary(rows: list[dict]) -> dict:
    """RMSE and RMS z per component, centre error figures per class."""
    ok = [r for r in rows if r["ok"]]
    out = {"frames": len(rows), "solved": len(ok)}
    for c in COMPONENTS:
        e = np.array([r[f"err_{c}"] for r in ok])
        z = np.array([r[f"z_{c}"] for r in ok if r[f"z_{c}"] is not None])
        out[f"rmse_{c}"] = float(np.sqrt(np.mean(e ** 2))) if e.size else None
        out[f"rms_z_{c}"] = float(np.sqrt(np.mean(z ** 2))) if z.size else None
        out[f"rms_z_interval_{c}"] = rms_z_bootstrap_interval(z)
    cen = np.array([c for r in rows for c in r["centres"]]).reshape(-1, 3)
    out["centre_median_px"] = float(np.median(np.hypot(cen[:, 1], cen[:, 2]))) if len(cen) else None
    out["centre_rms_px"] = float(np.sqrt(np.mean(cen[:, 1] ** 2 + cen[:, 2] ** 2))) if len(cen) else None
    for cls, name in ((0, "A"), (1, "B")):
        k = cen[cen[:, 0] == cls]
        out[f"centre_mean_{name}"] = [float(k[:, 1].mean()), float(k[:, 2].mean())] if len(k) else None
        out[f"markers_{name}"] = int(len(k))
    return out


def run_effect(detector, ds: Dataset, effect: str, frames: list[str], tell_cfa: bool, tell_jpeg: bool) -> dict:
    t0 = time.perf_counter()
    rows = []
    jpeg = tell_jpeg and EFFECTS[effect][2] is not None
    for fid in frames:
        passes = read_passes(ds.root / "exr" / f"{fid}.exr")
        cam = EFFECTS[effect][0](ds.labels[fid]["spec"]["index"])
        cfa = cam.cfa if tell_cfa and cam is not None and cam.cfa != "none" else None
        cfa = SAMPLED_AS.get(effect, cfa) if tell_cfa else cfa
        rows.append(measure_frame(detector, ds, fid, delivered(passes.rgb, ds.labels[fid], effect), cfa, jpeg))
    return {**summary(rows), "seconds": round(time.perf_counter() - t0, 1), "rows": rows}


def ratio_interval(rows: list[dict], ref_rows: list[dict], component: str) -> list[float] | None:
    """[low, high]: the paired bootstrap interval (95 %, two-sided) of RMSE(rows) / RMSE(ref_rows)
    of ``component`` over the frames solved in both, resampled together (the same frame through
    both cameras); None under 5 such frames. Why: over 48 frames one weakly determined frame can
    carry most of an RMSE, so a ratio alone can say more than the frames do."""
    ref = {r["frame"]: r for r in ref_rows if r["ok"]}
    pairs = [(r[f"err_{component}"], ref[r["frame"]][f"err_{component}"]) for r in rows
             if r["ok"] and r["frame"] in ref]
    e = np.array(pairs, dtype=float).reshape(-1, 2) ** 2
    if not e.size or not e[:, 1].sum() > 0:
        return None

    def ratio(idx: np.ndarray) -> float:
        return float(np.sqrt(e[idx, 0].sum() / max(e[idx, 1].sum(), 1e-300)))
    bounds = bootstrap_bounds(ratio, len(e), INTERVAL_CONFIDENCE, INTERVAL_SEED)
    return None if bounds is None else [round(bounds[0], 3), round(bounds[1], 3)]


def add_intervals(effects: dict) -> None:
    """Give each effect of one dataset that still holds its rows its ``ratio_interval_<c>`` to
    the three-chip reference (kept when the rows are stripped)."""
    ref = effects.get("three-chip")
    if not ref or "rows" not in ref:
        return
    for s in effects.values():
        if "rows" in s:
            s.update({f"ratio_interval_{c}": ratio_interval(s["rows"], ref["rows"], c) for c in COMPONENTS})
            s.update({f"rms_z_interval_{c}": rms_z_bootstrap_interval(
                [r[f"z_{c}"] for r in s["rows"] if r["ok"] and r[f"z_{c}"] is not None]) for c in COMPONENTS})


def _ratio_cell(s: dict, ref: dict | None, c: str) -> str:
    """'v (ratio [low-high])' of one component."""
    v = s[f"rmse_{c}"]
    if v is None:
        return "-"
    if not ref:
        return f"{v:.3f}"
    ci = s.get(f"ratio_interval_{c}")
    span = f" [{ci[0]:.2f}-{ci[1]:.2f}]" if ci else ""
    return f"{v:.3f} ({v / ref[f'rmse_{c}']:.2f}{span})"


def _z_cell(s: dict, c: str) -> str:
    """'RMS z [low-high]' of one component."""
    v, ci = s[f"rms_z_{c}"], s.get(f"rms_z_interval_{c}")
    if v is None:
        return "-"
    return f"{v:.2f} [{ci[0]:.2f}-{ci[1]:.2f}]" if ci else f"{v:.2f}"


def table(results: dict) -> str:
    """Markdown: per dataset and effect, RMSE (ratio to three-chip) and RMS z."""
    lines = ["| dataset | effect | solved | X mm (x [95 %]) | Y mm (x [95 %]) | alpha deg (x [95 %]) | RMS z X / Y / alpha [95 %] | "
             "centre median px | mean A / B px |", "| --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for ds_name, effects in results["datasets"].items():
        ref = effects.get("three-chip")
        for name, s in effects.items():
            cells = [_ratio_cell(s, ref, c) for c in COMPONENTS]
            z = " / ".join(_z_cell(s, c) for c in COMPONENTS)
            mean = " / ".join(f"({m[0]:+.3f}, {m[1]:+.3f})" if m else "-"
                              for m in (s["centre_mean_A"], s["centre_mean_B"]))
            lines.append(f"| {ds_name} | {name} | {s['solved']}/{s['frames']} | {' | '.join(cells)} | {z} | "
                         f"{s['centre_median_px']:.3f} | {mean} |")
    return "\n".join(lines)


TARGETS = {"bayer-bilinear": 1.5, "bayer-edge_aware": 1.5, "bayer-vng": 1.5, "bayer-mhc": 1.5, "bayer-jpeg90": 1.5,
           "blur1.2": 1.5, "wb20": 1.2}


def compare(paths: list[str]) -> str:
    """Markdown: per scene and effect, X / Y / alpha RMSE over the three-chip reference of the same
    run, in each results file side by side (e.g. the refinement before and after), and RMS z."""
    runs = [(Path(p).stem, json.loads(Path(p).read_text())) for p in paths]
    lines = ["| scene | effect | target | " + " | ".join(f"{n}: X / Y / alpha (x three-chip) | {n}: RMS z X / Y / alpha"
                                                   for n, _ in runs) + " |",
             "| --- | --- | --- | " + " | ".join("--- | ---" for _ in runs) + " |"]
    scenes = list(runs[0][1]["datasets"])
    for scene in scenes:
        for effect in EFFECTS:
            cells = []
            for _, res in runs:
                eff = res["datasets"].get(scene, {})
                s, ref = eff.get(effect), eff.get("three-chip")
                if s is None or ref is None:
                    cells.append("- | -")
                    continue
                ratio = " / ".join(f"{s[f'rmse_{c}'] / ref[f'rmse_{c}']:.2f}" for c in COMPONENTS)
                z = " / ".join(f"{s[f'rms_z_{c}']:.2f}" for c in COMPONENTS)
                cells.append(f"{s['rmse_x']:.3f} / {s['rmse_y']:.3f} / {s['rmse_alpha']:.4f} ({ratio}) | {z}")
            if any(c != "- | -" for c in cells):
                target = f"<= {TARGETS[effect]}x" if effect in TARGETS else ""
                lines.append(f"| {scene} | {effect} | {target} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _paired_rows(runs: list[dict], scenes: list[str], effect: str) -> tuple[list[dict], list[dict]]:
    """The rows of ``effect`` in both runs over ``scenes``, frame names made unique per scene."""
    out = []
    for res in runs:
        rows = []
        for scene in scenes:
            s = res["datasets"].get(scene, {}).get(effect) or {}
            rows += [{**r, "frame": f"{scene}/{r['frame']}"} for r in s.get("rows", [])]
        out.append(rows)
    return out[0], out[1]


def paired(paths: list[str]) -> str:
    """Markdown: per effect, per scene and over all scenes, RMSE of the second results file over
    the first's on the same frames (e.g. new weights over shipped ones), X / Y / alpha, each with its
    paired bootstrap interval. Needs the files' rows."""
    runs = [json.loads(Path(p).read_text()) for p in paths]
    scenes = [k for k in runs[0]["datasets"] if k in runs[1]["datasets"]]
    lines = [f"| effect | scenes | {Path(paths[1]).stem} / {Path(paths[0]).stem}: X | Y | alpha |",
             "| --- | --- | --- | --- | --- |"]
    for effect in EFFECTS:
        for group in [[sc] for sc in scenes] + ([scenes] if len(scenes) > 1 else []):
            new, old = _paired_rows(runs[::-1], group, effect)
            if not new or not old:
                continue
            cells, ref = [], {r["frame"]: r for r in old if r["ok"]}
            for c in COMPONENTS:
                num = [r[f"err_{c}"] ** 2 for r in new if r["ok"] and r["frame"] in ref]
                den = [ref[r["frame"]][f"err_{c}"] ** 2 for r in new if r["ok"] and r["frame"] in ref]
                ci = ratio_interval(new, old, c)
                span = f" [{ci[0]:.2f}-{ci[1]:.2f}]" if ci else ""
                cells.append(f"{np.sqrt(sum(num) / sum(den)):.2f}{span}" if sum(den) > 0 else "-")
            lines.append(f"| {effect} | {'all' if len(group) > 1 else group[0]} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("datasets", nargs="+", help="datasets (or, with --compare, results files)")
    p.add_argument("--compare", action="store_true", help="print the results files side by side")
    p.add_argument("--paired", action="store_true",
                   help="two results files with their rows: the second's RMSE over the first's, with intervals")
    p.add_argument("--out")
    p.add_argument("--effects", default=",".join(EFFECTS))
    p.add_argument("--frames", type=int, default=0, help="first N test frames only (0: all)")
    p.add_argument("--weights", default=None)
    p.add_argument("--tell-cfa", action="store_true", help="give the refinement the camera's Bayer pattern")
    p.add_argument("--tell-jpeg", action="store_true", help="tell the refinement which images were JPEG-encoded")
    p.add_argument("--resolve", metavar="ROWS.json",
                   help="solve the rows of this results file again (no detector) into --out; DATASETS: its datasets")
    args = p.parse_args(argv)
    if args.resolve:
        if not args.out:
            p.error("--out is required")
        from dockfactory.detector.noise_card import card_figures
        results = resolved(args.resolve, args.datasets, card_figures(args.weights or shipped_weights()).centre_noise_px)
        write_json_atomic(Path(args.out), results)
        print(table(results))
        return 0
    if args.compare:
        print(compare(args.datasets))
        return 0
    if args.paired:
        if len(args.datasets) != 2:
            p.error("--paired takes exactly two results files")
        print(paired(args.datasets))
        return 0
    if not args.out:
        p.error("--out is required")
    out = Path(args.out)
    results = json.loads(out.read_text()) if out.is_file() else {"datasets": {}}
    for flag in ("tell_cfa", "tell_jpeg"):   # rows already in the file were measured with its flags
        if results.get(flag, getattr(args, flag)) != getattr(args, flag):
            p.error(f"{out}: its rows were measured with {flag} = {results[flag]}; resume with the same "
                    f"flags or write another --out")
    import torch
    torch.set_num_threads(2)
    from dockfactory.detector.infer import MarkerDetector
    detector = MarkerDetector(args.weights or shipped_weights())
    results.update(weights=str(args.weights or shipped_weights()), preset=PRESET, tell_cfa=args.tell_cfa,
                   tell_jpeg=args.tell_jpeg)
    for root in args.datasets:
        ds = Dataset.open(root, full=False)
        frames = ds.frames("test")[: args.frames or None]
        key = f"{ds.config.dataset.name}@{ds.version_id}"
        for effect in args.effects.split(","):
            if effect in results["datasets"].get(key, {}):
                continue
            res = run_effect(detector, ds, effect, frames, args.tell_cfa, args.tell_jpeg)
            results["datasets"].setdefault(key, {})[effect] = res
            add_intervals(results["datasets"][key])
            write_json_atomic(out, results)
            print(f"{key} {effect}: X {res['rmse_x']:.3f} Y {res['rmse_y']:.3f} alpha {res['rmse_alpha']:.4f} "
                  f"({res['seconds']} s)", file=sys.stderr, flush=True)
    print(table(results))
    return 0


if __name__ == "__main__":
    sys.exit(main())
