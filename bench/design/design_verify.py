"""Predicted against rendered, over every verified design of one or more ``dockfactory design
--verify`` folders: the table of bench/results/design/README.md and the issue's figures.

Per design: predicted and rendered RMSE of X, Y, alpha (test frames), their ratio, the predicted
localization status (P >= the run's min probability) and the rendered localization decision
(the guarded rule on the rendered frames). Summary: per component the median and worst of
|predicted / rendered - 1|, and the share of designs whose predicted outcome (pass: P(accept) at
least the run's min probability, fail: P(reject) at least it, else undecided) is the rendered
one.

The rendered RMSE over n frames has its own sampling error, about 1 / sqrt(2 n) relative (14 %
at 24 frames): the table prints the chi-square 95 % interval of each rendered RMSE beside it.

Run: python -m bench.design.design_verify out/design_verify/quick out/design_verify/wide [--json OUT]
     [--predicted-by out/card/quick out/card/wide]   # the same renders, another card's predictions
"""
from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

from dockfactory.core.io import write_json_atomic
from dockfactory.design_verify import block_decision
from dockfactory.eval.confidence import chi2_bounds

COMPS = ("x", "y", "alpha")


def _predicted(row: dict, min_p: float) -> str:
    """pass / fail / undecided of the localization block alone (what the renders decide), with
    P(every test frame posed) of the row's ``no_pose`` (1 for a design.json written before it)."""
    loc = row["localization"].values()
    posed = (row.get("no_pose") or {}).get("p_all_test_posed", 1.0)
    if math.prod(v["probability"] for v in loc) * posed >= min_p:
        return "pass"
    if 1 - posed * math.prod(1 - v["reject_probability"] for v in loc) >= min_p:
        return "fail"
    return "undecided"


def records(folder: Path, predicted_by: Path | None = None) -> list[dict]:
    """One record per design of ``folder``/design.json whose run finished; ``predicted_by`` another
    ``design`` folder of the same space (run without --verify, e.g. with another predictor card)
    whose design.json gives the predictions instead (the designs matched by id)."""
    result = json.loads(((predicted_by or folder) / "design.json").read_text())
    out = []
    for row in result["designs"]:
        metrics = folder / "verify" / row["id"] / "run" / "eval" / "metrics.json"
        if not metrics.is_file():
            continue
        m = json.loads(metrics.read_text())
        loc = m["localization"]
        n = loc["n_solved"]
        rec = {"scene": folder.name, "id": row["id"], "design": row["design"], "frames": n,
               "solved": f"{n}/{loc['n_frames']}",
               "predicted_status": _predicted(row, result["min_probability"]),
               "p_localization": row["p_localization"],
               "rendered_decision": block_decision(m["acceptance"]["criteria"], "localization") or "-"}
        for c in COMPS:
            r = loc["overall"][c]["rmse"]
            lo, hi = chi2_bounds(n * r * r, n, 0.975)
            rec[c] = {"predicted": row["predicted_rmse"][c], "rendered": r, "ratio": row["predicted_rmse"][c] / r,
                      "rendered_95": [lo, hi]}
        out.append(rec)
    return out


def summary(recs: list[dict]) -> dict:
    out = {"designs": len(recs)}
    for c in COMPS:
        dev = sorted(abs(r[c]["ratio"] - 1) for r in recs)
        worst = max(recs, key=lambda r: abs(r[c]["ratio"] - 1))
        out[c] = {"median_abs_dev": dev[len(dev) // 2] if len(dev) % 2 else (dev[len(dev) // 2 - 1] + dev[len(dev) // 2]) / 2,
                  "worst_ratio": worst[c]["ratio"], "worst_design": f"{worst['scene']}: {worst['design']}"}
    agree = [r for r in recs if r["predicted_status"] == r["rendered_decision"]]
    out["agreement"] = {"agree": len(agree), "of": len(recs),
                        "disagree": [f"{r['scene']}: {r['design']} (P {r['p_localization']:.2f}, rendered "
                                     f"{r['rendered_decision']})" for r in recs if r not in agree]}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("folders", nargs="+", type=Path)
    ap.add_argument("--json", type=Path)
    ap.add_argument("--predicted-by", nargs="+", type=Path, default=None,
                    help="one design folder per folder: its predictions (the same space, another card)")
    args = ap.parse_args()
    if args.predicted_by is not None and len(args.predicted_by) != len(args.folders):
        ap.error("--predicted-by takes one folder per verified folder")
    recs = [r for k, f in enumerate(args.folders)
            for r in records(f, None if args.predicted_by is None else args.predicted_by[k])]
    print("| scene | design | X pred / rendered [95 %] | Y | alpha | P loc | rendered |\n| --- | --- | --- | --- | --- | --- | --- |")
    for r in recs:
        cells = [f"{r[c]['predicted']:.3g} / {r[c]['rendered']:.3g} [{r[c]['rendered_95'][0]:.3g}-"
                 f"{r[c]['rendered_95'][1]:.3g}] ({r[c]['ratio']:.2f})" for c in COMPS]
        print(f"| {r['scene']} | {r['design'].replace('|', '/')} | " + " | ".join(cells)
              + f" | {r['p_localization']:.2f} | {r['rendered_decision']} |")
    s = summary(recs) if recs else {"designs": 0}
    print(json.dumps(s, indent=1))
    if args.json:
        write_json_atomic(args.json, {"records": recs, "summary": s})


if __name__ == "__main__":
    main()
