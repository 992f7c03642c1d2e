"""Coverage of the verdict's confidence bounds (eval/confidence.py), Monte Carlo (JCGM 101 style).

    python -m bench.verdict.confidence_coverage [--trials 1000] [--confidence 0.95]

For each case (n errors per repetition, an error model, a true RMSE of 1), ``--trials`` repetitions
draw n errors, compute the one-sided bounds of the RMSE by chi-square and by bootstrap and the pair
that decides (the cautious one), and count how often each upper bound lies above the true RMSE and
each lower bound below it. A one-sided 95 % bound should cover 95 % of repetitions (93-97 % is the
target at 1,000 trials: +-1.4 % is the binomial standard error's 2 sigma). Error models: Gaussian
about zero; Gaussian with a bias of half the spread (true RMSE still 1: the chi-square bound counts
the bias as error); Student t with 4 degrees of freedom (heavy tails), scaled to RMSE 1. Pooled
spread: 3 static poses with 2, 3 and 10 captures. Seeds: default_rng([trial, case]).
"""
from __future__ import annotations

import argparse
import math

import numpy as np

from dockfactory.eval.confidence import pooled_spread_bounds, rmse_bounds


def draw(model: str, n: int, rng) -> np.ndarray:
    if model == "gauss":
        return rng.normal(0.0, 1.0, n)
    if model == "bias":
        return rng.normal(0.5, math.sqrt(1 - 0.25), n)
    t = rng.standard_t(4, n)
    return t / math.sqrt(4 / (4 - 2))


def coverage(model: str, n: int, trials: int, conf: float, case: int) -> dict:
    hits = {k: [0, 0] for k in ("chi2", "bootstrap", "decides")}
    counted = {k: 0 for k in hits}
    for t in range(trials):
        rng = np.random.default_rng([t, case])
        b = rmse_bounds(draw(model, n, rng), conf, seed=t)
        for k in hits:
            pair = b if k == "decides" else b[k]
            if pair is None or pair.get("upper") is None:
                continue
            counted[k] += 1
            hits[k][0] += pair["upper"] >= 1.0
            hits[k][1] += pair["lower"] <= 1.0
    return {k: (hits[k][0] / counted[k], hits[k][1] / counted[k]) if counted[k] else None for k in hits}


def pooled_coverage(trials: int, conf: float) -> dict:
    hits, n = [0, 0], 0
    for t in range(trials):
        rng = np.random.default_rng([t, 99])
        groups = [rng.normal(5.0 * k, 1.0, m) for k, m in enumerate((2, 3, 10))]
        b = pooled_spread_bounds(groups, conf, seed=t)
        n += 1
        hits[0] += b["upper"] >= 1.0
        hits[1] += b["lower"] <= 1.0
    return {"decides": (hits[0] / n, hits[1] / n)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=1000)
    ap.add_argument("--confidence", type=float, default=0.95)
    args = ap.parse_args()
    print("| errors | n | chi-square upper / lower | bootstrap upper / lower | deciding pair upper / lower |")
    print("| --- | --- | --- | --- | --- |")
    case = 0
    for model in ("gauss", "bias", "t4"):
        for n in (9, 30, 100):
            case += 1
            c = coverage(model, n, args.trials, args.confidence, case)
            cells = [f"{c[k][0]:.3f} / {c[k][1]:.3f}" if c[k] else "-" for k in ("chi2", "bootstrap", "decides")]
            print(f"| {model} | {n} | " + " | ".join(cells) + " |", flush=True)
    p = pooled_coverage(args.trials, args.confidence)["decides"]
    print(f"| pooled spread, 3 poses (2, 3, 10 captures) | dof 12 | - | - | {p[0]:.3f} / {p[1]:.3f} |")


if __name__ == "__main__":
    main()
