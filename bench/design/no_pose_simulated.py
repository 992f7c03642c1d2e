"""Frames without a pose, simulated per design (eval.design_refusals) against the rendered designs'
own: each card (one with ``no_pose_simulation``) predicts every rendered set of
bench.design.card_compare again, and each design's simulated refusals over its drawn test frames
stand beside the test frames its render left without a pose. Per card: the totals and the binomial
log-likelihood of the rendered counts under the simulated shares ((k + 1/2) / (n + 1), so a share
of 0 is not certainty) over the simulated designs, and the rendered refusals of the designs not
simulated (three-chip PNG: predicted none); over all designs and per scene (the demo scene ``quick``
and the wide one).

    python -m bench.design.no_pose_simulated --card k1=CARD.json [--card ...] [--json OUT]
"""
from __future__ import annotations

import argparse
import json
import math
import tempfile
from pathlib import Path

from bench.design.card_compare import RESULTS, SETS, predictions
from dockfactory.core.io import write_json_atomic


def rendered_counts() -> dict:
    """{design id: (test frames without a pose, test frames, scene, design)} of every rendered set."""
    out = {}
    for records, _ in SETS.values():
        for r in json.loads((RESULTS / records).read_text())["records"]:
            solved, n = (int(v) for v in r["solved"].split("/"))
            out[r["id"]] = (n - solved, n, "wide" if "wide" in r["scene"] else "quick", r["design"])
    return out


def per_design(pred: dict, rendered: dict) -> list[dict]:
    """One row per rendered design: its simulated and rendered frames without a pose."""
    rows = []
    for i, (k, n, scene, design) in rendered.items():
        nopose = pred[i][0].get("no_pose") or {}
        rows.append({"id": i, "design": design, "scene": scene, "rendered": k, "frames": n,
                     "simulated": nopose.get("simulated", 0), "refused": nopose.get("refused", 0)})
    return rows


def totals(rows: list[dict]) -> dict:
    """Refusals simulated and rendered, and the rendered counts' log-likelihood (module docstring)."""
    ll, simulated = 0.0, [r for r in rows if r["simulated"]]
    for r in simulated:
        p = (r["refused"] + 0.5) / (r["simulated"] + 1)
        ll += r["rendered"] * math.log(p) + (r["frames"] - r["rendered"]) * math.log(1 - p)
    return {"designs": len(rows), "simulated_refused": sum(r["refused"] for r in rows),
            "simulated_frames": sum(r["simulated"] for r in rows),
            "rendered_refused": sum(r["rendered"] for r in simulated), "log_likelihood": round(ll, 1),
            "not_simulated": len(rows) - len(simulated),
            "not_simulated_rendered_refused": sum(r["rendered"] for r in rows if not r["simulated"])}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--card", action="append", required=True, metavar="NAME=PATH")
    ap.add_argument("--json", type=Path)
    args = ap.parse_args(argv)
    rendered, res = rendered_counts(), {}
    spaces = [s for _, group in SETS.values() for s in group]
    with tempfile.TemporaryDirectory() as tmp:
        for c in args.card:
            name, path = c.split("=", 1)
            rows = per_design(predictions(Path(path).resolve(), spaces, Path(tmp) / name), rendered)
            res[name] = {"designs": rows, "all": totals(rows),
                         **{s: totals([r for r in rows if r["scene"] == s]) for s in ("quick", "wide")}}
    print("| card | designs simulated (not: refused rendered) | frames without a pose: simulated / rendered | "
          "log-likelihood | quick | wide |\n| --- | --- | --- | --- | --- | --- |")
    for name, r in res.items():
        a, q, w = r["all"], r["quick"], r["wide"]
        print(f"| {name} | {a['designs'] - a['not_simulated']} ({a['not_simulated']}: {a['not_simulated_rendered_refused']}) | "
              f"{a['simulated_refused']} / {a['rendered_refused']} | {a['log_likelihood']} | "
              f"{q['simulated_refused']} / {q['rendered_refused']} ({q['log_likelihood']}) | "
              f"{w['simulated_refused']} / {w['rendered_refused']} ({w['log_likelihood']}) |")
    if args.json:
        write_json_atomic(args.json, res)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
