"""The judge's sub-commands of ``dockfactory``: solve, evaluate, report, run (registered by
``dockfactory.cli``). Each returns an exit status; bad input raises DockfactoryError."""
from __future__ import annotations

import math
import sys
from pathlib import Path

from dockfactory.cli_args import add_set_flag, output_path
from dockfactory.cli_factory import load_checked
from dockfactory.core.errors import DockfactoryError
from dockfactory.core.io import write_json_atomic, write_text_atomic
from dockfactory.core.names import MIN_SCORE, SPLITS
from dockfactory.core.resources import default_acceptance, resolve_config, shipped_dataset_configs
from dockfactory.eval.acceptance import criterion_lines, load_acceptance, verdict_exit_status
from dockfactory.eval.dataset_access import read_json_for
from dockfactory.eval.envelope import EnvelopeGrid
from dockfactory.eval.evaluate import evaluate, portable_path, write_outputs
from dockfactory.eval.report import NO_ENGINE, build_report, pdf_engine, write_pdf
from dockfactory.eval.solve_frames import SELF_CALIBRATE, resolve_camera_model, solve_dataset, write_poses
from dockfactory.generator.datasets.folder import writer_lock
from dockfactory.generator.datasets.reader import Dataset
from dockfactory.pipeline import run_pipeline
from dockfactory.solver.checks import MAX_SIGMA_PX




def parse_splits(text: str) -> tuple[str, ...]:
    """``--split test,repeat`` -> ("test", "repeat"); unknown, empty or repeated names refused."""
    splits = tuple(s.strip() for s in text.split(","))
    for s in splits:
        if s not in SPLITS:
            raise DockfactoryError(f"--split: {s!r} is not a split (known: {', '.join(SPLITS)}; "
                                   "several separated by commas)")
    if len(set(splits)) != len(splits):
        raise DockfactoryError(f"--split: a split is named twice in {text!r}")
    return splits


def check_min_score(value: float) -> float:
    if not (math.isfinite(value) and 0.0 <= value <= 1.0):
        raise DockfactoryError(f"--min-score: must be in [0, 1], got {value}")
    return value


def check_oracle_noise(value: float | None) -> float | None:
    if value is not None and not (math.isfinite(value) and value >= 0.0):
        raise DockfactoryError(f"--oracle-noise: must be a finite number of pixels >= 0, got {value}")
    return value


def parse_section_shift(text: str | None) -> tuple[float, float] | None:
    """``--section-shift``: None, or "PX" (both axes) / "PX,PX" (x, y), each a number of pixels in
    [0, MAX_SIGMA_PX] (DockfactoryError naming the flag otherwise)."""
    if text is None:
        return None
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    if len(values) == 1:
        values *= 2
    if len(values) != 2 or not all(math.isfinite(v) and 0 <= v <= MAX_SIGMA_PX for v in values):
        raise DockfactoryError(f"--section-shift: expected PX or PX,PX, pixels in [0, {MAX_SIGMA_PX:g}], got {text!r}")
    return (values[0], values[1])


def cmd_solve(args) -> int:
    splits = parse_splits(args.split)
    check_min_score(args.min_score)
    check_oracle_noise(args.oracle_noise)
    if (args.detections is None) == (args.oracle_noise is None):
        raise DockfactoryError("give --detections DETS.json or --oracle-noise PX (exactly one)")
    model = resolve_camera_model(args.camera_model, args.self_calibrate)
    if args.sigma_floor is not None and not (math.isfinite(args.sigma_floor) and 0 < args.sigma_floor <= MAX_SIGMA_PX):
        raise DockfactoryError(f"--sigma-floor: must be a number of pixels in (0, {MAX_SIGMA_PX:g}], "
                               f"got {args.sigma_floor}")
    shift = parse_section_shift(args.section_shift)
    ds = Dataset.open(args.dataset)
    modes = {"camera_model": model, "self_calibrate": args.self_calibrate, "sigma_floor_px": args.sigma_floor,
             "section_shift_px": shift}
    if args.detections:
        dets = read_json_for(args.detections, "detections", ds)
        poses = solve_dataset(ds, splits, detections=dets, min_score=args.min_score, **modes)
    else:
        poses = solve_dataset(ds, splits, oracle_sigma_px=args.oracle_noise, **modes)
    write_poses(args.out, poses, args.detections)
    n_ok = sum(r["ok"] for r in poses["frames"].values())
    print(f"{n_ok} of {len(poses['frames'])} frames solved -> {args.out}", file=sys.stderr)
    return 0


def cmd_evaluate(args) -> int:
    check_min_score(args.min_score)
    spec = load_acceptance(args.acceptance or default_acceptance())
    ds = Dataset.open(args.dataset)   # every byte checked: the judge reads only an intact dataset
    metrics, rows = evaluate(ds, args.poses, spec, args.detections, min_score=args.min_score,
                             envelope=EnvelopeGrid() if args.envelope else None, camera_models=args.camera_models)
    with writer_lock(args.out, "evaluate"):   # a second writer is refused: the verdict printed is the file's
        return _write_verdict(args, metrics, rows)


def _write_verdict(args, metrics: dict, rows) -> int:
    """Write metrics, frames and provenance into --out and print the verdict (the caller holds
    the folder's lock until it is printed)."""
    write_outputs(args.out, metrics, rows)
    write_json_atomic(Path(args.out) / "provenance.json", {
        "detections": portable_path(args.detections, args.out) if args.detections else None, "commands": [" ".join(["dockfactory"] + sys.argv[1:])],
        # the weights the detections name: a report of a detector's run says which detector it judged
        "model_sha256": metrics.get("detection", {}).get("weights_sha256") if args.detections else None})
    acc = metrics["acceptance"]
    print("\n".join(criterion_lines(acc)))
    print(f"verdict: {acc['verdict']}  ({args.out}/metrics.json)")
    return verdict_exit_status(acc["verdict"])


def cmd_report(args) -> int:
    """Build the report holding the lock of the folder of --out (the HTML file; its .md and .json
    go beside it)."""
    if args.pdf and pdf_engine() is None:
        raise DockfactoryError(f"--pdf: {NO_ENGINE}")
    with writer_lock(Path(args.out).parent, "report", f"--out {args.out}: its folder"):
        summary = build_report(args.eval_dir, args.out,
                               signers={"prepared_by": args.prepared_by, "approved_by": args.approved_by})
        pdf = Path(args.out).with_suffix(".pdf")
        engine = write_pdf(args.out, pdf) if args.pdf else None
    print(f"verdict: {summary['verdict']}  report: {args.out} (id {summary['report_id']})"
          + (f"  pdf: {pdf} ({engine})" if engine else ""))
    return 0


def _check_run_flags(args) -> None:
    """Flags that were silently ignored or accepted (negative counts, --weights beside --train)."""
    check_oracle_noise(args.oracle_noise)
    if args.workers < 1:
        raise DockfactoryError(f"--workers: must be >= 1, got {args.workers}")
    if args.epochs is not None and args.epochs < 1:
        raise DockfactoryError(f"--epochs: must be >= 1, got {args.epochs}")
    if args.oracle_noise is not None and (args.train or args.weights):
        raise DockfactoryError("--oracle-noise skips the detector: --weights and --train do not apply with it")
    if args.train and args.weights:
        raise DockfactoryError("--weights and --train exclude each other (--train uses the detector it trains)")
    if args.epochs is not None and not args.train:
        raise DockfactoryError("--epochs applies only with --train")
    if args.weights and not Path(args.weights).is_file():
        raise DockfactoryError(f"--weights: {args.weights}: no such file")


def cmd_run(args) -> int:
    _check_run_flags(args)
    config = resolve_config(args.config)
    acceptance = args.acceptance or default_acceptance()
    _, text = load_checked(config, args.sets)   # a bad config or spec is refused before the work folder is made
    load_acceptance(acceptance)
    if args.sets:   # the resolved config is what runs: written into the work folder
        config = Path(args.out) / "config_resolved.toml"
        config.parent.mkdir(parents=True, exist_ok=True)
        write_text_atomic(config, text)
    return run_pipeline(config, args.out, acceptance, weights=args.weights, train=args.train,
                        oracle_noise_px=args.oracle_noise, workers=args.workers, train_epochs=args.epochs)


def add_eval_commands(sub) -> None:
    """Register solve, evaluate, report and run on ``sub`` (argparse subparsers)."""
    _add_solve_parser(sub)
    _add_evaluate_parser(sub)
    _add_report_parser(sub)
    _add_run_parser(sub)


def _add_solve_parser(sub) -> None:
    s = sub.add_parser("solve", help="poses of B relative to A from detections (or label centres + noise)")
    s.add_argument("dataset")
    s.add_argument("--detections", help="DETS.json from dockfactory detect")
    s.add_argument("--oracle-noise", type=float, metavar="PX", help="use the exact image centroids of the markers (labels) + Gaussian noise (px)")
    s.add_argument("--split", default="test,repeat")
    s.add_argument("--camera-model", help="pinhole, k1, k1k2, pp_k1, pp_k1_p or auto "
                                          "(default: pinhole, the paper's; auto with --self-calibrate)")
    s.add_argument("--self-calibrate", choices=SELF_CALIBRATE,
                   help="frame: the model per frame; sequence: each docking run of the labels (one camera "
                        "unit) solved with shared intrinsics")
    s.add_argument("--min-score", type=float, default=MIN_SCORE)
    s.add_argument("--sigma-floor", type=float, metavar="PX",
                   help="the detector's centre noise measured on labelled frames (evaluate's "
                        "centre_noise.used.value on another split): no frame's covariance assumes less")
    s.add_argument("--section-shift", metavar="PX[,PX]",
                   help="the common offset of a section's centres (x,y px; one number: both axes) measured on "
                        "labelled frames of the camera class (default: the detections' noise card)")
    s.add_argument("--out", type=output_path, required=True)
    s.set_defaults(func=cmd_solve)


def _add_evaluate_parser(sub) -> None:
    e = sub.add_parser("evaluate", help="metrics, per-frame CSV and the acceptance verdict (exit 0 accepted, 1 rejected, 2 bad input, 3 not proven)")
    e.add_argument("dataset")
    e.add_argument("--poses", required=True)
    e.add_argument("--detections")
    e.add_argument("--acceptance", help="acceptance spec TOML (default: the shipped one, the paper's criteria)")
    e.add_argument("--min-score", type=float, default=MIN_SCORE)
    e.add_argument("--envelope", action="store_true",
                   help="also sweep principal-point offset and k1 on the test geometry: which uncalibrated "
                        "cameras pass (reported, not gated; about 0.5 s per test frame)")
    e.add_argument("--camera-models", action="store_true",
                   help="also solve the test split with the pinhole and self-calibrated camera models side by "
                        "side (per frame, per docking run): pose and intrinsics errors (reported, not gated)")
    e.add_argument("--out", type=output_path, required=True)
    e.set_defaults(func=cmd_evaluate)


def _add_report_parser(sub) -> None:
    r = sub.add_parser("report", help="self-contained HTML acceptance report (+ report.json, report.md)")
    r.add_argument("eval_dir")
    r.add_argument("--out", type=output_path, required=True)
    r.add_argument("--prepared-by", metavar="NAME", help="name in the report's sign-off block (default: a line to sign)")
    r.add_argument("--approved-by", metavar="NAME", help="name in the report's sign-off block (default: a line to sign)")
    r.add_argument("--pdf", action="store_true",
                   help="also write the report as a PDF beside it (WeasyPrint, else a headless Chromium)")
    r.set_defaults(func=cmd_report)


def _add_run_parser(sub) -> None:
    u = sub.add_parser("run", help="render -> detect -> solve -> evaluate -> report (resumable)")
    u.add_argument("config", help="TOML config file, or the name of a shipped one "
                                  f"({', '.join(shipped_dataset_configs())})")
    u.add_argument("--out", type=output_path, required=True, help="work directory")
    u.add_argument("--acceptance", help="acceptance spec TOML (default: the shipped one, the paper's criteria)")
    u.add_argument("--weights", help="detector checkpoint (default: the shipped one; not with --train)")
    u.add_argument("--train", action="store_true", help="train a detector on the dataset's train split first")
    u.add_argument("--epochs", type=int, default=None, help="with --train: training epochs")
    u.add_argument("--oracle-noise", type=float, metavar="PX", help="skip the detector: exact centres + noise")
    u.add_argument("--workers", type=int, default=1, help="render processes (>= 1)")
    add_set_flag(u)
    u.set_defaults(func=cmd_run)
