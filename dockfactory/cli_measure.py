"""``dockfactory measure``: the command line of eval.measure (torch is imported inside the command)."""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from dockfactory.core.progress import Progress
from dockfactory.core.errors import DockfactoryError
from dockfactory.core.names import MIN_SCORE
from dockfactory.core.resources import shipped_weights
from dockfactory.core.camera_chain.cfa import PATTERNS
from dockfactory.core.camera_chain.demosaic import DEMOSAICS
from dockfactory.cli_args import (
    MAX_THREADS,
    float_in,
    int_in,
    lens_prior,
    output_path,
    positive_int,
    thread_count,
    torch_threads,
    unit_float,
)
from dockfactory.core.calibration_files import read_calibration
from dockfactory.measure import MAX_WORKERS, CameraInput, MeasureOptions, measure
from dockfactory.measure.verdict import budget_lines, pose_lines, summary_line
from dockfactory.eval.conformity import exit_status
from dockfactory.measure.read import DEFAULT_MAX_MEGAPIXELS, MAX_MEGAPIXELS
from dockfactory.measure.selfcal import parse_window
from dockfactory.measure.stream import FILTERS, PREFETCH, StreamOptions, measure_stream, stream_decider
from dockfactory.eval.solve_frames import SELF_CALIBRATE

MAX_CAMERA_INDEX = 1023   # capture device numbers (V4L2 /dev/videoN, DirectShow, AVFoundation) are small


def _weights(args) -> Path:
    weights = Path(args.weights) if args.weights else shipped_weights()
    if not weights.is_file():
        raise DockfactoryError(f"--weights: {weights}: no such file")
    return weights


def _check_inputs(args) -> bool:
    """True for a stream (--video or --camera), False for images; one line naming the clash else."""
    stream = args.video is not None or args.camera is not None
    if stream and args.images:
        raise DockfactoryError("measure: give images, or --video / --camera, not both")
    if not stream and not args.images:
        raise DockfactoryError("measure: give images (files or folders), --video PATH or --camera INDEX")
    window = (args.self_calibrate or "").startswith("window:")
    if stream and args.self_calibrate and not window:
        raise DockfactoryError(f"--self-calibrate {args.self_calibrate}: a stream self-calibrates over a sliding "
                               "window (window:N)")
    if not stream and window:
        raise DockfactoryError("--self-calibrate window:N: for a stream (--video, --camera); images use frame "
                               "or sequence")
    if not stream and (args.jsonl is not None or args.filter or args.max_frames or args.roi or args.input_scale
                       or args.freeze_after):
        raise DockfactoryError("--jsonl, --filter, --max-frames, --roi, --input-scale and --freeze-after apply to "
                               "a stream (--video, --camera)")
    if not stream and args.out is None:
        raise DockfactoryError("measure: --out is needed with images")
    if stream and args.out is not None:
        raise DockfactoryError("--out: a stream writes JSON lines (--jsonl FILE or - for standard output)")
    return stream


def cmd_measure_stream(args) -> int:
    """measure --video / --camera: JSON lines to --jsonl (default standard output), the summary
    line last; a human summary on standard error. Exit 1 when a frame had no pose."""
    window = parse_window(args.self_calibrate) if args.self_calibrate else None
    options = StreamOptions(args.backend, args.camera_model, args.min_score, args.cfa, args.filter, args.max_frames,
                            input_scale=args.input_scale, roi_refresh=args.roi, window=window,
                            freeze_after=args.freeze_after, workers=args.workers or 1,
                            prefetch=PREFETCH if (args.workers or 1) == 1 else 0,   # workers overlap the reads
                            lens=args.lens_prior,
                            calibration=read_calibration(args.calibration) if args.calibration else None)
    decide = stream_decider(args.acceptance) if args.acceptance else None
    weights = _weights(args)
    torch_threads(args.threads)
    s = measure_stream(args.layout, weights, args.jsonl or "-", args.video, args.camera, options, decide)
    fails = ", ".join(f"{n} {c}" for c, n in s["failures"].items())
    print(f"{s['frames_with_pose']} of {s['frames']} frames with a pose ({s['camera_model']} camera); "
          f"{s['frames_per_s']} frames/s, latency p95 {s['latency_ms']['p95']} ms"
          + (f"; no pose: {fails}" if fails else "") + (" (interrupted)" if s["stopped"] == "interrupted" else ""),
          file=sys.stderr)
    return 0 if s["frames_with_pose"] == s["frames"] else 1


def cmd_measure(args) -> int:
    if _check_inputs(args):
        return cmd_measure_stream(args)
    weights = _weights(args)
    calibration = read_calibration(args.calibration) if args.calibration else None
    if calibration is not None and (args.lens_prior is not None or args.camera_model not in (None, "pinhole")
                                    or args.self_calibrate):
        raise DockfactoryError("--calibration: the camera is calibrated; --lens-prior, --camera-model and "
                               "--self-calibrate estimate what it states")
    camera = CameraInput(args.cfa, args.raw_black, args.raw_white, args.demosaic, args.lens_prior, calibration)
    options = MeasureOptions(args.backend, args.workers or 2, args.overlay_size or None, camera, args.max_megapixels)
    torch_threads(args.threads)

    bars = []

    def progress(done, total):
        if not bars:
            bars.append(Progress(total, "measure", enabled=not args.quiet, per="s"))
        bars[0].update(done)
        if done >= total:
            bars[0].close()
    s = measure(args.images, args.layout, weights, args.out, camera_model=args.camera_model,
                self_calibrate=args.self_calibrate, min_score=args.min_score, progress=progress, options=options,
                acceptance=args.acceptance)
    fails = ", ".join(f"{n} {c}" for c, n in s["failures"].items())
    if s["earlier_run_discarded"]:
        print(f"measure: {args.out} held the results of other images or options: removed, measured afresh",
              file=sys.stderr)
    print(f"{s['images_with_pose']} of {s['images_total']} images with a pose ({s['camera_model']} camera"
          + (f", self-calibrated per {s['self_calibrate']}" if s["self_calibrate"] else "") + f"); "
          f"{s['frames_per_s']} frames/s" + (f" ({s['resumed']} done by an earlier run)" if s["resumed"] else "")
          + (f"; no pose: {fails}" if fails else "")
          + f" -> {Path(args.out) / 'measurements.json'}")
    if s["images_total"] == 1 and s["images_with_pose"] == 1 and not args.quiet:
        doc = json.loads((Path(args.out) / "measurements.json").read_text(encoding="utf-8"))
        print("\n".join(budget_lines(doc["images"][0])))
    if "conformity" in s:
        return _print_conformity(s, Path(args.out), args.quiet)
    return 0 if s["images_with_pose"] == s["images_total"] else 1


def _print_conformity(s: dict, out: Path, quiet: bool) -> int:
    """Per image (unless ``quiet``) the decision and each gated value +- U, then the summary
    line; the exit status of the worst image (0 IN, 1 OUT, 3 UNDECIDED)."""
    if not quiet:
        doc = json.loads((out / "measurements.json").read_text(encoding="utf-8"))
        for line in pose_lines(doc["images"], [Path(r["image"]).name for r in doc["images"]]):
            print(line)
    print(summary_line(s["conformity"]))
    return exit_status(s["conformity"]["worst"])


def _self_calibration(text: str) -> str:
    """argparse type of --self-calibrate: frame, sequence or window:N."""
    if text in SELF_CALIBRATE:
        return text
    try:
        parse_window(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"expected frame, sequence or window:N; {exc}") from None
    return text


def _add_stream_args(m) -> None:
    """The flags of measure on a stream (--video, --camera; dockfactory.measure.stream)."""
    m.add_argument("--video", help="measure the frames of a video file (any OpenCV reads) or an image-sequence "
                                   "pattern such as frames/%%06d.png: one JSON line per frame (--jsonl)")
    m.add_argument("--camera", type=int_in(0, MAX_CAMERA_INDEX), metavar="INDEX",
                   help="measure the frames of capture device INDEX as they come (Ctrl-C ends it, with the summary)")
    m.add_argument("--jsonl", help="a stream's JSON lines: a file, or - for standard output (the default)")
    m.add_argument("--filter", choices=FILTERS,
                   help="a stream's display filter: kalman (constant velocity on X, Y, alpha), written beside "
                        "the raw per-frame pose")
    m.add_argument("--max-frames", type=positive_int, help="a stream: stop after this many frames")
    m.add_argument("--freeze-after", type=positive_int, metavar="N",
                   help="a stream with --self-calibrate window:M: freeze the principal point and distortion after "
                        "N joint solves")
    m.add_argument("--roi", type=positive_int, metavar="N",
                   help="a stream: detect in a window around the previous frame's markers, the full frame every N "
                        "frames and whenever the window loses a marker (faster; default: every frame whole)")
    m.add_argument("--calibration", default=None, metavar="FILE",
                   help="the camera's calibration (OpenCV YAML / JSON, ROS camera_info YAML, COLMAP cameras.txt): "
                        "its principal point and distortion are known (its std_deviations_intrinsics, if "
                        "stated, in the budget)")
    m.add_argument("--lens-prior", type=lens_prior, default=None,
                   help="what is plausible for the intrinsics the camera model does not estimate, carried into "
                        "every pose's uncertainty: default (principal point within 0.04 x the image width, "
                        "|k1| <= 0.2, |k2| <= 0.1, |p1|, |p2| <= 2e-3), known (a calibrated lens: nothing added) or "
                        "pp=F,k1=A,k2=B,p=C (half-ranges; keys not given keep the default's)")
    m.add_argument("--input-scale", type=float_in(0.1, 2.0),
                   help="a stream: network px per image px (default: the weights' own, 0.5 for the shipped ones; "
                        "smaller is faster and sees small markers worse)")


def add_subcommand(sub) -> None:
    m = sub.add_parser("measure", help="poses of B in A from real images (no labels): detect, identify, solve")
    m.add_argument("images", nargs="*", help="PNG/JPEG/TIFF/BMP files or folders of them (or --video, --camera)")
    _add_stream_args(m)
    m.add_argument("--layout", required=True, help="marker layout JSON (a dataset's layout.json format)")
    m.add_argument("--weights", help="detector weights (default: the shipped ones)")
    m.add_argument("--camera-model", help="pinhole, k1, k1k2, pp_k1, pp_k1_p or auto "
                                          "(default: pinhole; auto with --self-calibrate)")
    m.add_argument("--self-calibrate", type=_self_calibration,
                   help="frame: choose the camera model per image; sequence: the images are one camera's "
                        "docking run, solved with shared intrinsics; window:N (a stream): intrinsics refined over "
                        "the last N frames")
    m.add_argument("--min-score", type=unit_float, default=MIN_SCORE)
    m.add_argument("--threads", type=thread_count, default=None,
                   help=f"torch threads with --workers 1 (1 to {MAX_THREADS}; default: one per core)")
    m.add_argument("--workers", type=positive_int, default=None,
                   help=f"images measured at once, each by its own process (1 to {MAX_WORKERS}, never more than the "
                        "images; default 2: one per core); a stream's frames (default 1: this process; more: "
                        "frame by frame, not with --roi or --self-calibrate window:N)")
    m.add_argument("--max-megapixels", type=float_in(0.0, MAX_MEGAPIXELS, low_open=True),
                   default=DEFAULT_MAX_MEGAPIXELS,
                   help=f"the largest image measured, by the size its header states "
                        f"(default {DEFAULT_MAX_MEGAPIXELS:g}: "
                        f"e.g. 8160x6120; at most {MAX_MEGAPIXELS:g}); a larger image is reported, never decoded "
                        "(decoding costs about 3 bytes per pixel per copy)")
    m.add_argument("--backend", choices=("auto", "torch", "onnx"), default="auto",
                   help="the detector network's runtime (auto: ONNX Runtime when installed, about 2x faster)")
    m.add_argument("--overlay-size", type=float, default=0.5,
                   help="overlay PNG resolution as a fraction of the image's (default 0.5, a live view; "
                        "1: full resolution; 0: no overlays)")
    m.add_argument("--cfa", choices=PATTERNS,
                   help="the camera's Bayer pattern: the centre refinement fits the sensor's own samples of a "
                        "demosaiced image, and one-channel 16-bit PNGs are read as raw frames")
    m.add_argument("--raw-black", type=float, default=0.0, help="raw frames: black level, DN (default 0)")
    m.add_argument("--raw-white", type=float, default=None,
                   help="raw frames: the sensor's white level, DN (needed: e.g. 4095 for 12 bit)")
    m.add_argument("--demosaic", choices=DEMOSAICS, default="mhc", help="raw frames: demosaic (default mhc)")
    m.add_argument("--acceptance", metavar="SPEC",
                   help="acceptance spec (TOML, as run and evaluate take): each image's X, Y, alpha... IN / OUT / "
                        "UNDECIDED against the [localization] tolerances about the docked pose, with the guard "
                        "band U = 2 u (ISO 14253-1); exit 0 all IN, 1 any OUT, 3 otherwise undecided")
    m.add_argument("--quiet", action="store_true")
    m.add_argument("--out", type=output_path,
                   help="images: output folder (locked while measure runs); a rerun with the same "
                                                "images and options measures only what is missing, with others "
                                                "it starts over")
    m.set_defaults(func=cmd_measure)
