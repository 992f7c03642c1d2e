"""Detector subcommands of ``dockfactory``: train, detect, ablate, export-onnx.

``add_subcommands(subparsers)`` registers them on an argparse subparsers object. torch is only
imported inside the command functions, so building the parser (and ``--help``) stays instant.
Each command returns an exit status (0 ok); bad input raises ValueError (the caller maps it to 2).
"""
from __future__ import annotations

from pathlib import Path

from dockfactory.core.errors import DockfactoryError
from dockfactory.core.io import write_json_atomic
from dockfactory.core.names import MIN_SCORE
from dockfactory.core.resources import shipped_weights
from dockfactory.detector.onnx_export import export_onnx
from dockfactory.ablate import run_ablation
from dockfactory.eval.detection_metrics import (
    evaluate_detections,
    format_report,
)
from dockfactory.eval.noise_calibration import calibrate_noise_card
from dockfactory.eval.simulated_cameras import dataset_camera
from dockfactory.cli_args import (
    input_scale,
    int_in,
    learning_rate,
    non_negative_int,
    output_path,
    thread_count,
    torch_threads,
    unit_float,
)
from dockfactory.generator.datasets.folder import writer_lock
from dockfactory.generator.datasets.reader import Dataset
from dockfactory.generator.exports import coco_results

# Named limits of the training flags: beyond them a run asks for gigabytes (1e9 crops per frame
# wanted a 30 GB index array) or years, not for a detector.
MAX_EPOCHS, MAX_BATCH, MAX_CROPS_PER_FRAME, MAX_SEEDS, MAX_INPUT_PX = 100_000, 4096, 1000, 100, 8192


def _train_config(args, attention: str, seed: int):
    from dockfactory.detector.data import DataConfig
    from dockfactory.detector.model import (
        DEFAULT_ANCHORS,
        DEFAULT_ANCHORS_P2,
        ModelConfig,
    )
    from dockfactory.detector.train import TrainConfig
    model = ModelConfig(scale=args.model, attention=attention, p2=args.p2,
                        anchors=DEFAULT_ANCHORS_P2 if args.p2 else DEFAULT_ANCHORS)
    data = DataConfig(crops_per_frame=args.crops_per_frame, input_scale=args.input_scale)
    return TrainConfig(model=model, data=data, epochs=args.epochs, batch_size=args.batch, nbs=args.nbs or args.batch,
                       lr0=args.lr0, seed=seed)


def cmd_train(args) -> int:
    torch_threads(args.threads)
    from dockfactory.detector.train import train
    cfg = _train_config(args, args.attention, args.seed)
    summary = train(Dataset.open(args.dataset), args.out, cfg, resume=args.resume, progress=not args.quiet,
                    init=args.init)
    h = summary["history"]
    print(f"trained {summary['epochs']} epochs on dataset {summary['dataset_version']} in {summary['seconds']} s "
          f"({h[-1]['images_per_s'] if h else float('nan')} img/s last epoch); weights: {summary['weights']}")
    return 0


def cmd_detect(args) -> int:
    torch_threads(args.threads)
    from dockfactory.detector.infer import detect_dataset
    split = None if args.split == "all" else args.split
    dataset = Dataset.open(args.dataset)
    native = args.format == "dockfactory"
    doc = detect_dataset(dataset, args.weights or shipped_weights(), args.out if native else None, split=split,
                         conf_threshold=args.conf, iou_threshold=args.iou, refine=not args.no_refine,
                         progress=not args.quiet, camera=dataset_camera(dataset))
    if not native:   # COCO results: the ids of the dataset's COCO export
        write_json_atomic(args.out, coco_results(dataset.splits, doc), indent=None)
    n = sum(len(v) for v in doc["frames"].values())
    print(f"{n} detections in {len(doc['frames'])} frames ({doc['timing']['mean_ms']} ms/image) -> {args.out}"
          + ("" if native else " (COCO results)"))
    if args.eval:
        print(format_report(evaluate_detections(dataset, doc)))
    return 0


def cmd_ablate(args) -> int:
    torch_threads(args.threads)
    attentions = [a.strip() for a in args.attention.split(",") if a.strip()]
    seeds = list(range(args.seeds))
    result = run_ablation(Dataset.open(args.dataset), args.out, attentions, seeds,
                          lambda att, seed: _train_config(args, att, seed), conf=args.conf,
                          progress=not args.quiet, record_dir=args.record, train=not args.no_train)
    print(result["table"])
    print(f"written: {Path(args.out) / 'ablation.md'}, {Path(args.out) / 'ablation.json'}")
    return 0


def cmd_export_onnx(args) -> int:
    """Export under the lock of the ONNX file's folder (one writer at a time; a folder that
    cannot be written is one line before any work)."""
    out = Path(args.out)
    if out.is_dir():
        raise DockfactoryError(f"--out {out}: is a folder; give the ONNX file's name")
    torch_threads(args.threads)
    with writer_lock(out.parent, "export-onnx", f"--out {out}: its folder"):
        info = export_onnx(args.weights or shipped_weights(), out, height=args.height, width=args.width,
                           check=not args.no_check)
    print(f"ONNX model -> {info['path']} (input {info['input_shape']}); "
          + (f"max |onnx - torch| = {info['max_abs_diff']:.2e}" if "max_abs_diff" in info else "not checked"))
    return 0


def cmd_noise_card(args) -> int:
    torch_threads(args.threads)
    weights = Path(args.weights) if args.weights else shipped_weights()
    card = calibrate_noise_card(Dataset.open(args.dataset), weights, split=args.split, progress=not args.quiet)
    print(f"centre noise {card['centre_noise_px']:.4f} px per axis (x {card['axis_px'][0]:.4f}, "
          f"y {card['axis_px'][1]:.4f}) over {card['n']} used centres of {card['measured_on']['frames']} "
          f"{args.split} frames -> {card['card']}")
    return 0


def _add_training_options(p) -> None:
    """Options shared by train and ablate."""
    p.add_argument("--model", choices=("n", "s"), default="n", help="YOLOv5 scale (default n)")
    p.add_argument("--epochs", type=int_in(1, MAX_EPOCHS), default=60, help=f"epochs, 1-{MAX_EPOCHS} (default 60)")
    p.add_argument("--batch", type=int_in(1, MAX_BATCH), default=16, help=f"crops per batch, 1-{MAX_BATCH} (default 16)")
    p.add_argument("--nbs", type=int_in(1, MAX_BATCH * 64),
                   help="nominal batch for gradient accumulation (default = --batch)")
    p.add_argument("--crops-per-frame", type=int_in(1, MAX_CROPS_PER_FRAME), default=2,
                   help=f"windows per training frame per epoch, 1-{MAX_CROPS_PER_FRAME}")
    p.add_argument("--input-scale", type=input_scale, default=0.5, help="network px per image px (default 0.5)")
    p.add_argument("--p2", action="store_true", help="add the stride-4 (P2) output")
    p.add_argument("--lr0", type=learning_rate, default=0.01,
                   help="initial learning rate, (0, 1] (default 0.01; a fine-tune usually wants 0.001-0.003)")
    p.add_argument("--threads", type=thread_count, help="torch threads (default: all cores)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")


def _add_train_parser(subparsers) -> None:
    t = subparsers.add_parser("train", help="train the marker detector on a dataset's train split")
    t.add_argument("dataset", help="dataset directory (dockfactory render --out)")
    t.add_argument("--out", type=output_path, required=True, help="run directory (checkpoints, history, weights)")
    t.add_argument("--attention", choices=("se", "eca", "cbam", "a2", "none"), default="se",
                   help="attention block after the last backbone C3 (default se)")
    t.add_argument("--seed", type=non_negative_int, default=0, help="seed of initial weights, crops and augmentation")
    t.add_argument("--resume", action="store_true", help="continue from RUN/last.pt")
    t.add_argument("--init", metavar="WEIGHTS",
                   help="fine-tune from these weights (a weights file or checkpoint): the network, its anchors and "
                        "input scale come from them, so --model, --attention, --p2 and --input-scale are not used")
    _add_training_options(t)
    t.set_defaults(func=cmd_train)


def _add_detect_parser(subparsers) -> None:
    d = subparsers.add_parser("detect", help="detect markers (boxes, refined centres) in a dataset's frames")
    d.add_argument("dataset")
    d.add_argument("--weights",
                   help="weights.pt / last.pt of a run (default: the shipped models/yolov5n_se_rings_markers.pt)")
    d.add_argument("--split", default="test", choices=("train", "test", "repeat", "all"), help="default test")
    d.add_argument("--out", type=output_path, required=True, help="detections JSON")
    d.add_argument("--format", choices=("dockfactory", "coco-results"), default="dockfactory",
                   help="dockfactory: the detections document (default); coco-results: a COCO results list "
                        "(image and category ids of the dataset's COCO export) for COCOeval")
    d.add_argument("--conf", type=unit_float, default=MIN_SCORE, help="score threshold (use 0.001 for mAP)")
    d.add_argument("--iou", type=unit_float, default=0.45, help="NMS IoU threshold")
    d.add_argument("--no-refine", action="store_true", help="skip the sub-pixel centre refinement")
    d.add_argument("--eval", action="store_true", help="print mAP, centre error and recall afterwards")
    d.add_argument("--threads", type=thread_count)
    d.add_argument("--quiet", action="store_true")
    d.set_defaults(func=cmd_detect)


def _add_ablate_parser(subparsers) -> None:
    a = subparsers.add_parser("ablate", help="train and evaluate attention variants under one budget")
    a.add_argument("dataset")
    a.add_argument("--attention", default="none,se,eca,cbam,a2", help="comma-separated variants")
    a.add_argument("--seeds", type=int_in(1, MAX_SEEDS), default=1, help=f"number of seeds (0..S-1), 1-{MAX_SEEDS}")
    a.add_argument("--out", type=output_path, default="out/ablation",
                   help="folder for runs and tables (default out/ablation)")
    a.add_argument("--conf", type=unit_float, default=0.001, help="score threshold for mAP")
    a.add_argument("--record", help="also write each finished run's metrics to RECORD/<variant>_seed<k>.json and "
                   "take runs recorded there (same dataset version and config) without training them again")
    a.add_argument("--no-train", action="store_true",
                   help="train nothing: the table of the finished runs (records without a later figure get it "
                        "from their saved detections), e.g. beside a running ablation")
    _add_training_options(a)
    a.set_defaults(func=cmd_ablate)


def _add_export_parser(subparsers) -> None:
    e = subparsers.add_parser("export-onnx", help="export weights to ONNX and check against torch")
    e.add_argument("--weights", help="default: the shipped weights")
    e.add_argument("--out", type=output_path, required=True, help="ONNX file")
    e.add_argument("--height", type=int_in(32, MAX_INPUT_PX), default=480, help="network input height (default 480)")
    e.add_argument("--width", type=int_in(32, MAX_INPUT_PX), default=640, help="network input width (default 640)")
    e.add_argument("--no-check", action="store_true", help="skip the onnxruntime comparison")
    e.add_argument("--threads", type=thread_count)
    e.set_defaults(func=cmd_export_onnx)


def _add_noise_card_parser(subparsers) -> None:
    n = subparsers.add_parser("noise-card", help="measure the weights' centre noise on a labelled split and "
                                                 "write their noise card (the floor of the solver's covariance)")
    n.add_argument("dataset")
    n.add_argument("--weights", help="default: the shipped weights (the card is written next to them)")
    n.add_argument("--split", default="val", choices=("train", "val"),
                   help="a split the evaluation does not judge (default val)")
    n.add_argument("--threads", type=thread_count)
    n.add_argument("--quiet", action="store_true")
    n.set_defaults(func=cmd_noise_card)


def add_subcommands(subparsers) -> None:
    """Register train, detect, ablate, export-onnx and noise-card on ``subparsers`` (argparse)."""
    _add_train_parser(subparsers)
    _add_detect_parser(subparsers)
    _add_ablate_parser(subparsers)
    _add_export_parser(subparsers)
    _add_noise_card_parser(subparsers)
