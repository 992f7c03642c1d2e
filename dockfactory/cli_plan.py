"""``dockfactory plan-frames``: how many test frames would prove conformance (eval.frame_planner)."""
from __future__ import annotations

import math

from dockfactory.cli_args import float_in, positive_int
from dockfactory.core.config import load_config
from dockfactory.core.errors import DockfactoryError
from dockfactory.core.names import COMPONENTS
from dockfactory.core.resources import default_acceptance, resolve_config
from dockfactory.eval.acceptance import load_acceptance
from dockfactory.eval.frame_planner import expected_from_config, plan_frames, plan_lines
from dockfactory.solver.checks import MAX_SIGMA_PX


def parse_figures(items, flag: str) -> dict[str, float]:
    """``["x=0.4", "alpha=0.02"]`` -> {"x": 0.4, "alpha": 0.02}; a component named twice, an
    unknown one, or a value that is not a finite number > 0 is a one-line DockfactoryError."""
    out: dict[str, float] = {}
    for item in items or ():
        name, sep, text = item.partition("=")
        name = name.strip()
        if not sep or name not in COMPONENTS:
            raise DockfactoryError(f"{flag}: expected COMPONENT=VALUE with a component of {', '.join(COMPONENTS)}, "
                                   f"got {item!r}")
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not (math.isfinite(value) and value > 0):
            raise DockfactoryError(f"{flag}: {name}: expected a finite number > 0 (mm or deg), got {text!r}")
        if name in out:
            raise DockfactoryError(f"{flag}: {name} is given twice")
        out[name] = value
    return out


def expected_figures(args) -> dict:
    """{"localization": {...}, "estimation": {...}} from --rmse / --spread, or from --config's
    geometry at --centre-noise (both blocks), never both ways."""
    given = {"localization": parse_figures(args.rmse, "--rmse"), "estimation": parse_figures(args.spread, "--spread")}
    if args.config is not None:
        if any(given.values()):
            raise DockfactoryError("plan-frames: give --config (with --centre-noise) or --rmse / --spread, not both")
        if args.centre_noise is None:
            raise DockfactoryError("plan-frames: --config needs --centre-noise PX (the detector's centre noise)")
        bound = expected_from_config(load_config(resolve_config(args.config)), args.centre_noise, args.bound_factor,
                                     args.max_frames)
        return {"localization": bound, "estimation": bound}
    if args.centre_noise is not None:
        raise DockfactoryError("plan-frames: --centre-noise needs --config (the geometry it is propagated through)")
    figures = {block: f for block, f in given.items() if f}
    if not figures:
        raise DockfactoryError("plan-frames: give --rmse COMPONENT=VALUE (and/or --spread), or --config with "
                               "--centre-noise")
    return figures


def cmd_plan_frames(args) -> int:
    spec = load_acceptance(args.spec if args.spec is not None else default_acceptance())
    rows = plan_frames(spec, expected_figures(args))
    if spec.decision_rule != "guarded":
        print("plan-frames: the spec's rule is simple (the value alone decides); the counts are the guarded rule's")
    print("\n".join(plan_lines(rows)))
    return 0


def add_subcommand(sub) -> None:
    p = sub.add_parser("plan-frames", help="how many test frames (repeatability captures) prove conformance at the "
                                           "spec's confidence under the guarded rule")
    p.add_argument("spec", nargs="?", help="acceptance spec TOML (default: the shipped configs/acceptance.toml)")
    p.add_argument("--rmse", action="append", metavar="C=V",
                   help="expected localization RMSE of a component (mm or deg), e.g. --rmse x=0.4 --rmse alpha=0.02")
    p.add_argument("--spread", action="append", metavar="C=V",
                   help="expected repeatability spread of a component (mm or deg)")
    p.add_argument("--config", help="a dataset config: its test frames' geometry gives the expected figures "
                                    "(Cramer-Rao bound at --centre-noise)")
    p.add_argument("--centre-noise", type=float_in(0.0, MAX_SIGMA_PX, low_open=True), metavar="PX",
                   help="centre noise per axis, px (with --config)")
    p.add_argument("--bound-factor", type=float_in(1.0, 100.0), default=1.0,
                   help="expected RMSE over the Cramer-Rao bound (default 1; measured ratios of real "
                        "solves: docs/acceptance.md)")
    p.add_argument("--max-frames", type=positive_int, default=200,
                   help="test frames of --config whose bounds are averaged (default 200)")
    p.set_defaults(func=cmd_plan_frames)
