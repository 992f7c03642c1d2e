"""Factory subcommands of ``dockfactory``: render, dataset, check-config, show (registered by the
root CLI, ``dockfactory.cli``). Heavy imports happen inside the commands."""
from __future__ import annotations

import json
import sys
from collections import Counter
from pathlib import Path

from dockfactory.cli_args import add_set_flag, int_at_least, output_path, shard_spec, tolerance_levels
from dockfactory.core.config import LICENSE_ID
from dockfactory.core.config_text import defaults_toml, load_config_text, to_toml
from dockfactory.core.errors import DockfactoryError
from dockfactory.core.resources import resolve_config, shipped_dataset_configs
from dockfactory.generator.datasets import tools as dt
from dockfactory.generator.datasets import published
from dockfactory.generator.datasets.folder import dataset_lock, identity, writer_lock
from dockfactory.generator.datasets.card import write_card
from dockfactory.generator.datasets.dvc_links import outside_note
from dockfactory.generator.exports import FORMATS, check_export_formats
from dockfactory.generator.label_overlay import draw_overlay
from dockfactory.generator.reference_render import REFERENCE_SAMPLES, reference_overrides
from dockfactory.generator.render_job import JobOptions, print_summary, run_render
from dockfactory.generator.sampler import check_focal_fits, frame_plan

EXIT_OK, EXIT_FAILED = 0, 1


def load_checked(path, sets=()):
    """(config, its text) of ``path`` with ``--set`` overrides ``sets``, its ``[export] formats``
    checked against the export registry (the generator's: core knows no format names) and the config
    checked feasible (every planned frame fits its markers: the check samples every frame's geometry),
    so both run here (render, run, check-config), not on every load."""
    cfg, text = load_config_text(resolve_config(path), sets)
    check_export_formats(cfg, str(path))
    check_focal_fits(cfg, str(path))
    return cfg, text


def cmd_render(args) -> int:
    sets = reference_overrides(args.reference, args.sets) if args.reference is not None else args.sets
    cfg, text = load_checked(args.config, sets)
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


def cmd_verify(args) -> int:
    """Each DIR verified (every byte), or checked against a published manifest."""
    reports = []
    for root in args.dirs:
        reports.append(published.verify_against(root, args.manifest, args.tolerance) if args.manifest
                       else dt.verify(root))
        print(reports[-1].text())
    return EXIT_OK if all(r.ok for r in reports) else EXIT_FAILED


def cmd_publish(args) -> int:
    with writer_lock(args.out, "dataset publish"):   # one writer; a bad folder is one line, nothing written
        for root in args.dirs:
            print(published.publish(root, args.out))
    return EXIT_OK


def cmd_info(args) -> int:
    infos = [dt.info(root) for root in args.dirs]
    if args.json:
        print(json.dumps(infos[0] if len(infos) == 1 else infos, indent=1))
    else:
        print("\n".join(dt.info_text(d) for d in infos))
    return EXIT_OK


def cmd_diff(args) -> int:
    """Exit like ``git diff --exit-code``: 0 identical, 1 different (2, bad input, by the CLI)."""
    d = dt.diff(args.dir_a, args.dir_b)
    print(json.dumps(d, indent=1) if args.json else dt.diff_text(d, args.dir_a, args.dir_b))
    return EXIT_OK if d["identical"] else EXIT_FAILED


def cmd_card(args) -> int:
    """Write each dataset's card (README.md) and Hugging Face view (hf/) again."""
    if args.license is not None and not LICENSE_ID.fullmatch(args.license):
        raise DockfactoryError(f"--license {args.license!r}: not a licence id (lower-case letters, digits, "
                               f"'.', '-', '+'; e.g. cc-by-4.0, cc0-1.0, mit, other)")
    for root in args.dirs:
        ds = dt.Dataset.open(root)   # every byte checked: the card describes an intact dataset
        with dataset_lock(root, "dataset card"):
            print(write_card(ds, args.license))
    return EXIT_OK


def format_names(text: str) -> list[str]:
    """The names of ``--format`` (comma-separated, spaces around a name ignored), each a format of the
    export registry; else a DockfactoryError naming the first unknown one."""
    formats = [f.strip() for f in text.split(",")]
    unknown = [f for f in formats if f not in dt.EXPORT_WRITERS]
    if unknown:
        raise DockfactoryError(f"--format: unknown export format {unknown[0]!r} "
                               f"(known: {', '.join(dt.EXPORT_WRITERS)})")
    return formats


def cmd_export(args) -> int:
    formats = format_names(args.format)
    if args.out is not None and len(args.dirs) > 1:
        raise DockfactoryError("--out: one dataset at a time (each export folder holds one dataset's formats)")
    for root in args.dirs:
        ds = dt.Dataset.open(root)   # every byte checked once for all its formats
        if args.out is None and outside_note(root):
            print(f"note: {outside_note(root)}", file=sys.stderr)
        for fmt in formats:
            print(dt.export(root, fmt, ds, args.out))
    return EXIT_OK


def cmd_check(args) -> int:
    if args.defaults:
        print(defaults_toml(), end="")
        return EXIT_OK
    if args.config is None:
        raise DockfactoryError("check-config needs a CONFIG (or --defaults)")
    cfg, _ = load_checked(args.config, args.sets)
    if args.resolved:
        print(to_toml(cfg.to_dict(full=True)), end="")
        return EXIT_OK
    plan = frame_plan(cfg)
    print(f"{args.config}: valid; dataset version {identity(cfg)['version_id']}, {len(plan)} frames")
    for (split, cond), n in sorted(Counter((s.split, s.condition) for s in plan).items()):
        print(f"  {split:7s} {cond:10s} {n}")
    return EXIT_OK


def cmd_show(args) -> int:
    out = draw_overlay(args.dataset, args.frame_id, args.out)
    print(out)
    return EXIT_OK


def _format_help() -> str:
    """Each format of the export registry with its summary (the ones ``[export] formats`` cannot name marked)."""
    marks = {True: " (on demand: not in [export] formats)", False: ""}
    return "; ".join(f"{name}: {fmt.summary}".replace("%", "%%") + marks[fmt.on_demand]
                     for name, fmt in FORMATS.items())


def _add_dataset_actions(d) -> None:
    """``dataset verify | info | diff | export | card | publish``, each its own parser: a flag of one
    action given to another is an error, not silently ignored."""
    acts = d.add_subparsers(dest="action", required=True, metavar="ACTION")
    v = acts.add_parser("verify", help="check every byte of each dataset, or a re-render against a published one")
    v.add_argument("dirs", nargs="+", metavar="DIR", help="dataset directories")
    v.add_argument("--manifest", help="check a re-render (any subset of frames) against this published "
                   "manifest.json and the fingerprints(_v2).npz beside it")
    v.add_argument("--tolerance", type=tolerance_levels, default=published.DEFAULT_TOLERANCE,
                   help=f"with --manifest: largest tile-mean difference (8-bit levels) of an image that is not "
                        f"byte for byte the published one (default {published.DEFAULT_TOLERANCE})")
    v.set_defaults(func=cmd_verify)
    i = acts.add_parser("info", help="what each dataset holds (version, frames, splits, cameras)")
    i.add_argument("dirs", nargs="+", metavar="DIR")
    i.add_argument("--json", action="store_true", help="print JSON")
    i.set_defaults(func=cmd_info)
    f = acts.add_parser("diff", help="compare two datasets file by file (size, sha256) and label by label; "
                                     "exit 0 identical, 1 different, 2 bad input")
    f.add_argument("dir_a", metavar="DIR_A")
    f.add_argument("dir_b", metavar="DIR_B")
    f.add_argument("--json", action="store_true", help="print JSON")
    f.set_defaults(func=cmd_diff)
    e = acts.add_parser("export", help="write exports of each dataset (under its exports/): COCO, YOLO, BOP, "
                                       "cameras, docking-run videos, ... (--format)")
    e.add_argument("dirs", nargs="+", metavar="DIR")
    e.add_argument("--format", default="coco,yolo,bop",
                   help=_format_help() + " (comma-separated; default coco,yolo,bop)")
    e.add_argument("--out", type=output_path, default=None, metavar="FOLDER",
                   help="write FOLDER/<format>/ outside the dataset (default: DIR/exports/; for a dataset "
                        "tracked by DVC whose project does not ignore exports/, T.exports/ beside its tracked folder T)")
    e.set_defaults(func=cmd_export)
    c = acts.add_parser("card", help="write each dataset's card (README.md) and Hugging Face view (hf/) again")
    c.add_argument("dirs", nargs="+", metavar="DIR")
    c.add_argument("--license", default=None, metavar="ID",
                   help="the data's licence in the card (default: the config's [dataset] license)")
    c.set_defaults(func=cmd_card)
    p = acts.add_parser("publish", help="verify a complete dataset and write its manifest and fingerprints")
    p.add_argument("dirs", nargs="+", metavar="DIR")
    p.add_argument("--out", type=output_path, required=True,
                   help="folder for manifest.json, fingerprints.npz, fingerprints_v2.npz")
    p.set_defaults(func=cmd_publish)


def add_subcommands(sub) -> None:
    """Register render, dataset, check-config and show on ``sub`` (argparse subparsers)."""

    r = sub.add_parser("render", help="render (the missing frames of) a dataset from a TOML config")
    r.add_argument("config", help="TOML config file, or the name of a shipped one "
                                  f"({', '.join(shipped_dataset_configs())})")
    r.add_argument("--out", type=output_path, required=True, help="dataset directory")
    r.add_argument("--workers", type=int_at_least(1), default=1, help="render processes sharing the cores")
    r.add_argument("--shard", type=shard_spec, default=(1, 1), metavar="K/N",
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
    r.add_argument("--reference", type=int_at_least(1), nargs="?", const=REFERENCE_SAMPLES, default=None, metavar="N",
                   help="render the converged reference for measuring: every marker crop pixel at N samples "
                        f"(default {REFERENCE_SAMPLES}), no denoiser or coverage correction there")
    add_set_flag(r)
    r.set_defaults(func=cmd_render)

    _add_dataset_actions(sub.add_parser("dataset", help="verify, describe, compare, export, card or publish datasets",
                                        description="One action per sub-command; each has its own flags "
                                                    "(dockfactory dataset ACTION --help)."))

    c = sub.add_parser("check-config", help="validate a config and print its plan (or its resolved TOML, or the defaults)")
    c.add_argument("config", nargs="?", help="TOML config file or a shipped config's name")
    c.add_argument("--resolved", action="store_true", help="print the resolved config (every key) as TOML")
    c.add_argument("--defaults", action="store_true", help="print every key with its default, type and meaning")
    add_set_flag(c)
    c.set_defaults(func=cmd_check)

    s = sub.add_parser("show", help="draw a frame's labels over its image (PNG or JPEG, by the suffix of --out)")
    s.add_argument("dataset")
    s.add_argument("frame_id")
    s.add_argument("--out", type=output_path, required=True)
    s.set_defaults(func=cmd_show)
