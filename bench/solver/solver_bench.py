"""Benchmark of the uncalibrated pose solver against peers on docking-like trials.

Trials: the factory's marker layout (7 + 7 markers on two cylinders of radius 300 mm), camera
1.0-1.8 m from the seam with up to 4 deg tilt and 2 deg roll, f 1200-2400 px (capped so that the
markers fit), 1280 x 960, principal point ((W - 1) / 2, (H - 1) / 2), B placed by d_from_b within
the factory's ranges (see solver/synthetic.py). Gaussian pixel noise sigma in {0, 0.1, 0.3, 1}
px. Every solver sees the same trials.

Solvers:
- ours-closed: UPnP closed form alone (best candidate), each section on its own;
- ours-1sec: closed form + Levenberg-Marquardt, each section on its own (solve_pnpf);
- ours-joint: the docking solver, both sections with one shared focal (solve_docking);
- sqpnp(true f): OpenCV solvePnP SOLVEPNP_SQPNP given the TRUE focal (calibrated reference);
- pycolmap: estimate_and_refine_absolute_pose, focal estimation + refinement, default RANSAC;
- poselib-p4pf: the minimal P4Pf solver on every 4-subset, best reprojection over all points.
Peers are optional (`pip install pycolmap poselib`); a missing one is skipped with a message.

Metrics (RMS over the trials a solver did not fail): rotation error of cam_from_a (deg),
translation error of cam_from_a per camera axis (mm), focal error (%), and X, Y (mm), alpha
(deg) of d_from_b. "/CRB" rows divide each RMS by the RMS over the same trials of the
Cramer-Rao standard deviation of the problem the solver solves: one section with unknown focal
(7 parameters; d_from_b from two such sections), one section with known focal (sqpnp), or the
joint 13-parameter problem (ours-joint). Failure: an exception, a non-finite result, or an
error beyond 10 Cramer-Rao standard deviations (of the solver's problem, per trial) in any
metric. Timing: median microseconds per call on this machine (per section for single-section
solvers, per frame for ours-joint), measured as process CPU time because the cores are shared.

Also: the robust layer with 20 % outliers (3 of 14 correspondences replaced by wrong pixels):
fraction of trials whose inlier mask is exactly right; and identification from class-only
detections with missing markers, spurious detections and swapped classes. (The batch API and
its throughput figure were removed with solver/batch.py: it was a second implementation of the
closed form, LM and covariance used by no production path.)

Single-section hard sets (issue 12): 10 markers within +-20 deg of the line facing the camera
(near-planar), and 5 of a section's 7 markers (what occlusion leaves), sigma 0.1 / 0.3 / 1 px:
refusals (SolverError), wrong minima (an RMS above that of the refinement started from the truth),
solutions beyond 6 Cramer-Rao standard deviations in rotation or in-plane translation (t_x, t_y:
the quantities these sets determine; "(all)": results whose focal is flagged determined, beyond 6
in any of rotation, t, focal: the maximum likelihood itself strays that far when the bound's
linearisation fails, e.g. f 4253 px for a true 1977 with an equal RMS from the truth), results flagged focal-undetermined,
and RMS / bound of rotation, t_x, t_y and the focal.

Run: python -m bench.solver.solver_bench [--trials 500] [--seed 0] [--hard-trials 5000] [--hard-only]
"""
from __future__ import annotations

import argparse
import itertools
import time

import numpy as np

from dockfactory.core.geometry import pose_components
from dockfactory.core.layout import DEFAULT_LAYOUT_B, build_layout
from dockfactory.solver import (
    SolverError,
    crb_d_from_b,
    crb_joint,
    crb_pnpf,
    solve_docking,
    solve_pnpf,
    upnp,
)
from dockfactory.solver.lie import rotation_angle_deg
from dockfactory.solver.refine import refine_pnpf, relative_pose
from dockfactory.solver.synthetic import default_layout, docking_scene

LAYOUT = default_layout()
IDS = [m.id for m in LAYOUT]
W, H = 1280, 960
METRICS = ["rot_deg", "tx_mm", "ty_mm", "tz_mm", "f_pct", "X_mm", "Y_mm", "alpha_deg"]


# ------------------------------------------------------------------------------------ peers

def _peer_cv2():
    try:
        import cv2
    except ImportError:
        return None, "opencv not installed"
    if not hasattr(cv2, "SOLVEPNP_SQPNP"):
        return None, "this OpenCV has no SOLVEPNP_SQPNP"

    def solve(p3, p2, pp, f_true):
        k = np.array([[f_true, 0, pp[0]], [0, f_true, pp[1]], [0, 0, 1.0]])
        ok, rvec, tvec = cv2.solvePnP(p3, p2, k, None, flags=cv2.SOLVEPNP_SQPNP)
        if not ok:
            raise RuntimeError("SQPnP failed")
        r, _ = cv2.Rodrigues(rvec)
        return r, tvec.ravel(), f_true
    return solve, None


def _peer_pycolmap():
    try:
        import pycolmap
    except ImportError:
        return None, "pycolmap not installed (pip install pycolmap)"

    def solve(p3, p2, pp, f_true):
        cam = pycolmap.Camera(model="SIMPLE_PINHOLE", width=W, height=H,
                              params=[1.2 * max(W, H), pp[0], pp[1]])
        eo = pycolmap.AbsolutePoseEstimationOptions()
        eo.estimate_focal_length = True
        eo.ransac.random_seed = 0
        ro = pycolmap.AbsolutePoseRefinementOptions()
        ro.refine_focal_length = True
        out = pycolmap.estimate_and_refine_absolute_pose(p2, p3, cam, eo, ro)
        if out is None:
            raise RuntimeError("pycolmap found no pose")
        m = out["cam_from_world"].matrix()
        return m[:, :3], m[:, 3], float(cam.params[0])
    return solve, None


def _peer_poselib():
    try:
        import poselib
    except ImportError:
        return None, "poselib not installed (pip install poselib)"

    def solve(p3, p2, pp, f_true):
        x = p2 - pp
        best = None
        for sub in itertools.combinations(range(p3.shape[0]), 4):
            sub = list(sub)
            poses, focals = poselib.p4pf(x[sub], p3[sub], True)
            for pose, f in zip(poses, focals):
                rt = pose.Rt
                pc = p3 @ rt[:, :3].T + rt[:, 3]
                if f <= 0 or np.any(pc[:, 2] <= 0):
                    continue
                e = float(np.sum((f * pc[:, :2] / pc[:, 2:3] - x) ** 2))
                if best is None or e < best[0]:
                    best = (e, rt[:, :3], rt[:, 3], f)
        if best is None:
            raise RuntimeError("p4pf found no valid pose")
        return best[1], best[2], best[3]
    return solve, None


def _ours_closed(p3, p2, pp, f_true):
    c = upnp(p3, p2, pp)[0]
    return c.rotation, c.translation, c.focal_px


def _ours_1sec(p3, p2, pp, f_true):
    r = solve_pnpf(p3, p2, pp)
    return r.rotation, r.translation, r.focal_px


# ------------------------------------------------------------------------------------ trials

def make_trials(seed, sigma, n):
    rng = np.random.default_rng([seed, int(round(sigma * 1000))])
    out = []
    for _ in range(n):
        sc = docking_scene(rng)
        ua = sc.uv_a + sigma * rng.standard_normal(sc.uv_a.shape)
        ub = sc.uv_b + sigma * rng.standard_normal(sc.uv_b.shape)
        out.append((sc, ua, ub))
    return out


def bounds(sc, sigma):
    """Per-trial CRB std of every metric for the three problems."""
    pp, f = sc.principal_point, sc.focal_px
    out = {}
    s = max(sigma, 1e-300)
    c7 = crb_pnpf(sc.points_a, sc.cam_from_d, f, pp, s)
    c6 = crb_pnpf(sc.points_a, sc.cam_from_d, f, pp, s, focal_known=True)
    c13 = crb_joint(sc.points_a, sc.cam_from_d, sc.points_b, sc.cam_from_b, f, pp, s)
    for name, cov_pose, problem in (("single", c7, "independent"), ("calib", c6, "calibrated"),
                                    ("joint", c13, "joint")):
        d = crb_d_from_b(sc.points_a, sc.cam_from_d, sc.points_b, sc.cam_from_b, f, pp, s,
                         problem)
        fvar = cov_pose[-1, -1] if name != "calib" else 0.0
        out[name] = np.array([
            np.degrees(np.sqrt(np.trace(cov_pose[:3, :3]))),
            *np.sqrt(np.diag(cov_pose)[3:6]), 100.0 * np.sqrt(fvar) / f,
            d.std["x_mm"], d.std["y_mm"], d.std["alpha_deg"]])
        if sigma == 0:
            out[name] = np.zeros(8)
    return out


def errors(sc, ra, ta, fa, rb, tb):
    truth = pose_components(sc.d_from_b)
    est = pose_components(relative_pose(ra, ta, rb, tb))
    return np.array([rotation_angle_deg(ra, sc.cam_from_d[:3, :3]),
                     *(ta - sc.cam_from_d[:3, 3]), 100.0 * (fa / sc.focal_px - 1.0),
                     est["x_mm"] - truth["x_mm"], est["y_mm"] - truth["y_mm"],
                     est["alpha_deg"] - truth["alpha_deg"]])


def failed(e, bound):
    """An exception / non-finite result, or an error no noise explains: beyond 10 Cramer-Rao
    standard deviations of the solver's problem in any metric (sigma = 0: beyond 1e-3)."""
    if not np.all(np.isfinite(e)):
        return True
    tol = np.where(bound > 0, 10.0 * bound, 1e-3)
    return bool(np.any(np.abs(e) > tol))


def run_single_section(solver, trials, bnd):
    errs, fails, times = [], [], []
    for (sc, ua, ub), b in zip(trials, bnd):
        try:
            t0 = _clock()
            ra, ta, fa = solver(sc.points_a, ua, sc.principal_point, sc.focal_px)
            t1 = _clock()
            rb, tb, _ = solver(sc.points_b, ub, sc.principal_point, sc.focal_px)
            t2 = _clock()
            times += [t1 - t0, t2 - t1]
            e = errors(sc, np.asarray(ra), np.asarray(ta, dtype=float), fa, np.asarray(rb),
                       np.asarray(tb, dtype=float))
        except (SolverError, RuntimeError, np.linalg.LinAlgError):
            e = np.full(8, np.nan)
        fails.append(failed(e, b))
        errs.append(e)
    return np.array(errs), np.array(fails), np.array(times)


def run_joint(trials, bnd):
    errs, fails, times = [], [], []
    for (sc, ua, ub), b in zip(trials, bnd):
        uv = np.vstack([ua, ub])
        try:
            t0 = _clock()
            r = solve_docking(LAYOUT, sc.principal_point, correspondences=(IDS, uv))
            times.append(_clock() - t0)
            ca, cb = r.cam_from_a, r.cam_from_b
            e = errors(sc, ca[:3, :3], ca[:3, 3], r.focal_px, cb[:3, :3], cb[:3, 3])
        except SolverError:
            e = np.full(8, np.nan)
        fails.append(failed(e, b))
        errs.append(e)
    return np.array(errs), np.array(fails), np.array(times)


def _clock():
    """CPU time of this process (s): per-call timings stay meaningful when other work shares
    the cores (wall-clock time would count the time our process waits for a core)."""
    return time.process_time()


def fmt(v, w=9):
    if v is None or not np.isfinite(v):
        return " " * (w - 1) + "-"
    if v == 0:
        return f"{0:>{w}.0f}"
    if abs(v) >= 1000 or abs(v) < 1e-3:
        return f"{v:>{w}.2e}"
    return f"{v:>{w}.4g}"


def report(sigma, rows, bnds):
    print(f"\n=== sigma = {sigma} px, {len(next(iter(rows.values()))[0])} trials ===")
    head = "solver           fail%  us/call " + "".join(f"{m:>9}" for m in METRICS)
    print(head)
    for name, (errs, fails, times, problem) in rows.items():
        ok = ~fails
        rms = np.sqrt(np.nanmean(errs[ok] ** 2, axis=0)) if ok.any() else np.full(8, np.nan)
        line = f"{name:<16}{100 * fails.mean():6.2f} {np.median(times) * 1e6:8.0f} "
        print(line + "".join(fmt(v) for v in rms))
        if sigma > 0 and ok.any():
            b = np.sqrt(np.mean(bnds[problem][ok] ** 2, axis=0))
            ratio = rms / np.where(b > 0, b, np.nan)
            if problem == "calib":
                ratio[4] = np.nan
            print(f"{'  /CRB(' + problem + ')':<31}" + "".join(fmt(v) for v in ratio))


# ------------------------------------------------------------------------------------ extras

def outlier_trials(seed, n, sigma=0.5, n_bad=3):
    rng = np.random.default_rng([seed, 777])
    ok, fail_msgs, times = 0, [], []
    for trial in range(n):
        sc = docking_scene(rng)
        uv = np.vstack([sc.uv_a, sc.uv_b]) + sigma * rng.standard_normal((14, 2))
        bad = rng.choice(14, size=n_bad, replace=False)
        for k in bad:
            while True:
                q = rng.uniform([0, 0], [W, H])
                if np.linalg.norm(q - uv[k]) > 12.0:
                    uv[k] = q
                    break
        want = np.ones(14, dtype=bool)
        want[bad] = False
        try:
            t0 = time.perf_counter()
            r = solve_docking(LAYOUT, sc.principal_point, correspondences=(IDS, uv), robust=True,
                              rng=np.random.default_rng([seed, trial]))
            times.append(time.perf_counter() - t0)
            if np.array_equal(r.inliers, want):
                ok += 1
            else:
                fail_msgs.append("wrong inlier mask")
        except SolverError as exc:
            fail_msgs.append(str(exc)[:60])
    return ok / n, fail_msgs, np.median(times) if times else float("nan")


def identification_trials(seed, n, sigma=0.5):
    rng = np.random.default_rng([seed, 888])
    ok, wrong, raised, times = 0, 0, 0, []
    for trial in range(n):
        sc = docking_scene(rng)
        uv = np.vstack([sc.uv_a, sc.uv_b]) + sigma * rng.standard_normal((14, 2))
        cls = np.array([0] * 7 + [1] * 7)
        while True:
            keep = rng.random(14) >= 0.15
            if keep[:7].sum() >= 5 and keep[7:].sum() >= 5:
                break
        for k in rng.choice(np.flatnonzero(keep), size=trial % 3, replace=False):
            cls[k] = 1 - cls[k]
        n_sp = trial % 4
        spur = []
        while len(spur) < n_sp:
            q = rng.uniform([0, 0], [W, H])
            if np.min(np.linalg.norm(uv - q, axis=1)) > 15.0:
                spur.append(q)
        pts = np.vstack([uv[keep]] + ([np.array(spur)] if spur else []))
        classes = np.concatenate([cls[keep], rng.integers(0, 2, n_sp)])
        truth = [i for i, k in zip(IDS, keep) if k] + [None] * n_sp
        try:
            t0 = time.perf_counter()
            r = solve_docking(LAYOUT, sc.principal_point, detections=(classes, pts))
            times.append(time.perf_counter() - t0)
            if list(r.marker_ids) == truth:
                ok += 1
            else:
                wrong += 1
        except SolverError:
            raised += 1
    return ok / n, wrong / n, raised / n, np.median(times) if times else float("nan")


# ------------------------------------------------------------------------------------ hard sets

HARD_KINDS = ("near-planar-10", "5-point")
FOCAL_RANGE = (1000.0, 4000.0)   # a zoom range around the trials' 1200-2400 px (solve_pnpf focal_range_px)


def hard_trial(kind: str, rng):
    """(points (N, 3) mm, pixels (N, 2) noise-free, cam_from_d, focal, pp) of one hard set:
    ``near-planar-10``: 10 markers of A within +-20 deg of the line facing the camera (axial
    20-200 mm), the camera of a docking frame; ``5-point``: 5 of the default layout's 7 markers
    of A (what occlusion leaves)."""
    if kind == "near-planar-10":
        pattern = tuple(zip(rng.uniform(20.0, 200.0, 10), rng.uniform(-20.0, 20.0, 10)))
        markers = build_layout(pattern, DEFAULT_LAYOUT_B, radius_mm=300.0, diameter_mm=20.0)
        sc = docking_scene(rng, markers=markers)
        return sc.points_a, sc.uv_a, sc.cam_from_d, sc.focal_px, sc.principal_point
    sc = docking_scene(rng)
    keep = np.sort(rng.choice(len(sc.points_a), size=5, replace=False))
    return sc.points_a[keep], sc.uv_a[keep], sc.cam_from_d, sc.focal_px, sc.principal_point


def hard_errors(res, cam, f):
    """rotation (deg), t_x, t_y, t_z (mm), focal (%) errors of a single-section result."""
    return np.array([rotation_angle_deg(res.rotation, cam[:3, :3]), *(res.translation - cam[:3, 3]),
                     100.0 * (res.focal_px / f - 1.0)])


def hard_bound(p3, cam, f, pp, sigma):
    cov = crb_pnpf(p3, cam, f, pp, sigma)
    return np.array([np.degrees(np.sqrt(np.trace(cov[:3, :3]))), *np.sqrt(np.diag(cov)[3:6]),
                     100.0 * np.sqrt(cov[6, 6]) / f])


def _wrong_minimum(res, p3, uv, pp, cam, f) -> bool:
    """The result's RMS is above (by 1e-6 relative) that of the refinement started from the truth:
    the solver stopped in a local minimum, not at the maximum likelihood."""
    try:
        truth = refine_pnpf(p3, uv, pp, cam[:3, :3], cam[:3, 3], f)
    except SolverError:
        return False
    return bool(res.rmse_px > truth.rmse_px * (1.0 + 1e-6) + 1e-12)


def run_hard(kind: str, sigma: float, n: int, seed: int, focal_range=None) -> dict:
    """Refusals, solutions beyond 6 bound-sigmas in rotation or in-plane translation, and RMS /
    bound of rotation, t_x, t_y (the determined quantities) over ``n`` seeded trials;
    ``focal_range``: the camera's known focal range (lo, hi) px given to solve_pnpf (the same
    trials as without it)."""
    rng = np.random.default_rng([seed, HARD_KINDS.index(kind), int(round(sigma * 1000))])
    errs, bnds, refused, wild, wild_all, flagged, wrong, at_bound = [], [], [], 0, 0, 0, 0, 0
    for _ in range(n):
        p3, uv, cam, f, pp = hard_trial(kind, rng)
        noisy = uv + sigma * rng.standard_normal(uv.shape)
        b = hard_bound(p3, cam, f, pp, sigma)
        try:
            res = solve_pnpf(p3, noisy, pp, focal_range_px=focal_range)
        except SolverError as exc:
            refused.append(type(exc).__name__)
            continue
        e = hard_errors(res, cam, f)
        at_bound += res.focal_at_bound
        flagged += not res.focal_determined
        wild += bool(np.any(np.abs(e[:3]) > 6.0 * b[:3]))
        wild_all += bool(res.focal_determined and np.any(np.abs(e) > 6.0 * b))
        wrong += focal_range is None and _wrong_minimum(res, p3, noisy, pp, cam, f)
        errs.append(e)
        bnds.append(b)
    errs, bnds = np.array(errs), np.array(bnds)
    rms = np.sqrt(np.mean(errs ** 2, axis=0)) / np.sqrt(np.mean(bnds ** 2, axis=0))
    label = kind if focal_range is None else f"{kind} f in [{focal_range[0]:.0f}, {focal_range[1]:.0f}]"
    return {"kind": label, "at_bound": at_bound, "sigma": sigma, "trials": n, "refused": len(refused), "wild": wild, "wild_all": wild_all, "wrong": wrong,
            "flagged": flagged, "ratio_rot": rms[0], "ratio_tx": rms[1], "ratio_ty": rms[2],
            "ratio_f": rms[4], "why": sorted(set(refused))}


def report_hard(rows) -> None:
    print("\nsingle-section hard sets (solve_pnpf; targets: refused <= 1 %, 0 beyond 6 bound-sigmas, "
          "RMS/bound of rotation, t_x, t_y <= 1.15)")
    print(f"{'set':<34}{'sigma':>6}{'trials':>7}{'refused%':>9}{'wrong':>6}{'>6sig':>6}{'(all)':>6}{'flagged%':>9}"
          f"{'rot/CRB':>8}{'tx/CRB':>8}{'ty/CRB':>8}{'f/CRB':>8}  refusals")
    for r in rows:
        print(f"{r['kind']:<34}{r['sigma']:>6}{r['trials']:>7}{100 * r['refused'] / r['trials']:>9.2f}"
              f"{r['wrong']:>6}{r['wild']:>6}{r['wild_all']:>6}{100 * r['flagged'] / r['trials']:>9.2f}{r['ratio_rot']:>8.3f}{r['ratio_tx']:>8.3f}"
              f"{r['ratio_ty']:>8.3f}{r['ratio_f']:>8.3f}  {', '.join(r['why'])}")


# ------------------------------------------------------------------------------------ main

def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--trials", type=int, default=500)
    ap.add_argument("--sigmas", type=float, nargs="+", default=[0.0, 0.1, 0.3, 1.0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--outlier-trials", type=int, default=500)
    ap.add_argument("--ident-trials", type=int, default=200)
    ap.add_argument("--hard-trials", type=int, default=5000, help="per hard set and sigma (0: skip)")
    ap.add_argument("--hard-only", action="store_true", help="only the single-section hard sets")
    args = ap.parse_args(argv)
    if args.hard_trials:
        rows = [run_hard(k, s, args.hard_trials, args.seed) for k in HARD_KINDS for s in (0.1, 0.3, 1.0)]
        rows += [run_hard("near-planar-10", s, args.hard_trials, args.seed, FOCAL_RANGE) for s in (0.1, 0.3, 1.0)]
        report_hard(rows)
    if args.hard_only:
        return

    peers = {}
    for name, factory in (("sqpnp(true f)", _peer_cv2), ("pycolmap", _peer_pycolmap),
                          ("poselib-p4pf", _peer_poselib)):
        fn, why = factory()
        if fn is None:
            print(f"[skip] {name}: {why}")
        else:
            peers[name] = fn
    print(f"solver bench: seed {args.seed}, {args.trials} trials per sigma, image {W}x{H}, "
          "factory layout, f 1200-2400 px")
    for sigma in args.sigmas:
        trials = make_trials(args.seed, sigma, args.trials)
        bnds = {k: np.array([bounds(sc, sigma)[k] for sc, _, _ in trials])
                for k in ("single", "calib", "joint")} if sigma > 0 else \
            {k: np.zeros((len(trials), 8)) for k in ("single", "calib", "joint")}
        rows = {}
        rows["ours-closed"] = (*run_single_section(_ours_closed, trials, bnds["single"]),
                               "single")
        rows["ours-1sec"] = (*run_single_section(_ours_1sec, trials, bnds["single"]), "single")
        rows["ours-joint"] = (*run_joint(trials, bnds["joint"]), "joint")
        for name, fn in peers.items():
            problem = "calib" if "sqpnp" in name else "single"
            rows[name] = (*run_single_section(fn, trials, bnds[problem]), problem)
        report(sigma, rows, bnds)

    rate, msgs, t = outlier_trials(args.seed, args.outlier_trials)
    print(f"robust layer, 20 % outliers (3 of 14 correspondences wrong, sigma 0.5): inlier "
          f"mask exact in {100 * rate:.1f} % of {args.outlier_trials} trials "
          f"(median {t * 1e3:.1f} ms per frame)")
    if msgs:
        print("  failures:", sorted(set(msgs))[:5])
    ok, wrong, raised, t = identification_trials(args.seed, args.ident_trials)
    print(f"identification (15 % missing, 0-3 spurious, 0-2 swapped classes, sigma 0.5): "
          f"all ids right {100 * ok:.1f} %, wrong {100 * wrong:.1f} %, refused (SolverError) "
          f"{100 * raised:.1f} % of {args.ident_trials} frames (median {t * 1e3:.1f} ms)")


if __name__ == "__main__":
    main()
