"""Speed and accuracy of the stream path of ``measure`` (--video) beside today's ``measure`` on the
PNG files of the same frames, in one run (issue 31 targets: >= 15 frames/s end to end from a
1280x960 video and from PNG files with overlays off, latency p95 <= 150 ms from a frame's read to
its JSON line written, X / Y / alpha RMSE within 1.05x of today's measure).

    python -m bench.cli.stream_speed DATASET [--run K] [--frames N] [--threads 1] [--json OUT.json]

DATASET: a complete dataset with docking runs (e.g. out/realistic/dataset; only read). The first N
frames of its K-th docking run are written as videos into a temporary folder (mp4v MP4 as
``dataset export --format video`` writes them, and FFV1), then measured by each variant in turn,
every variant on the same frames with the same shipped weights and ``--threads`` torch / ONNX
threads:
  png-measure        today's ``measure`` on the PNGs (one worker, overlays off); its latency is the
                     time between consecutive per-image records (written as each image finishes)
  png-stream         the stream path on the PNGs (VideoCapture of the image-sequence pattern)
  mp4                the stream path on the MP4 (the reference stream variant)
  mp4-no-prefetch    ... without the reader thread (no overlap of decoding and measuring)
  mp4-torch          ... with the network on torch instead of ONNX Runtime
  mp4-scale-0.375    ... with a smaller network input (0.375 network px per image px, not 0.5)
  mp4-roi-10         ... detecting in a window around the previous frame's markers (--roi 10)
  mp4-roi-10-0.375   ... both
  png-stream-roi-10  the stream path on the PNGs with the window
  mkv-ffv1           the stream path on the lossless video
  *-2-workers        ... with two worker processes measuring alternate frames (--workers 2; the
                     workers start before the clock does, as the detector loads before it);
                     *-no-prefetch without the reader thread (measure's default with workers)
Prints one row per variant: CPU ms per frame (this process, every thread: what the load of a
shared machine changes least; with workers the parent's only: reading, filtering, writing), frames/s (after the detector is loaded), latency p50 / p95, median
read / detect / solve ms, X, Y, alpha RMSE against the labels (frames with a pose in every
variant) and its ratio to png-measure's; then one frame's steps alone, each the best of 11 runs
(decoding a PNG and an MP4 frame, the network at each scale and runtime and on the --roi window,
detection with refinement, detect + solve): what each means buys when the machine lets it run;
the load average before and after (a shared machine
makes absolute figures noisy: compare the rows, which ran minutes apart at most).
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import tempfile
import time
from pathlib import Path

import dockfactory

dockfactory.set_app_environment(os.environ)   # as the dockfactory command runs, before numpy loads

import numpy as np  # noqa: E402

TARGETS = {"frames_per_s": 15.0, "latency_p95_ms": 150.0, "rmse_ratio": 1.05}
GATED = ("x_mm", "y_mm", "alpha_deg")


def _write_videos(ds, run: int, frames: int, folder: Path) -> tuple[list[str], dict[str, Path]]:
    from dockfactory.generator.exports.video import CODECS, video_runs, write_run_video
    runs = video_runs(ds)
    if not 0 <= run < len(runs):
        raise SystemExit(f"{ds.root}: run {run} does not exist ({len(runs)} runs)")
    ids = runs[run][:frames]
    paths = {}
    for fmt in ("video", "video_lossless"):
        fourcc, suffix, _ = CODECS[fmt]
        paths[fmt] = folder / f"run{suffix}"
        write_run_video(ds, ids, paths[fmt], fourcc)
    return ids, paths


def _png_sequence(ds, ids: list[str], folder: Path) -> str:
    """The PNGs of ``ids`` as an image-sequence pattern (hard links named 000000.png, ...)."""
    seq = folder / "seq"
    seq.mkdir()
    for k, fid in enumerate(ids):
        try:
            os.link(ds.image_path(fid), seq / f"{k:06d}.png")
        except OSError:
            (seq / f"{k:06d}.png").write_bytes(ds.image_path(fid).read_bytes())
    return str(seq / "%06d.png")


def _today(ds, ids, layout, weights, folder: Path) -> dict:
    """Today's measure on the PNGs (one worker, ONNX Runtime when installed, no overlays)."""
    from dockfactory.measure.images import MeasureOptions, measure
    out = folder / "measure"
    head = measure([ds.image_path(f) for f in ids], layout, weights, out,
                   options=MeasureOptions("auto", 1, None))
    recs = json.loads((out / "measurements.json").read_text())["images"]
    stamps = sorted(p.stat().st_mtime_ns for p in (out / "records").glob("*.json"))
    gaps = list(np.diff(stamps) / 1e6)
    timing = {k: float(np.median([r["timing_ms"][k] for r in recs if "timing_ms" in r])) for k in ("detect", "solve")}
    return {"frames_per_s": head["frames_per_s"], "latency_ms": {"p50": _pct(gaps, 50), "p95": _pct(gaps, 95)},
            "timing_ms_median": timing, "poses": [r.get("pose") for r in recs], "backend": head["backend"]}


def _pct(values, q):
    return round(float(np.percentile(values, q)), 1) if len(values) else None


def _stream(source: str, layout, weights, detector, folder: Path, name: str, prefetch: int = 1,
            roi: int | None = None, workers: int = 1) -> dict:
    from dockfactory.measure.stream import StreamOptions, measure_stream
    out = folder / f"{name}.jsonl"
    summary = measure_stream(layout, weights, str(out), video=source,
                             options=StreamOptions(prefetch=prefetch, roi_refresh=roi, workers=workers),
                             detector=detector)
    lines = [json.loads(ln) for ln in out.read_text().splitlines()][:-1]
    return {"frames_per_s": summary["frames_per_s"], "latency_ms": summary["latency_ms"],
            "timing_ms_median": summary["timing_ms_median"], "poses": [ln.get("pose") for ln in lines],
            "backend": summary["backend"]}


def _detector(weights, backend: str, scale: float | None, size: tuple[int, int]):
    """A loaded detector, warmed up at the frames' size (ONNX Runtime: torch's thread count)."""
    from dockfactory.measure.stream import StreamOptions, load_detector
    return load_detector(weights, StreamOptions(backend=backend, input_scale=scale), size)


def _cpu_timed(variant, frames: int) -> dict:
    """The variant's result with ``cpu_ms_per_frame``: this process's CPU time (every thread) per
    frame, which a shared machine's load changes far less than the wall time."""
    c0 = time.process_time()
    res = variant()
    res["cpu_ms_per_frame"] = round(1000.0 * (time.process_time() - c0) / frames, 1)
    return res


def _best_ms(fn, repeats: int = 11) -> float:
    """The fastest of ``repeats`` calls, ms: what a step costs when the shared machine lets it run."""
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return round(1000.0 * best, 1)


def _components(ds, ids, mp4: str, onnx, torch_det, small) -> dict:
    """Each step of one frame (the run's middle one) alone, best of 11: decoding, the network on the
    full frame at each input scale and runtime and on the window --roi would use, detection with
    the centre refinement, and identification + solve."""
    import cv2

    from dockfactory.measure.images import detect_in, solve_image
    from dockfactory.measure.roi import RoiTracker
    k = len(ids) // 2
    data = ds.image_path(ids[k]).read_bytes()
    rgb = cv2.cvtColor(cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
    cap = cv2.VideoCapture(mp4)
    tracker = RoiTracker(rgb.shape[1], rgb.shape[0], min_score=onnx.conf)
    tracker.update(onnx.detect(rgb), None)
    roi = tracker.region()
    x0, y0, x1, y1 = roi
    crop = np.ascontiguousarray(rgb[y0:y1, x0:x1])
    markers = ds.markers()
    out = {"png_decode": _best_ms(lambda: cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)),
           "mp4_seek_and_read_frame": _best_ms(lambda: (cap.set(cv2.CAP_PROP_POS_FRAMES, 0), cap.read())),
           "network_onnx_0.5": _best_ms(lambda: onnx.raw(rgb)),
           "network_torch_0.5": _best_ms(lambda: torch_det.raw(rgb)),
           "network_onnx_0.375": _best_ms(lambda: small.raw(rgb)),
           "network_onnx_0.5_roi": _best_ms(lambda: onnx.raw(crop)),
           "detect_refined_full": _best_ms(lambda: onnx.detect(rgb)),
           "detect_refined_roi": _best_ms(lambda: detect_in(onnx, rgb, roi)),
           "detect_and_solve_full": _best_ms(lambda: solve_image(onnx, markers, 0, Path("f"), rgb, "pinhole",
                                                                 onnx.conf))}
    out["roi_px"] = [x1 - x0, y1 - y0]
    return out


def _rmse(results: dict, truth: list[dict]) -> None:
    """Adds each variant's RMSE (and ratio to png-measure's) over the frames every variant solved."""
    common = [k for k in range(len(truth)) if all(r["poses"][k] for r in results.values())]
    for r in results.values():
        r["rmse"] = {n: float(np.sqrt(np.mean([(r["poses"][k][n] - truth[k][n]) ** 2 for k in common])))
                     for n in GATED} if common else {}
        r["frames_compared"] = len(common)
    ref = results["png-measure"]["rmse"]
    for r in results.values():
        r["rmse_ratio"] = {n: r["rmse"][n] / ref[n] if ref.get(n) else None for n in r["rmse"]}


def _run_all(ds, args, folder: Path) -> dict:
    from dockfactory.core.resources import shipped_weights
    weights, layout = shipped_weights(), ds.root / "layout.json"
    ids, videos = _write_videos(ds, args.run, args.frames, folder)
    seq = _png_sequence(ds, ids, folder)
    size = (ds.config.image.width, ds.config.image.height)
    onnx, torch_det = _detector(weights, "auto", None, size), _detector(weights, "torch", None, size)
    small = _detector(weights, "auto", 0.375, size)
    results = {"png-measure": _cpu_timed(lambda: _today(ds, ids, layout, weights, folder), len(ids))}
    mp4 = str(videos["video"])
    for name, source, det, prefetch, roi, workers in (
            ("png-stream", seq, onnx, 1, None, 1), ("mp4", mp4, onnx, 1, None, 1),
            ("mp4-no-prefetch", mp4, onnx, 0, None, 1), ("mp4-torch", mp4, torch_det, 1, None, 1),
            ("mp4-scale-0.375", mp4, small, 1, None, 1), ("mp4-roi-10", mp4, onnx, 1, 10, 1),
            ("mp4-roi-10-0.375", mp4, small, 1, 10, 1), ("png-stream-roi-10", seq, onnx, 1, 10, 1),
            ("mkv-ffv1", str(videos["video_lossless"]), onnx, 1, None, 1),
            ("mp4-2-workers", mp4, None, 1, None, 2), ("mp4-2-workers-no-prefetch", mp4, None, 0, None, 2),
            ("png-stream-2-workers", seq, None, 1, None, 2), ("png-2-workers-no-prefetch", seq, None, 0, None, 2),
            ("mkv-ffv1-2-workers", str(videos["video_lossless"]), None, 1, None, 2)):
        results[name] = _cpu_timed(lambda: _stream(source, layout, weights, det, folder, name, prefetch, roi, workers),
                                   len(ids))
    _rmse(results, [ds.labels[f]["pose_b_in_d"] for f in ids])
    steps = _components(ds, ids, mp4, onnx, torch_det, small)
    return {"frames": len(ids), "frame_ids": [ids[0], ids[-1]], "variants": results, "steps_best_ms": steps}


def _print(res: dict, meta: dict) -> None:
    print(f"machine: {meta['machine']}; {meta['cores']} cores, shared (load average {meta['load_before']:.2f} "
          f"before, {meta['load_after']:.2f} after); torch / ONNX threads {meta['threads']}")
    print(f"dataset {meta['dataset']} version {meta['version']}, run {meta['run']}: {res['frames']} frames "
          f"({res['frame_ids'][0]}..{res['frame_ids'][1]}) of {meta['size']}")
    print(f"{'variant':17s} {'backend':7s} {'CPU ms':>6s} {'frames/s':>8s} {'lat p50':>8s} {'lat p95':>8s} {'read':>6s} "
          f"{'detect':>7s} {'solve':>6s} {'RMSE X mm':>10s} {'Y mm':>7s} {'alpha deg':>10s} {'ratio X/Y/a':>16s}")
    for name, r in res["variants"].items():
        t, rm, ra = r["timing_ms_median"], r["rmse"], r["rmse_ratio"]
        print(f"{name:17s} {r['backend']:7s} {r['cpu_ms_per_frame']:6.0f} {r['frames_per_s']:8.2f} {r['latency_ms']['p50'] or 0:8.1f} "
              f"{r['latency_ms']['p95'] or 0:8.1f} {t.get('read', float('nan')):6.1f} {t['detect']:7.1f} "
              f"{t['solve']:6.1f} {rm.get('x_mm', float('nan')):10.4f} {rm.get('y_mm', float('nan')):7.4f} "
              f"{rm.get('alpha_deg', float('nan')):10.5f} "
              + "/".join(f"{ra.get(n) or float('nan'):.2f}" for n in GATED))
    print("one frame's steps alone, best of 11 (ms): "
          + ", ".join(f"{k} {v}" for k, v in res["steps_best_ms"].items()))
    print(f"targets: >= {TARGETS['frames_per_s']:.0f} frames/s, latency p95 <= {TARGETS['latency_p95_ms']:.0f} ms, "
          f"RMSE ratio <= {TARGETS['rmse_ratio']} (RMSE over the {res['variants']['mp4']['frames_compared']} frames "
          "with a pose in every variant)")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("dataset")
    p.add_argument("--run", type=int, default=0)
    p.add_argument("--frames", type=int, default=24)
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--json")
    args = p.parse_args()
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
    import torch
    torch.set_num_threads(args.threads)
    from dockfactory.generator.datasets.reader import Dataset
    ds = Dataset.open(args.dataset, full=False)
    meta = {"machine": f"{platform.machine()} {_cpu()}", "cores": os.cpu_count(), "threads": args.threads,
            "load_before": os.getloadavg()[0], "dataset": args.dataset, "version": ds.version_id, "run": args.run,
            "size": f"{ds.config.image.width}x{ds.config.image.height}", "date_utc": time.strftime("%Y-%m-%d %H:%M")}
    with tempfile.TemporaryDirectory() as tmp:
        res = _run_all(ds, args, Path(tmp))
    meta["load_after"] = os.getloadavg()[0]
    _print(res, meta)
    if args.json:
        from dockfactory.core.io import write_json_atomic
        for r in res["variants"].values():
            r.pop("poses")
        write_json_atomic(args.json, {"meta": meta, **res})


def _cpu() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


if __name__ == "__main__":
    main()
