"""A common offset of each section's centres (``DockingOptions.section_shift_px``,
``solver.section_shift``): what a section's pose absorbs without a residual, carried in the
covariance of a single frame and of a docking run.

Tolerances: 300 seeded frames (200 runs) give an RMS z to about 1 / sqrt(2 n) = 4-5 % per
component; the band is issue 29's, 0.85-1.2."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from dockfactory.core.geometry import pose_components
from dockfactory.solver import solve_docking, solve_sequence
from dockfactory.solver.errors import InvalidSolverInput
from dockfactory.solver.options import DEFAULT_DOCKING, DockingOptions
from dockfactory.solver.section_shift import section_shift_covariance, shift_indicator
from dockfactory.solver.synthetic import default_layout, docking_run, docking_scene

LAYOUT = default_layout()
IDS = [m.id for m in LAYOUT]
SECTION = np.array([0 if m.section == "A" else 1 for m in LAYOUT])
COMPONENTS = ("x_mm", "y_mm", "alpha_deg")


def test_indicator_puts_each_axis_of_each_group_in_its_column():
    s = shift_indicator([0, 1, 0], (0.1, 0.2))
    assert s.shape == (6, 4)
    assert np.allclose(s[:, 0], [0.1, 0, 0, 0, 0.1, 0]) and np.allclose(s[:, 3], [0, 0, 0, 0.2, 0, 0])


def test_covariance_is_the_shift_propagated_through_the_estimator():
    """For a linear model the added covariance equals the spread of the least-squares estimate
    over shifts drawn from the prior (2,000 draws: within 8 % plus 3 % of the largest entry),
    weighted or not."""
    rng = np.random.default_rng(3)
    jac = rng.standard_normal((20, 3))
    groups = np.repeat([0, 1], 5)
    sqrt_w = np.broadcast_to(np.diag([1.0, 2.0]), (10, 2, 2))
    for w in (None, sqrt_w):
        want = section_shift_covariance(jac, groups, (0.1, 0.3), w)
        jw = jac if w is None else np.einsum("nab,nbk->nak", w, jac.reshape(10, 2, 3)).reshape(20, 3)
        draws = []
        for _ in range(2000):
            shift = rng.standard_normal((2, 2)) * [0.1, 0.3]
            r = shift[groups].reshape(-1)
            rw = r if w is None else np.einsum("nab,nb->na", w, r.reshape(10, 2)).reshape(-1)
            draws.append(np.linalg.lstsq(jw, rw, rcond=None)[0])
        assert np.allclose(np.cov(np.array(draws).T), want, rtol=0.08, atol=0.03 * np.abs(want).max())
    assert not np.any(section_shift_covariance(jac, groups, (0.0, 0.0)))


@pytest.mark.parametrize("bad", [(0.1,), (0.1, -0.01), (0.1, float("nan")), "ab", (0.1, 101.0)])
def test_bad_shift_is_refused_in_one_line(bad):
    with pytest.raises(InvalidSolverInput, match="section_shift_px"):
        DockingOptions(section_shift_px=bad)


def _shifted(uv, rng, sigma, tau):
    """``uv`` with white noise ``sigma`` and one common shift of std ``tau`` per section."""
    shift = tau * rng.standard_normal((2, 2))
    return uv + shift[SECTION] + sigma * rng.standard_normal(uv.shape)


def _z(result, d_from_b):
    truth = pose_components(d_from_b)
    return [(getattr(result, k) - truth[k]) / result.std[k] for k in COMPONENTS]


@pytest.mark.slow   # 300 synthetic frames, each solved twice
def test_frame_covariance_covers_a_section_shift():
    """Centres with 0.05 px of noise and a common shift of 0.1 px per section and axis: told the
    shift, the RMS z of X, Y and alpha over 300 frames is within 0.85-1.2; not told, X and Y are
    under-covered beyond 1.4 (the shift is invisible in the residuals)."""
    rng = np.random.default_rng(2026)
    z = {True: [], False: []}
    for _ in range(300):
        sc = docking_scene(rng)
        uv = _shifted(np.vstack([sc.uv_a, sc.uv_b]), rng, 0.05, 0.1)
        for told in (True, False):
            opts = replace(DEFAULT_DOCKING, section_shift_px=(0.1, 0.1) if told else None)
            res = solve_docking(LAYOUT, sc.image_centre, correspondences=(IDS, uv), options=opts)
            z[told].append(_z(res, sc.d_from_b))
            if told:
                assert res.section_shift_covariance is not None and res.section_shift_covariance[0, 0] > 0
    on, off = (np.sqrt(np.mean(np.square(z[t]), axis=0)) for t in (True, False))
    print("told", on.round(2), "not told", off.round(2))
    assert np.all((on > 0.85) & (on < 1.2)), on
    assert np.all(off[:2] > 1.4), off


@pytest.mark.slow   # 150 synthetic runs of 6 frames, each solved twice
def test_run_covariance_covers_a_shift_that_persists_over_the_run():
    """The same shift in every frame of a run (a fixed camera repeats its colour effects): told
    it, the run's RMS z of X, Y and alpha is within 0.85-1.2; not told, X and Y beyond 1.4. The
    run-bias field is off: its noise model shapes each centre's noise by its disc (the detector's
    noise), which over-covers alpha for this test's isotropic noise (0.78 with the term, 0.79
    without: not what is tested here)."""
    rng = np.random.default_rng(29)
    z = {True: [], False: []}
    for _ in range(150):
        run = docking_run(rng, 6)
        shift = 0.1 * rng.standard_normal((2, 2))
        frames = [(IDS, np.vstack([f.uv_a, f.uv_b]) + shift[SECTION] + 0.05 * rng.standard_normal((len(IDS), 2)))
                  for f in run.frames]
        for told in (True, False):
            opts = replace(DEFAULT_DOCKING, section_shift_px=(0.1, 0.1) if told else None, run_marker_bias=False)
            res = solve_sequence(LAYOUT, run.frames[0].image_centre, frames, options=opts)
            z[told] += [_z(fr, sc.d_from_b) for fr, sc in zip(res.frames, run.frames)]
    on, off = (np.sqrt(np.mean(np.square(z[t]), axis=0)) for t in (True, False))
    print("told", on.round(2), "not told", off.round(2))
    assert np.all((on > 0.85) & (on < 1.2)), on
    assert np.all(off[:2] > 1.4), off
