"""Does the single-section solver ever say less than its error? Counts of solves whose error is
beyond 6 of the solver's own reported standard deviations, and the RMS of error / reported std.

    python -m bench.solver.solver_honesty [--trials 5000] [--seed 0] [--modes given,floor,estimated]

Sets (as bench/solver/solver_bench.py's hard sets, the same seeds): ``near-planar-10`` (10 markers of A
within +-20 deg of the line facing the camera) and ``5-point`` (5 of the default layout's 7
markers of A), Gaussian centre noise sigma 0.1 / 0.3 / 1 px. Modes of the noise the solver is
told: ``given`` (sigma_px = the true sigma), ``floor`` (estimated from the residuals, never below
the true sigma: a detector's noise card, as the pipelines pass it), ``estimated`` (from the
residuals alone: 3 residual degrees of freedom for 5 points). Per set and mode: refusals, solves
beyond 6 reported stds in rotation (the angle over the root of the rotation covariance's trace),
in any of t_x, t_y, t_z, and in f, counted over the solves the solver does not flag
(``uncertainty_determined``), with the flagged solves and those of them beyond 6 stds apart; RMS z
of t_x, t_y, t_z, f over the unflagged solves. A line is printed as each set ends.
"""
from __future__ import annotations

import argparse
import sys
from dataclasses import replace

import numpy as np

from bench.solver.solver_bench import HARD_KINDS, hard_errors, hard_trial
from dockfactory.solver.errors import SolverError
from dockfactory.solver.pnpf import solve_pnpf
from dockfactory.solver.refine import DEFAULT_REFINE
def solve(p3, uv, pp, sigma, mode):
    if mode == "given":
        return solve_pnpf(p3, uv, pp, sigma_px=sigma)
    floor = sigma if mode == "floor" else None
    return solve_pnpf(p3, uv, pp, refine_options=replace(DEFAULT_REFINE, sigma_floor_px=floor))


def run_set(kind: str, sigma: float, mode: str, n: int, seed: int) -> dict:
    rng = np.random.default_rng([seed, HARD_KINDS.index(kind), int(round(sigma * 1000))])
    refused, rot, trans, foc, flagged, flagged_wild, zs = 0, 0, 0, 0, 0, 0, []
    for _ in range(n):
        p3, uv, cam, f, pp = hard_trial(kind, rng)
        noisy = uv + sigma * rng.standard_normal(uv.shape)
        try:
            res = solve(p3, noisy, pp, sigma, mode)
        except SolverError:
            refused += 1
            continue
        e = hard_errors(res, cam, f)
        z = np.abs(np.r_[e[1:4], e[4] / 100.0 * f]) / res.std[3:7]
        wild_rot = bool(np.radians(e[0]) > 6.0 * np.sqrt(np.trace(res.covariance[:3, :3])))
        if not res.uncertainty_determined:
            flagged += 1
            flagged_wild += bool(wild_rot or z.max() > 6.0)
            continue
        rot += wild_rot
        trans += bool(z[:3].max() > 6.0)
        foc += bool(z[3] > 6.0)
        zs.append(z)
    rms = np.sqrt(np.mean(np.array(zs) ** 2, axis=0)) if zs else np.full(4, np.nan)
    return {"kind": kind, "sigma": sigma, "mode": mode, "trials": n, "refused": refused, "rot": rot,
            "trans": trans, "focal": foc, "flagged": flagged, "flagged_wild": flagged_wild,
            "rms_z": rms}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=5000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--modes", default="given,floor,estimated")
    args = ap.parse_args(argv)
    print(f"{'set':<16}{'sigma':>6}{'mode':>10}{'trials':>7}{'refused':>8}{'>6 rot':>7}{'>6 t':>6}{'>6 f':>6}"
          f"{'flagged':>8}{'(>6)':>6}   RMS z t_x / t_y / t_z / f (unflagged)")
    for kind in HARD_KINDS:
        for sigma in (0.1, 0.3, 1.0):
            for mode in args.modes.split(","):
                r = run_set(kind, sigma, mode, args.trials, args.seed)
                print(f"{kind:<16}{sigma:>6}{mode:>10}{r['trials']:>7}{r['refused']:>8}{r['rot']:>7}{r['trans']:>6}"
                      f"{r['focal']:>6}{r['flagged']:>8}{r['flagged_wild']:>6}   " + " / ".join(f"{v:.2f}" for v in r["rms_z"]), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
