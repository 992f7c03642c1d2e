"""Self-calibration from a docking run (issue 11, section 2): ``solve_sequence`` with shared
intrinsics, one cam_from_a for the run (or one per frame) and one cam_from_b per frame, on the
synthetic runs of ``solver.synthetic.docking_run``. Seeded; tolerances stated per test.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from dockfactory.core.distortion import undistort_pixels
from dockfactory.core.geometry import pose_components
from dockfactory.solver import (
    InvalidSolverInput,
    ModelChoiceOptions,
    TooFewPoints,
    crb_sequence,
    solve_sequence,
)
from dockfactory.solver.options import DEFAULT_DOCKING
from dockfactory.solver.synthetic import POSE_RANGES, default_layout, docking_run

LAYOUT = default_layout()
IDS = [m.id for m in LAYOUT]
PRIOR = ModelChoiceOptions()
KEYS = ("focal_px", "cx", "cy", "k1")


def _frames(run, rng=None, sigma=0.0):
    out = []
    for f in run.frames:
        uv = np.vstack([f.uv_a, f.uv_b])
        if rng is not None:
            uv = uv + sigma * rng.standard_normal(uv.shape)
        out.append((IDS, uv))
    return out


def _intrinsics_error(res, run) -> np.ndarray:
    ti = run.intrinsics
    return np.array([res.focal_px - ti.focal_px, res.intrinsics["cx"] - ti.principal_point[0],
                     res.intrinsics["cy"] - ti.principal_point[1],
                     res.intrinsics["k1"] - ti.coeffs[0]])


def _pose_errors(res, run) -> np.ndarray:
    out = []
    for fr, sc in zip(res.frames, run.frames):
        t = pose_components(sc.d_from_b)
        out.append([fr.x_mm - t["x_mm"], fr.y_mm - t["y_mm"], fr.alpha_deg - t["alpha_deg"]])
    return np.array(out)


def test_docking_run_is_a_fixed_camera_with_b_approaching():
    run = docking_run(np.random.default_rng(1), 25, pp_offset_px=(20.0, 15.0), coeffs=(-0.05,))
    assert len(run.frames) == 25
    for f in run.frames:
        assert np.array_equal(f.cam_from_d, run.cam_from_d) and f.focal_px == run.frames[0].focal_px
        assert np.allclose(f.principal_point, [659.5, 494.5]) and f.coeffs[0] == -0.05
        uv = np.vstack([f.uv_a, f.uv_b])      # every marker in the image
        assert np.all(uv > 0) and np.all(uv < [1279, 959])
    comps = np.array([[pose_components(f.d_from_b)[k] for k in ("x_mm", "y_mm", "z_mm",
                       "alpha_deg", "beta_deg", "gamma_deg")] for f in run.frames])
    x = comps[:, 0]
    assert 135 <= x[0] <= 150 and 2 <= x[-1] <= 8
    assert np.allclose(np.diff(x), np.diff(x)[0])                  # evenly spaced in time
    for k, (lo, hi) in enumerate(POSE_RANGES[1:], start=1):        # smooth drift in range
        assert np.all((comps[:, k] >= lo - 1e-9) & (comps[:, k] <= hi + 1e-9))
        assert np.max(np.abs(np.diff(comps[:, k], 2))) <= 0.02 * (hi - lo)
    with pytest.raises(ValueError):
        docking_run(np.random.default_rng(1), 1)


@pytest.mark.parametrize("share", [True, False])
def test_sequence_noise_free_recovers_the_camera(share):
    """pp_k1_p camera, noise-free run of 20 frames: f to 1e-6 relative, every extra to 1e-6
    of its plausible range, X, Y to 1e-6 mm, alpha to 1e-7 deg, in both parameterisations."""
    run = docking_run(np.random.default_rng(2), 20, pp_offset_px=(-30.0, 22.0),
                      coeffs=(-0.08, 0.0, 8e-4, -6e-4))
    r = solve_sequence(LAYOUT, run.frames[0].image_centre, _frames(run),
                       camera_model="pp_k1_p", share_cam_from_a=share)
    assert r.camera_model == "pp_k1_p" and r.share_cam_from_a is share
    assert abs(r.focal_px / run.intrinsics.focal_px - 1) < 1e-6
    for key, true in run.intrinsics.values().items():
        assert abs(r.intrinsics[key] - true) <= 1e-6 * PRIOR.prior(key), key
    err = _pose_errors(r, run)
    assert np.max(np.abs(err[:, :2])) < 1e-6 and np.max(np.abs(err[:, 2])) < 1e-7
    assert np.allclose(r.cam_from_a, run.cam_from_d, atol=1e-6)
    assert r.intrinsics_covariance.shape == (6, 6) and r.rmse_px < 1e-6


def test_sequence_results_and_bad_input():
    rng = np.random.default_rng(3)
    run = docking_run(rng, 6)
    frames = _frames(run, rng, 0.1)
    r = solve_sequence(LAYOUT, run.frames[0].image_centre, frames, sigma_px=0.1)
    assert r.camera_model == "pinhole" and r.intrinsics["k1"] == 0.0
    assert len(r.frames) == 6 and r.frames[0].covariance.shape == (6, 6)
    assert r.frames[0].covariance_params.shape == (13, 13)
    assert r.intrinsics_std["cx"] == 0.0 and r.intrinsics_std["focal_px"] > 0
    pp = run.frames[0].image_centre
    with pytest.raises(InvalidSolverInput, match="at least one frame"):
        solve_sequence(LAYOUT, pp, [])
    with pytest.raises(InvalidSolverInput, match="camera_model"):
        solve_sequence(LAYOUT, pp, frames, camera_model="k3")
    short = list(frames)
    short[4] = (IDS[:10], frames[4][1][:10])          # B keeps 3 markers in frame 4
    with pytest.raises(TooFewPoints, match="frame 4"):
        solve_sequence(LAYOUT, pp, short)
    with pytest.raises(InvalidSolverInput, match="frame 2"):
        solve_sequence(LAYOUT, pp, frames[:2] + [({"Z9": (1.0, 2.0)})] + frames[3:])


def test_sequence_auto_keeps_pinhole_on_an_ideal_camera():
    """Ideal camera, 3 runs of 20 frames at 0.1 px: the run keeps the paper's model."""
    rng = np.random.default_rng(4)
    for _ in range(3):
        run = docking_run(rng, 20)
        r = solve_sequence(LAYOUT, run.frames[0].image_centre, _frames(run, rng, 0.1),
                           camera_model="auto", sigma_px=0.1)
        assert r.camera_model == "pinhole", [t.reason for t in r.model_choice.tests]


def test_sequence_covariance_is_consistent_with_its_errors():
    """pp_k1 camera solved with pp_k1, 8 runs of 20 frames at 0.1 px: the errors of (f, cx,
    cy, k1) over their reported std have RMS in [0.7, 1.35] (32 values); without the run-bias
    term the reported std equals the run's Cramer-Rao bound within 10 % (same Jacobian,
    evaluated at the estimate), and with it (the default) never falls below that, and equals it
    in at least 6 of the 8 runs (white noise shows a bias in about 1 run in 20: BIAS_ALPHA)."""
    rng = np.random.default_rng(5)
    z, equal = [], 0
    for _ in range(8):
        run = docking_run(rng, 20, pp_offset_px=(20.0, 15.0), coeffs=(-0.05,))
        frames = _frames(run, rng, 0.1)
        r = solve_sequence(LAYOUT, run.frames[0].image_centre, frames, camera_model="pp_k1", sigma_px=0.1)
        white = solve_sequence(LAYOUT, run.frames[0].image_centre, frames, camera_model="pp_k1", sigma_px=0.1,
                               options=replace(DEFAULT_DOCKING, run_marker_bias=False))
        std = np.array([r.intrinsics_std[k] for k in KEYS])
        z.append(_intrinsics_error(r, run) / std)
        f0 = run.frames[0]
        b = crb_sequence(f0.points_a, f0.cam_from_d, f0.points_b,
                         [f.cam_from_b for f in run.frames], f0.focal_px, f0.principal_point,
                         0.1, camera_model="pp_k1", coeffs=f0.coeffs)
        bound = np.array([b.intrinsics_std[k] for k in KEYS])
        assert np.allclose([white.intrinsics_std[k] for k in KEYS], bound, rtol=0.1)
        assert np.all(std >= 0.9 * bound)
        equal += bool(np.allclose(std, bound, rtol=0.1))
    rms = float(np.sqrt(np.mean(np.square(z))))
    assert 0.7 <= rms <= 1.35, rms
    assert equal >= 6, equal


@pytest.mark.slow
def test_self_calibration_targets_on_runs_of_40_frames():
    """The issue's self-calibration targets, on 24 runs of 40 frames (camera: pp (+20, +15) px
    and k1 = -0.05; 0.1 px; sequence model "auto"), as RMS over the runs:
    principal point error <= 3 px, |k1 error| <= 0.005, focal error <= 0.2 %; the bias of X,
    Y, alpha over all frames <= 0.25 of their std; RMSE of X, Y, alpha <= 1.2 x the same runs
    solved with the true intrinsics (undistorted pixels, true principal point). Also the
    run-level CRB: the (f, cx, cy, k1) errors over the bound have RMS in [0.75, 1.3].
    Measured (seed 1): pp 2.3 px, k1 0.0036, f 0.15 %, bias/std <= 0.09, RMSE ratio 1.01,
    1.01, 1.14. (Per run, not every run meets them: see the bench; 20-frame runs miss them:
    pp 3.4 px, k1 0.0073, f 0.25 %, alpha RMSE ratio 1.24 -- the Cramer-Rao bound's limit.)"""
    geo, noise = np.random.default_rng([1, 3]), np.random.default_rng([1, 4])
    err, true_err, intr, z = [], [], [], []
    for _ in range(24):
        run = docking_run(geo, 40, pp_offset_px=(20.0, 15.0), coeffs=(-0.05,))
        frames = _frames(run, noise, 0.1)
        ti = run.intrinsics
        r = solve_sequence(LAYOUT, run.frames[0].image_centre, frames, camera_model="auto",
                           sigma_px=0.1)
        assert r.camera_model == "pp_k1"
        und = [(ids, undistort_pixels(uv, ti.focal_px, ti.principal_point, ti.coeffs))
               for ids, uv in frames]
        rt = solve_sequence(LAYOUT, ti.principal_point, und, sigma_px=0.1)
        err.append(_pose_errors(r, run))
        true_err.append(_pose_errors(rt, run))
        e = _intrinsics_error(r, run)
        intr.append([np.hypot(e[1], e[2]), abs(e[3]), 100 * abs(e[0]) / ti.focal_px])
        z.append(e / np.array([r.intrinsics_std[k] for k in KEYS]))
    err, true_err, intr = np.vstack(err), np.vstack(true_err), np.array(intr)
    rms = np.sqrt(np.mean(intr ** 2, axis=0))
    assert rms[0] <= 3.0 and rms[1] <= 0.005 and rms[2] <= 0.2, rms
    assert np.all(np.abs(err.mean(0)) <= 0.25 * err.std(0)), err.mean(0) / err.std(0)
    ratio = np.sqrt(np.mean(err ** 2, 0)) / np.sqrt(np.mean(true_err ** 2, 0))
    assert np.all(ratio <= 1.2), ratio
    assert 0.75 <= np.sqrt(np.mean(np.square(z))) <= 1.3
