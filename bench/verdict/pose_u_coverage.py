"""Coverage of a single pose's expanded uncertainty U = 2 u (eval/uncertainty_budget.py), Monte Carlo
(JCGM 101 style).

    python -m bench.verdict.pose_u_coverage [--trials 1000] [--sigma-px 0.3] [--layout-mm 0.05]

Each trial draws a synthetic docking frame (solver.synthetic.docking_scene, default layout,
1280 x 960, 1-1.8 m), displaces the markers the camera sees by N(0, layout_mm^2) per coordinate
from the layout the solver is given (in the cases with layout error), projects them, adds
N(0, sigma_px^2) to every centre, solves from the correspondences and computes the pose's budget;
it counts how often |error| <= U for X, Y and alpha. U = 2 u of a Gaussian covers 95.45 %; the
target is 93-97 % (the binomial 2-sigma band at 1,000 trials is +-1.3 %). Cases:
- pixel noise, sigma estimated from the residuals (what measure does without a known sigma);
- pixel noise, sigma known;
- pixel noise and layout error, the layout's sigma_mm stated (the budget's layout term), the
  noise estimated from the residuals (which then hold part of the layout error) or known;
- the same layout error, not stated (the budget without its layout term).
Seeds: default_rng([trial, case]).
"""
from __future__ import annotations

import argparse

import numpy as np

from dockfactory.core.geometry import pose_components
from dockfactory.eval.solve_frames import pose_record
from dockfactory.eval.uncertainty_budget import pose_budget
from dockfactory.solver import SolverError, solve_docking
from dockfactory.solver.synthetic import default_layout, docking_scene, project

MARKERS = default_layout()
IDS = [m.id for m in MARKERS if m.section == "A"] + [m.id for m in MARKERS if m.section == "B"]
NAMES = ("x_mm", "y_mm", "alpha_deg")


def trial(rng, sigma_px: float, layout_mm: float, known: bool, stated: bool):
    """(|error| <= U per NAMES) of one frame, or None when the solve fails."""
    sc = docking_scene(rng, markers=MARKERS)
    pa = sc.points_a + rng.normal(0.0, layout_mm, sc.points_a.shape)
    pb = sc.points_b + rng.normal(0.0, layout_mm, sc.points_b.shape)
    uv = np.vstack([project(sc.cam_from_d, sc.focal_px, sc.image_centre, pa),
                    project(sc.cam_from_b, sc.focal_px, sc.image_centre, pb)])
    uv += rng.normal(0.0, sigma_px, uv.shape)
    try:
        res = solve_docking(MARKERS, sc.image_centre, correspondences=(IDS, uv), sigma_px=sigma_px if known else None)
    except SolverError:
        return None
    rec = {**pose_record(res, len(IDS)), "image_size": list(sc.image_size)}
    budget = pose_budget(rec, MARKERS, {i: layout_mm for i in IDS} if stated else None, noise_from_residuals=not known)
    truth = pose_components(sc.d_from_b)
    return [abs(rec["pose"][n] - truth[n]) <= budget[n]["expanded"] for n in NAMES]


def coverage(trials: int, case: int, **kw) -> tuple[list[float], int]:
    hits, n = np.zeros(len(NAMES)), 0
    for t in range(trials):
        r = trial(np.random.default_rng([t, case]), **kw)
        if r is not None:
            hits += r
            n += 1
    return (hits / max(n, 1)).tolist(), trials - n


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=1000)
    ap.add_argument("--sigma-px", type=float, default=0.3)
    ap.add_argument("--layout-mm", type=float, default=0.05)
    args = ap.parse_args()
    cases = (("pixel noise, sigma estimated", dict(layout_mm=0.0, known=False, stated=False)),
             ("pixel noise, sigma known", dict(layout_mm=0.0, known=True, stated=False)),
             (f"+ layout error {args.layout_mm} mm, stated", dict(layout_mm=args.layout_mm, known=False, stated=True)),
             (f"+ layout error {args.layout_mm} mm, stated, sigma known", dict(layout_mm=args.layout_mm, known=True,
                                                                              stated=True)),
             (f"+ layout error {args.layout_mm} mm, not stated", dict(layout_mm=args.layout_mm, known=False,
                                                                      stated=False)))
    print(f"| case ({args.sigma_px} px) | X | Y | alpha | failed solves |")
    print("| --- | --- | --- | --- | --- |")
    for k, (name, kw) in enumerate(cases, start=1):
        cov, failed = coverage(args.trials, k, sigma_px=args.sigma_px, **kw)
        print(f"| {name} | " + " | ".join(f"{c:.3f}" for c in cov) + f" | {failed} |", flush=True)


if __name__ == "__main__":
    main()
