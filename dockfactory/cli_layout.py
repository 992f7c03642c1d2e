"""``dockfactory layout``: write a layout file (the measured markers ``measure``, ``solve`` and
``evaluate`` take with ``--layout``) from a CSV of measured coordinates, or from a config's
factory scene. Both are checked as every layout file is before anything is written.
``dockfactory schema``: the JSON Schema of the factory's file formats (the labels), for the
user's own tools."""
from __future__ import annotations

import json
from pathlib import Path

from dockfactory.cli_args import float_in, output_path
from dockfactory.core.config import load_config
from dockfactory.core.io import write_text_atomic
from dockfactory.core.label_schema import SCHEMAS
from dockfactory.core.layout_csv import SURFACES, UNITS_MM, layout_from_csv, write_layout
from dockfactory.core.layout_file import MAX_SIGMA_MM
from dockfactory.core.resources import resolve_config
from dockfactory.generator.datasets.folder import layout_record


def _summary(out: Path, markers, layout: dict) -> str:
    counts = ", ".join(f"{s} {sum(m.section == s for m in markers)}" for s in ("A", "B"))
    sigma = f"; sigma {layout['sigma_mm']:g} mm" if "sigma_mm" in layout else ""
    own = sum("sigma_mm" in m for m in layout["markers"])
    return f"{out}: {len(markers)} markers ({counts}){sigma}" + (f"; {own} with their own sigma" if own else "") \
        + ": checked as a layout file"


def cmd_from_csv(args) -> int:
    layout = layout_from_csv(args.csv, args.units, args.surface, args.sigma_mm)
    markers = write_layout(layout, args.out, str(args.csv))
    print(_summary(Path(args.out), markers, layout))
    return 0


def cmd_from_config(args) -> int:
    layout = layout_record(load_config(resolve_config(args.config)))
    markers = write_layout(layout, args.out, str(args.config))
    print(_summary(Path(args.out), markers, layout))
    return 0


def add_subcommand(sub) -> None:
    """Register ``layout from-csv`` and ``layout from-config`` on ``sub`` (argparse subparsers)."""
    p = sub.add_parser("layout", help="write a layout file from measured marker coordinates (CSV) or a config",
                       description="One action per sub-command (dockfactory layout ACTION --help).")
    actions = p.add_subparsers(dest="action", required=True)
    c = actions.add_parser("from-csv", help="a layout file from a CSV of measured markers (CMM, laser tracker)",
                           description="Columns: id, section, x, y, z, diameter; optional nx, ny, nz (else the "
                                       "surface's normal), index, sigma_mm. docs/measure.md, 'Your markers'.")
    c.add_argument("csv", help="the marker table (a header row, one row per marker)")
    c.add_argument("--out", type=output_path, required=True, help="the layout file to write (JSON)")
    c.add_argument("--units", choices=tuple(UNITS_MM), default="mm", help="unit of coordinates, diameters, sigmas")
    c.add_argument("--surface", choices=SURFACES, default="cylinder",
                   help="the normal of a row without nx, ny, nz: the outward radial of a cylinder about X")
    c.add_argument("--sigma-mm", type=float_in(0.0, MAX_SIGMA_MM), default=None,
                   help="1-sigma uncertainty of every coordinate (mm), carried into the uncertainty budget")
    c.set_defaults(func=cmd_from_csv)
    f = actions.add_parser("from-config", help="the layout file of a config's factory scene")
    f.add_argument("config", help="TOML config file or a shipped config's name")
    f.add_argument("--out", type=output_path, required=True, help="the layout file to write (JSON)")
    f.set_defaults(func=cmd_from_config)


def cmd_schema(args) -> int:
    text = json.dumps(SCHEMAS[args.format], indent=1) + "\n"
    if args.out:
        write_text_atomic(args.out, text)
    else:
        print(text, end="")
    return 0


def add_schema_subcommand(sub) -> None:
    """Register ``schema FORMAT [--out FILE]`` on ``sub``."""
    p = sub.add_parser("schema", help="the JSON Schema of a file format (labels): print it or write it")
    p.add_argument("format", choices=tuple(SCHEMAS), help="labels: labels/<frame_id>.json")
    p.add_argument("--out", type=output_path, default=None, help="write it here (default: standard output)")
    p.set_defaults(func=cmd_schema)
