"""The refined centres' heavy tail per camera class and image format, from the sensor bench's rows:
the contaminated normal (a share eps of the centres m times noisier than the rest) that best
explains each class's centre errors, for the simulated refusals (eval.design_refusals, a card's
``no_pose_simulation.tail``).

    python -m bench.design.centre_tails ROWS.json [ROWS.json ...] [--card CARD.json --card-out OUT.json]
                                        [--json OUT]

ROWS: results of bench.sensor.sensor_effects (its per-frame rows: each matched centre's error,
refined minus the label's outline centroid). Per effect and dataset the errors (both axes) are
taken over their robust sigma (1.4826 x the median absolute deviation); pooled over the datasets,
(eps, m, core) maximise the likelihood on a grid (eps 0 and 0.005-0.5, m 1.5-40, core 0.6-1.2 of
the robust sigma). ``--card`` writes the table into a copy of a card that has a
``no_pose_simulation`` section. The effects a design has (eval.design_space: PNG, JPEG; monochrome
or Bayer, bilinear) are kept; a Gaussian has eps 0.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from bench.design.no_pose_rates import effect_class
from dockfactory.core.io import write_json_atomic

EPS = np.r_[0.0, np.geomspace(0.005, 0.5, 25)]
M = np.geomspace(1.5, 40.0, 30)
CORE = np.linspace(0.6, 1.2, 25)
DESIGN_EFFECTS = ("three-chip", "three-chip-jpeg90", "three-chip-jpeg95", "bayer-bilinear", "bayer-jpeg90",
                  "bayer-jpeg95")


def normalised_errors(results: list[dict]) -> dict:
    """{effect: (n,) errors over their (dataset, effect)'s robust sigma, both axes, pooled}."""
    out: dict = {}
    for res in results:
        for effects in res["datasets"].values():
            for effect, s in effects.items():
                if effect not in DESIGN_EFFECTS or "rows" not in s:
                    continue
                e = np.array([c[1:] for r in s["rows"] for c in r["centres"]], dtype=float).ravel()
                med = np.median(e)
                out.setdefault(effect, []).append((e - med) / (1.4826 * np.median(np.abs(e - med))))
    return {k: np.concatenate(v) for k, v in out.items()}


def mixture_fit(z: np.ndarray) -> dict:
    """{"eps", "m", "core", "nll_gain"} of the contaminated normal of largest likelihood for ``z``
    (module docstring); nll_gain its negative log-likelihood below the best Gaussian's."""
    z2 = z[:, None] ** 2
    best, gauss = None, None
    for eps in EPS:
        for m in (M if eps > 0 else M[:1]):
            c = CORE[None, :]
            p = (1 - eps) * np.exp(-z2 / (2 * c * c)) / c + eps * np.exp(-z2 / (2 * (m * c) ** 2)) / (m * c)
            nll = -np.log(p + 1e-300).sum(axis=0)
            k = int(np.argmin(nll))
            if eps == 0:
                gauss = nll[k]
            if best is None or nll[k] < best[0]:
                best = (nll[k], eps, m, CORE[k])
    return {"eps": round(float(best[1]), 4), "m": round(float(best[2]), 2), "core": round(float(best[3]), 3),
            "nll_gain": round(float(gauss - best[0]), 1), "n": int(len(z)),
            "rms_over_robust": round(float(np.sqrt(np.mean(z ** 2))), 2)}


def card_tail(fits: dict) -> dict:
    """The card's ``no_pose_simulation.tail`` table of the fits: {format: {cfa: [eps, m]}}."""
    out: dict = {}
    for effect, f in fits.items():
        fmt, cfa = effect_class(effect)
        out.setdefault(fmt, {})[cfa] = [f["eps"], f["m"]]
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("rows", nargs="+", type=Path)
    ap.add_argument("--card", type=Path)
    ap.add_argument("--card-out", type=Path)
    ap.add_argument("--json", type=Path)
    args = ap.parse_args(argv)
    fits = {k: mixture_fit(z) for k, z in normalised_errors([json.loads(p.read_text()) for p in args.rows]).items()}
    print("| effect | centres | RMS / robust sigma | eps | m | core / robust | -log L below the Gaussian's |\n"
          "| --- | --- | --- | --- | --- | --- | --- |")
    for k, f in fits.items():
        print(f"| {k} | {f['n']} | {f['rms_over_robust']} | {f['eps']} | {f['m']} | {f['core']} | {f['nll_gain']} |")
    if args.card and args.card_out:
        card = json.loads(args.card.read_text())
        card["no_pose_simulation"]["tail"] = card_tail(fits)
        write_json_atomic(args.card_out, card)
    if args.json:
        write_json_atomic(args.json, {"rows": [str(p) for p in args.rows], "fits": fits, "tail": card_tail(fits)})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
