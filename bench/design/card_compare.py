"""Cards side by side on every design already rendered: each card predicts the designs again (no
render) and is judged against the rendered figures committed under bench/results/design/.

A rendered set is a records file of bench.design.design_verify (``--json``) and the design spaces
its designs came from; a design is matched by its id. Per card and set: the median of
|predicted / rendered - 1| per component and the outcomes agreeing (the localization block's
predicted pass / fail / undecided against the rendered guarded decision); then over every set.
Used to choose between cards before a blind set (a card is shipped on designs it has not seen).

    python -m bench.design.card_compare --card shipped=models/design_predictor.json \\
        --card candidate=bench/results/design/card_luma_candidate.json [--json OUT]
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from bench.design.design_verify import _predicted
from dockfactory.core.io import write_json_atomic

ROOT = Path(__file__).resolve().parents[2]
RESULTS = ROOT / "bench" / "results" / "design"
SETS = {   # name: (records file under RESULTS, the design spaces under bench/configs/)
    "held-out 16": ("verify_48_luma.json", ("design_verify_quick_48", "design_verify_wide_48")),
    "blind 1 (12)": ("confirm_12_luma.json", ("design_confirm_quick", "design_confirm_wide", "design_confirm_wide2")),
    "blind 3 (12)": ("confirm3_12.json", ("design_confirm3_quick", "design_confirm3_wide", "design_confirm3_wide3")),
    "blind 4 (12)": ("confirm4_12.json", ("design_confirm4_quick", "design_confirm4_quick2", "design_confirm4_wide")),
    "blind 5 (12)": ("confirm5_12.json", ("design_confirm5_quick", "design_confirm5_wide", "design_confirm5_wide2")),
    "blind 6 (12)": ("confirm6_12.json", ("design_confirm6_quick", "design_confirm6_quick2", "design_confirm6_wide")),
    "blind 7 (12)": ("confirm7_12.json", ("design_confirm7_quick", "design_confirm7_quick2", "design_confirm7_wide")),
    "blind 8 (12)": ("confirm8_12.json", ("design_confirm8_quick", "design_confirm8_quick2", "design_confirm8_wide")),
}
# Sets' renders judged again with a later refinement, camera classes or solver (not in "all": the
# same designs as their blind sets; the sets a card is chosen on before the next blind set).
REJUDGED = {
    "blind 6 re-judged (12)": ("confirm6_classes.json", SETS["blind 6 (12)"][1]),
    # the sixth and seventh sets' renders solved and judged again at the boxes' shortfall
    "blind 6-7 at the shortfall (24)": ("confirm67_shortfall.json", SETS["blind 6 (12)"][1] + SETS["blind 7 (12)"][1]),
}
COMPS = ("x", "y", "alpha")


def predictions(card: Path, spaces, work: Path) -> dict:
    """{design id: (row, min probability)} of ``spaces`` predicted by ``card`` (into ``work``)."""
    out = {}
    for space in spaces:
        dest = work / space
        subprocess.run([sys.executable, "-m", "dockfactory", "design", str(ROOT / "bench" / "configs" / f"{space}.toml"),
                        "--card", str(card), "--out", str(dest)], check=True, capture_output=True)
        d = json.loads((dest / "design.json").read_text())
        out.update({r["id"]: (r, d["min_probability"]) for r in d["designs"]})
    return out


def judged(records: list[dict], pred: dict) -> list[dict]:
    """Per rendered record: its design, ratios predicted / rendered per component, outcomes."""
    rows = []
    for rec in records:
        row, min_p = pred[rec["id"]]
        status = _predicted(row, min_p) if row["status"] not in ("infeasible", "not predicted") else row["status"]
        rows.append({"design": rec["design"], "predicted": status, "rendered": rec["rendered_decision"],
                     **{c: row["predicted_rmse"][c] / rec[c]["rendered"] for c in COMPS}})
    return rows


def summary(rows: list[dict]) -> dict:
    dev = np.abs(np.array([[r[c] for c in COMPS] for r in rows]) - 1.0)
    return {**{c: float(np.median(dev[:, i])) for i, c in enumerate(COMPS)},
            "agree": sum(r["predicted"] == r["rendered"] for r in rows), "of": len(rows)}


def compare(cards: dict, work: Path) -> dict:
    out = {}
    for name, path in cards.items():
        every, sets = [], {}
        for set_name, (records, spaces) in SETS.items():
            rows = judged(json.loads((RESULTS / records).read_text())["records"],
                          predictions(path, spaces, work / name / set_name.split()[0]))
            sets[set_name] = summary(rows)
            every += rows
        for set_name, (records, spaces) in REJUDGED.items():
            sets[set_name] = summary(judged(json.loads((RESULTS / records).read_text())["records"],
                                            predictions(path, spaces, work / name / set_name.replace(" ", "_"))))
        out[name] = {"sets": sets, "all": summary(every),
                     "disagree": [r for r in every if r["predicted"] != r["rendered"]]}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--card", action="append", required=True, metavar="NAME=PATH")
    ap.add_argument("--json", type=Path)
    args = ap.parse_args(argv)
    cards = {c.split("=", 1)[0]: Path(c.split("=", 1)[1]).resolve() for c in args.card}
    with tempfile.TemporaryDirectory() as tmp:
        res = compare(cards, Path(tmp))
    print("| card | set | median abs(pred / rendered - 1) X / Y / alpha | outcomes agreeing |\n| --- | --- | --- | --- |")
    for name, r in res.items():
        for set_name, s in [*r["sets"].items(), ("all", r["all"])]:
            print(f"| {name} | {set_name} | {100 * s['x']:.0f} / {100 * s['y']:.0f} / {100 * s['alpha']:.0f} % | {s['agree']} of {s['of']} |")
        for d in r["disagree"]:
            print(f"  {name} disagrees: {d['design']}: {d['predicted']} -> {d['rendered']} "
                  f"({d['x']:.2f} / {d['y']:.2f} / {d['alpha']:.2f})")
    if args.json:
        write_json_atomic(args.json, res)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
