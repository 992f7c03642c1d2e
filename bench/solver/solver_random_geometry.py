"""Does the single-section solver pick a wrong basin with confidence, on geometry unlike the
project's own? Random cameras and layouts, the solver told the noise (as the pipelines tell it
the noise card's), counts of unflagged solves beyond 6 reported standard deviations and the RMS
of the errors over the Cramer-Rao bound.

    python -m bench.solver.solver_random_geometry [--trials 20000] [--seed 0] [--sigmas 0.1,0.3,1]
        [--out FILE.json] [--no-basin-check]

``--no-basin-check``: the solver as it was before the focal-basin check (solver.focal_basins), for
the before / after figures.

A trial draws: the section radius 300-600 mm, 5-12 markers of A (axial 10-300 mm from the seam,
spread over +-5..+-60 deg (log-uniform) around the line facing the camera, diameter 20-40 mm,
redrawn until no two overlap), a camera 1-3 m from the seam (the factory's tilt, roll and jitter), an image
1280-4096 px wide at 4:3, a focal 800-4000 px that keeps every marker 48 px inside the image;
the exact projections plus Gaussian noise sigma. ``solve_pnpf(..., sigma_px=sigma)``.

Per sigma: refused; flagged (``uncertainty_determined`` False); unflagged solves beyond 6
reported stds in rotation (angle / root of the rotation covariance's trace), any of t_x, t_y,
t_z, or f; "wrong basin" (focal more than 25 % off and beyond 6 stds) with and without the flag;
RMS error / RMS bound of rotation, t_x, t_y, t_z, f over the unflagged solves; RMS z. A line is
printed as each sigma ends; ``--out`` writes the rows and the worst unflagged trials (JSON).
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from dockfactory.core.layout import DEFAULT_LAYOUT_B, build_layout, marker_points
from dockfactory.solver.crb import crb_pnpf
from dockfactory.solver.errors import SolverError
from dockfactory.solver.lie import rotation_angle_deg
from dockfactory.solver.pnpf import solve_pnpf
from dockfactory.solver.synthetic import docking_scene


def random_pattern(rng, n: int, radius: float, diameter: float) -> tuple:
    """(s_mm, phi_deg) of ``n`` markers of A that do not overlap (centre spacing >= 1.5 d): axial
    10-300 mm, within +-spread deg, the spread log-uniform in 5-60 deg (near-planar sets
    included: the focal-depth trade-off's hard case)."""
    spread = float(np.exp(rng.uniform(np.log(5.0), np.log(60.0))))
    for _ in range(200):
        s = rng.uniform(10.0, 300.0, n)
        phi = rng.uniform(-spread, spread, n)
        xy = np.c_[s, np.radians(phi) * radius]
        d = np.linalg.norm(xy[:, None] - xy[None], axis=2) + np.eye(n) * 1e9
        if d.min() >= 1.5 * diameter:
            return tuple(zip(s, phi))
        spread = min(spread * 1.1, 90.0)
    raise RuntimeError("could not place the markers")


def random_trial(rng):
    """(points (N, 3) mm, noise-free pixels (N, 2), cam_from_d (4, 4), focal px, pp (2,), meta)."""
    while True:
        radius = rng.uniform(300.0, 600.0)
        n = int(rng.integers(5, 13))
        diameter = rng.uniform(20.0, 40.0)
        width = int(rng.integers(1280, 4097))
        size = (width, int(round(width * 3 / 4)))
        markers = build_layout(random_pattern(rng, n, radius, diameter), DEFAULT_LAYOUT_B[:1],
                               radius_mm=radius, diameter_mm=diameter)
        try:
            sc = docking_scene(rng, markers=markers, focal_range=(800.0, 4000.0),
                               distance_range=(1000.0, 3000.0), image_size=size, radius_mm=radius)
        except RuntimeError:
            continue
        meta = {"radius_mm": radius, "markers": n, "diameter_mm": diameter, "image": list(size),
                "focal_px": sc.focal_px, "distance_mm": float(np.linalg.norm(sc.cam_from_d[:3, 3]))}
        return marker_points(markers, "A"), sc.uv_a, sc.cam_from_d, sc.focal_px, sc.principal_point, meta


def trial_errors(res, cam, f) -> np.ndarray:
    """rotation (deg), t_x, t_y, t_z (mm), focal (px) errors."""
    return np.array([rotation_angle_deg(res.rotation, cam[:3, :3]), *(res.translation - cam[:3, 3]),
                     res.focal_px - f])


def bound(p3, cam, f, pp, sigma) -> np.ndarray:
    """Cramer-Rao std of rotation (deg), t_x, t_y, t_z (mm), f (px)."""
    cov = crb_pnpf(p3, cam, f, pp, sigma)
    return np.array([np.degrees(np.sqrt(np.trace(cov[:3, :3]))), *np.sqrt(np.diag(cov)[3:7])])


def reported(res) -> np.ndarray:
    """The solver's own std, in the order of :func:`trial_errors`."""
    return np.array([np.degrees(np.sqrt(np.trace(res.covariance[:3, :3]))), *res.std[3:7]])


def run_sigma(sigma: float, n: int, seed: int) -> dict:
    rng = np.random.default_rng([seed, int(round(sigma * 1000))])
    counts = dict(refused=0, flagged=0, beyond6=0, wrong_basin=0, wrong_basin_flagged=0)
    errs, bnds, zs, worst = [], [], [], []
    for k in range(n):
        p3, uv, cam, f, pp, meta = random_trial(rng)
        noisy = uv + sigma * rng.standard_normal(uv.shape)
        try:
            res = solve_pnpf(p3, noisy, pp, sigma_px=sigma)
        except SolverError:
            counts["refused"] += 1
            continue
        e = trial_errors(res, cam, f)
        z = np.abs(e) / reported(res)
        wrong = bool(abs(e[4]) > 0.25 * f and z[4] > 6.0)
        if not res.uncertainty_determined:
            counts["flagged"] += 1
            counts["wrong_basin_flagged"] += wrong
            continue
        counts["wrong_basin"] += wrong
        if z.max() > 6.0:
            counts["beyond6"] += 1
            worst.append({"trial": k, "z": z.round(2).tolist(), "focal_found": res.focal_px, **meta})
        errs.append(e)
        bnds.append(bound(p3, cam, f, pp, sigma))
        zs.append(z)
    errs, bnds, zs = np.array(errs), np.array(bnds), np.array(zs)
    ratio = np.sqrt(np.mean(errs ** 2, axis=0)) / np.sqrt(np.mean(bnds ** 2, axis=0))
    return {"sigma": sigma, "trials": n, **counts, "ratio_rot_t_f": ratio.round(3).tolist(),
            "rms_z": np.sqrt(np.mean(zs ** 2, axis=0)).round(3).tolist(), "worst": worst[:20]}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=20000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--sigmas", default="0.1,0.3,1")
    ap.add_argument("--out", type=Path)
    ap.add_argument("--no-basin-check", action="store_true")
    args = ap.parse_args(argv)
    if args.no_basin_check:
        import dockfactory.solver.pnpf as pnpf
        pnpf.settle_focal_basin = lambda p3, p2, pp, res, sigma, options, focal_range=None: res
    print(f"{'sigma':>6}{'trials':>7}{'refused':>8}{'flagged':>8}{'>6 std':>7}{'wrong':>6}{'(flagged)':>10}"
          "   RMS/CRB rot / tx / ty / tz / f     RMS z rot / tx / ty / tz / f   s")
    rows = []
    for sigma in (float(s) for s in args.sigmas.split(",")):
        t0 = time.perf_counter()
        r = run_sigma(sigma, args.trials, args.seed)
        rows.append(r)
        print(f"{sigma:>6}{r['trials']:>7}{r['refused']:>8}{r['flagged']:>8}{r['beyond6']:>7}{r['wrong_basin']:>6}"
              f"{r['wrong_basin_flagged']:>10}   " + " / ".join(f"{v:.2f}" for v in r["ratio_rot_t_f"])
              + "   " + " / ".join(f"{v:.2f}" for v in r["rms_z"]) + f"   {time.perf_counter() - t0:.0f}",
              flush=True)
        if args.out:
            args.out.parent.mkdir(parents=True, exist_ok=True)
            args.out.write_text(json.dumps({"seed": args.seed, "basin_check": not args.no_basin_check,
                                            "rows": rows}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
