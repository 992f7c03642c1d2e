"""The share of honest frames each camera class leaves without a pose: the predictor card's
``no_pose_rate`` (eval.design_card), measured on the sensor bench's frames solved as measure
solves them.

Input: results of bench.verdict.gate_classes run with ``--class-gate`` and the fault "as is" (the
honest frames), over any number of scenes. Per camera class and image format (the bench effect's:
``three-chip`` -> png / none, ``bayer-bilinear`` and ``bayer-vng`` -> png / rggb,
``three-chip-jpegQ`` -> jpegQ / none, ``bayer-jpegQ`` -> jpegQ / rggb), pooled over the scenes:
frames, frames without a pose (refused by the fit gate or unsolved), the share and its 95 % Wilson
interval, and the share per scene (the spread a pooled figure hides). With ``--card`` the pooled
shares are written into that card (atomically; its other figures untouched) with their source.

    python -m bench.design.no_pose_rates GATE.json [GATE.json ...] [--card models/design_predictor.json]
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

from bench.detector.centre_quality import wilson
from dockfactory.core.io import write_json_atomic

ROOT = Path(__file__).resolve().parents[2]

__all__ = ["effect_class", "pooled_rates"]


def effect_class(effect: str) -> tuple[str, str] | None:
    """(image format, cfa) of a sensor bench effect, None for an effect no design has (blur,
    the RGGB sampling alone)."""
    cfa = "rggb" if effect.startswith("bayer") else "none" if effect.startswith("three-chip") else None
    if cfa is None:
        return None
    tail = effect.rsplit("-", 1)[-1]
    if tail.startswith("jpeg") and tail[4:].isdigit():
        return tail, cfa
    return ("png", cfa) if effect in ("three-chip", "bayer-bilinear", "bayer-vng") else None


def pooled_rates(tables: list[dict]) -> dict:
    """{(format, cfa): {"frames", "without", "rate", "wilson95", "per_scene": {dataset: rate}}} over
    the "as is" rows of gate_classes ``tables`` (each row: dataset, effect, fault, frames, ok)."""
    out: dict = {}
    for row in tables:
        key = effect_class(row["effect"])
        if key is None or row["fault"] != "as is":
            continue
        e = out.setdefault(key, {"frames": 0, "without": 0, "per_scene": {}})
        e["frames"] += row["frames"]
        e["without"] += row["frames"] - row["ok"]
        s = e["per_scene"].setdefault(row["dataset"], [0, 0])
        s[0] += row["frames"] - row["ok"]
        s[1] += row["frames"]
    for e in out.values():
        e["rate"] = e["without"] / e["frames"]
        e["wilson95"] = wilson(e["without"], e["frames"])
        e["per_scene"] = {d: k / n for d, (k, n) in e["per_scene"].items()}
    return out


def card_table(rates: dict) -> dict:
    """The card's ``no_pose_rate``: {format: {"none": share, "rggb": share}} for the formats
    measured through both camera classes."""
    formats = sorted({f for f, _ in rates})
    return {f: {c: round(rates[(f, c)]["rate"], 4) for c in ("none", "rggb")}
            for f in formats if (f, "none") in rates and (f, "rggb") in rates}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("results", nargs="+", type=Path, help="bench.verdict.gate_classes --class-gate outputs")
    ap.add_argument("--card", type=Path, default=None, help="write the shares into this predictor card")
    args = ap.parse_args()
    tables = [row for f in args.results for row in json.loads(f.read_text())["tables"]]
    rates = pooled_rates(tables)
    print("| format | camera | frames | without a pose | share [95 %] | per scene |\n| --- | --- | --- | --- | --- | --- |")
    for (fmt, cfa), e in sorted(rates.items()):
        lo, hi = e["wilson95"]
        scenes = ", ".join(f"{d.split('@')[0].replace('sensor-scene-', '')} {100 * r:.1f}" for d, r in e["per_scene"].items())
        print(f"| {fmt} | {cfa} | {e['frames']} | {e['without']} | {100 * e['rate']:.2f} % [{100 * lo:.2f}-{100 * hi:.2f}] | {scenes} |")
    if args.card:
        card = json.loads(args.card.read_text())
        card["no_pose_rate"] = card_table(rates)
        card.setdefault("fitted_on", {})["no_pose_source"] = [
            str(f.resolve().relative_to(ROOT)) if f.resolve().is_relative_to(ROOT) else str(f) for f in args.results]
        write_json_atomic(args.card, card)
        print(f"{args.card}: no_pose_rate {card['no_pose_rate']}")


if __name__ == "__main__":
    main()
