"""Factory subcommands of ``dockfactory``: render, dataset, check-config, show (registered by the
root CLI, ``dockfactory.eval.cli``). Heavy imports happen inside the commands."""
from __future__ import annotations

import argparse
import json
import sys
from collections import Counter
from pathlib import Path

from dockfactory.core.config import load_config
from dockfactory.core.errors import DockfactoryError
from dockfactory.core.resources import resolve_config
from dockfactory.generator import dataset_tools as dt
from dockfactory.generator import published
from dockfactory.generator.dataset import identity, writer_lock
from dockfactory.generator.overlay import draw_overlay
from dockfactory.generator.render_job import JobOptions, print_summary, run_render
from dockfactory.generator.sampler import check_focal_fits, frame_plan

EXIT_OK, EXIT_FAILED = 0, 1


def _shard(text: str) -> tuple[int, int]:
    try:
        k, n = (int(v) for v in text.split("/"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected K/N (e.g. 2/4), got {text!r}") from None
    if not (n >= 1 and 1 <= k <= n):
        raise argparse.ArgumentTypeError(f"expected K/N with 1 <= K <= N, got {text!r}")
    return k, n


def int_at_least(low: int):
    """argparse type: an integer >= ``low`` (a negative count used to be accepted silently)."""
    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer >= {low}, got {text!r}") from None
        if v < low:
            raise argparse.ArgumentTypeError(f"expected an integer >= {low}, got {text!r}")
        return v
    parse.__name__ = f"integer >= {low}"
    return parse


def _load(path):
    """Load a config and check it is feasible (every planned frame fits its markers): the check
    samples every frame's geometry, so it runs here (render, check-config), not on every load."""
    cfg = load_config(resolve_config(path))
    check_focal_fits(cfg, str(path))
    return cfg, resolve_config(path).read_text(encoding="utf-8")


def cmd_render(args) -> int:
    cfg, text = _load(args.config)
    frame_ids = tuple(args.frames.split(",")) if args.frames else None
    opts = JobOptions(workers=args.workers, shard=args.shard, frame_ids=frame_ids,
                      retries=args.retries, recycle_after=args.recycle_after,
                      progress=not args.quiet, executor=args.executor, ray_address=args.ray_address)
    summary = run_render(cfg, args.out, text, opts)
    print_summary(summary)
    if summary.complete:
        print(f"\nimages: {Path(args.out) / 'images'}  labels: {Path(args.out) / 'labels'}\n"
              f"look at one: dockfactory show {args.out} <frame_id> --out overlay.png", file=sys.stderr)
    return EXIT_OK if summary.ok else EXIT_FAILED


def cmd_dataset(args) -> int:
    """Every DIR is taken: verify/info/export run on each (in order), diff needs exactly two."""
    if args.action == "verify":
        reports = []
        for root in args.dirs:
            reports.append(published.verify_against(root, args.manifest, args.tolerance) if args.manifest
                           else dt.verify(root))
            print(reports[-1].text())
        return EXIT_OK if all(r.ok for r in reports) else EXIT_FAILED
    if args.action == "publish":
        if not args.out:
            raise DockfactoryError("dataset publish needs --out FOLDER")
        with writer_lock(args.out, "dataset publish"):   # one writer; a bad folder is one line, nothing written
            for root in args.dirs:
                print(published.publish(root, args.out))
        return EXIT_OK
    if args.action == "info":
        infos = [dt.info(root) for root in args.dirs]
        if args.json:
            print(json.dumps(infos[0] if len(infos) == 1 else infos, indent=1))
        else:
            print("\n".join(dt.info_text(d) for d in infos))
        return EXIT_OK
    if args.action == "diff":
        if len(args.dirs) != 2:
            raise DockfactoryError(f"dataset diff needs two directories DIR_A DIR_B, got {len(args.dirs)}")
        d = dt.diff(*args.dirs)
        print(json.dumps(d, indent=1) if args.json else dt.diff_text(d, *args.dirs))
        return EXIT_OK
    if args.action == "export":
        formats = [f.strip() for f in args.format.split(",")]
        unknown = [f for f in formats if f not in dt.EXPORT_WRITERS]
        if unknown:
            raise DockfactoryError(f"--format: unknown export format {unknown[0]!r} "
                                   f"(known: {', '.join(dt.EXPORT_WRITERS)})")
        for root in args.dirs:
            ds = dt.Dataset.open(root)   # every byte checked once for all its formats
            for fmt in formats:
                print(dt.export(root, fmt, ds))
        return EXIT_OK
    raise DockfactoryError(f"unknown dataset action {args.action!r}")


def cmd_check(args) -> int:

    cfg, _ = _load(args.config)
    plan = frame_plan(cfg)
    print(f"{args.config}: valid; dataset version {identity(cfg)['version_id']}, {len(plan)} frames")
    for (split, cond), n in sorted(Counter((s.split, s.condition) for s in plan).items()):
        print(f"  {split:7s} {cond:10s} {n}")
    return EXIT_OK


def cmd_show(args) -> int:
    out = draw_overlay(args.dataset, args.frame_id, args.out)
    print(out)
    return EXIT_OK


def add_subcommands(sub) -> None:
    """Register render, dataset, check-config and show on ``sub`` (argparse subparsers)."""

    r = sub.add_parser("render", help="render (the missing frames of) a dataset from a TOML config")
    r.add_argument("config", help="TOML config file, or the name of a shipped one (smoke, quick, paper, ideal, detector)")
    r.add_argument("--out", required=True, help="dataset directory")
    r.add_argument("--workers", type=int_at_least(1), default=1, help="render processes sharing the cores")
    r.add_argument("--shard", type=_shard, default=(1, 1), metavar="K/N",
                   help="render only shard K of N (frames with index %% N == K-1)")
    r.add_argument("--frames", help="comma-separated frame ids to render (default: all)")
    r.add_argument("--retries", type=int_at_least(0), default=2, help="retries of a frame whose worker crashed")
    r.add_argument("--recycle-after", type=int_at_least(1), default=100,
                   help="restart a worker after this many frames")
    r.add_argument("--executor", choices=("local", "ray"), default="local",
                   help="local worker processes, or actors on a Ray cluster")
    r.add_argument("--ray-address", default=None,
                   help="Ray cluster address (default: start a local Ray instance)")
    r.add_argument("--quiet", action="store_true", help="no progress display")
    r.set_defaults(func=cmd_render)

    d = sub.add_parser("dataset", help="verify, describe, compare or export datasets")
    d.add_argument("action", choices=("verify", "info", "diff", "export", "publish"))
    d.add_argument("dirs", nargs="+", metavar="DIR", help="dataset directories (verify, info, export: "
                   "each of them; diff: exactly two)")
    d.add_argument("--format", default="coco,yolo,bop", help="export: coco, yolo, bop (comma-separated)")
    d.add_argument("--json", action="store_true", help="info/diff: print JSON")
    d.add_argument("--manifest", help="verify: check a re-render (any subset of frames) against this published "
                   "manifest.json and the fingerprints(_v2).npz beside it")
    d.add_argument("--tolerance", type=float, default=published.DEFAULT_TOLERANCE,
                   help=f"verify --manifest: largest tile-mean difference (8-bit levels) of an image that is not "
                        f"byte for byte the published one (default {published.DEFAULT_TOLERANCE})")
    d.add_argument("--out", help="publish: folder for the verified dataset's manifest.json and its "
                   "fingerprints.npz, fingerprints_v2.npz")
    d.set_defaults(func=cmd_dataset)

    c = sub.add_parser("check-config", help="validate a config and print its plan")
    c.add_argument("config")
    c.set_defaults(func=cmd_check)

    s = sub.add_parser("show", help="draw a frame's labels over its image (PNG or JPEG, by the suffix of --out)")
    s.add_argument("dataset")
    s.add_argument("frame_id")
    s.add_argument("--out", required=True)
    s.set_defaults(func=cmd_show)
