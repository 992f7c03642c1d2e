"""``dockfactory design``: which camera, lens and markers pass? Every design of a space predicted
(eval.design_rank), ranked, written as design.json / .md / .html (eval.design_report), and with
``--verify K`` the top K rendered and judged beside their predictions (design_verify)."""
from __future__ import annotations

import argparse
import time
from pathlib import Path

from dockfactory.cli_args import float_in, output_path, positive_int
from dockfactory.core.io import check_output_folder
from dockfactory.core.config import load_config
from dockfactory.design_jobs import default_jobs, design_rows
from dockfactory.design_verify import comparison_lines, verify_designs
from dockfactory.core.resources import (
    default_acceptance,
    resolve_config,
    resolve_design_space,
    shipped_design_card,
    shipped_design_refusals,
)
from dockfactory.eval.acceptance import load_acceptance
from dockfactory.eval.design_card import load_design_card, with_refusals
from dockfactory.eval.design_rank import design_id, rank_rows
from dockfactory.eval.design_report import table_lines, write_design_outputs
from dockfactory.eval.design_space import designs_of, load_design_space

NOTES = ("Predicted for frames in normal light: occlusion and glare add errors the predictor does not model.",)
NO_POSE_NOTE = ("P(accept) covers the gated pose criteria (chi-square bound, components independent) and every test "
                "frame and capture getting a pose (a frame without one fails its block and the failure gate), each "
                "frame left without a pose at the card's share for its camera class and image format, measured on "
                "the sensor bench's scenes: a design's own geometry can refuse more. The detection gates are not "
                "predicted: --verify renders and judges them.")
SIM_POSE_NOTE = ("P(accept) covers the gated pose criteria (chi-square bound, components independent) and every test "
                 "frame and capture getting a pose (a frame without one fails its block and the failure gate), each "
                 "frame left without a pose at the share of the design's own drawn frames its predicted centres "
                 "(with the card's tail per camera class) leave refused by the solver's gate (not simulated for a "
                 "design its pose errors already fail). The detection gates are not predicted: --verify renders "
                 "and judges them.")
NO_NO_POSE_NOTE = ("P(accept) covers the gated pose criteria (chi-square bound, components independent); frames "
                   "without a pose, the detection and failure gates are not predicted: --verify renders and judges them.")
SENSOR_NOTE = ("The sensor's temporal noise enters as the card's share of the centre variance scaled by the sensor's "
               "relative noise at mid grey (EMVA preset, or the scene's plain sensor); its fixed patterns, gain and "
               "exposure are not terms.")
NO_SENSOR_NOTE = ("The sensor's temporal noise (EMVA preset) is not a term of this card: it enters only through "
                  "the renders of --verify.")


def _jpeg_summary(table: dict) -> str:
    """The JPEG factors per ring, monochrome / Bayer: "3.9 / 4.1 dark, 2.7 / 1.6 white"."""
    return ", ".join(f"{t['none']:g} / {t['rggb']:g} {ring}" for ring, t in table.items())


def _card_summary(card) -> str:
    fitted = card.data.get("fitted_on", {})
    law = card.law
    noise = ("centre noise as the solver weighs it" if law is None else
             f"centre noise variance (10 / b)^{law.minor_exponent:g} + {law.floor:g} + "
             f"{law.ring_coefficient:g} (1.5 / w)^{law.ring_exponent:g} (b minor semi-axis, w ring width, px)")
    size = (card.size_exponent or {}).get("rggb", 0.0)
    bayer = f"Bayer x{card.cfa_factor['rggb']}" + (f" (10 / b)^{size:g}" if size else "")
    above = "".join(f", JPEG q{q}+ x{_jpeg_summary(t)}" for q, t in sorted((card.jpeg_above or {}).items()))
    sensor = ("" if not card.sensor_share else
              f", sensor share {card.sensor_share['none']:g} / {card.sensor_share['rggb']:g} of {card.sensor_reference}'s")
    return (f"{noise}, scale {card.scale_px} px, section offset {list(card.shift_px)} px, "
            f"{bayer}, JPEG q{card.jpeg_min_quality}+ x{_jpeg_summary(card.jpeg_factor)}{above}, "
            f"white ring x{card.ring_factor['white']['none']} (Bayer x{card.ring_factor['white']['rggb']}){sensor}; "
            f"fitted on {len(fitted.get('renders', []))} renders of {fitted.get('frames_each', '?')} frames; "
            f"provisional: {', '.join(card.provisional) or 'none'}")


def design_answer(args) -> tuple[dict, dict, object, object, Path]:
    """(result, designs by id, space, scene config, spec path) of ``args``."""
    t0 = time.monotonic()
    space = load_design_space(resolve_design_space(args.space), resolve_config)
    scene = load_config(space.scene)
    spec_path = space.spec or default_acceptance()
    spec = load_acceptance(spec_path)
    card = load_design_card(args.card or shipped_design_card())
    if args.refusals:
        card = with_refusals(card, shipped_design_refusals())
    designs = designs_of(space, scene)
    pose_note = SIM_POSE_NOTE if card.no_pose_gate else NO_POSE_NOTE if card.no_pose else NO_NO_POSE_NOTE
    notes = [*NOTES, pose_note, SENSOR_NOTE if card.sensor_share else NO_SENSOR_NOTE]
    if spec.estimation.thresholds() and not space.repeatability[0]:
        notes.append("The spec gates repeatability but the space gives no repeatability captures: "
                     "P(accept) covers localization only ([design] repeatability_poses / _captures).")
    rows = rank_rows(design_rows(designs, space, scene, spec, card, args.min_probability, args.jobs or default_jobs()),
                     args.min_probability)
    result = {"format": "dockfactory.design/1", "space": space.source, "scene": str(space.scene),
              "spec": str(spec_path), "decision_rule": spec.decision_rule, "confidence": spec.confidence,
              "test_frames": space.test_frames, "repeatability": list(space.repeatability),
              "min_probability": args.min_probability, "seconds": round(time.monotonic() - t0, 2),
              "card": {"path": card.path, "summary": _card_summary(card)}, "notes": notes,
              "designs": rows}
    return result, {design_id(d): d for d in designs}, space, scene, spec_path


def cmd_design(args) -> int:
    check_output_folder(args.out)   # before any work: a bad --out loses no prediction
    result, by_id, space, scene, spec_path = design_answer(args)
    print("\n".join(table_lines(result["designs"], args.top)))
    print(f"{len(result['designs'])} designs predicted in {result['seconds']:.1f} s")
    paths = write_design_outputs(args.out, result)   # the predictions stand before any render
    if args.verify:
        result["verify"] = verify_designs(result["designs"], by_id, space, scene, spec_path, args.out,
                                          args.verify, args.verify_frames, args.weights, args.workers)
        print("\n".join(comparison_lines(result["verify"])))
        paths = write_design_outputs(args.out, result)
    print("wrote " + ", ".join(str(p) for p in paths))
    return 0


def add_subcommand(sub) -> None:
    p = sub.add_parser("design", help="which camera, lens and markers pass: every design of a space "
                                      "predicted against the tolerance, ranked (--verify K: rendered)")
    p.add_argument("space", help="design space TOML (docs/design.md), or a shipped one by name "
                                 "(docking_cell)")
    p.add_argument("--out", type=output_path, default="out/design",
                   help="folder for design.json / .md / .html (default out/design)")
    p.add_argument("--top", type=positive_int, default=15, help="designs shown in the table (default 15)")
    p.add_argument("--min-probability", type=float_in(0.0, 1.0, low_open=True), default=0.9,
                   help="P(accept) a passing design needs (default 0.9)")
    p.add_argument("--card", help="a predictor card (default: the shipped models/design_predictor.json)")
    p.add_argument("--refusals", action=argparse.BooleanOptionalAction, default=True,
                   help="predict the frames the solver's gate leaves without a pose, each design's drawn frames "
                        "simulated through it (models/design_refusals.json; the default; --no-refusals: not "
                        "predicted, a design's P(accept) then covers its pose errors alone)")
    p.add_argument("--jobs", type=positive_int, default=None,
                   help="processes predicting the designs (default: one per core; the answer is the same for any)")
    p.add_argument("--verify", type=positive_int, default=0, metavar="K",
                   help="render and judge the top K designs (dockfactory run each; minutes per design)")
    p.add_argument("--verify-frames", type=positive_int, default=24,
                   help="test frames rendered per verified design (default 24)")
    p.add_argument("--weights", help="detector weights for --verify (default: the shipped ones)")
    p.add_argument("--workers", type=positive_int, default=1, help="render workers for --verify")
    p.set_defaults(func=cmd_design)
