"""A docking run's centre errors that persist over the run and correlate between nearby markers of
a section (a bias field over the image: lighting, blur and colour effects that a fixed camera
repeats): ``solver.model_error.spatial_bias_factor`` and the run covariance that carries them
(``solver.solve_sequence`` with ``run_marker_bias``).

Tolerances: 200 seeded runs of 8 frames give an RMS z to about 1 / sqrt(200) = 7 % per component
where the run-level error dominates; the band is the issue's, 0.85-1.2."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from dockfactory.core.geometry import pose_components
from dockfactory.solver import solve_sequence
from dockfactory.solver.model_error import BIAS_LENGTH, spatial_bias_factor
from dockfactory.solver.options import DEFAULT_DOCKING
from dockfactory.solver.synthetic import default_layout, docking_run

LAYOUT = default_layout()
IDS = [m.id for m in LAYOUT]
SECTION = np.array([m.section for m in LAYOUT])
COMPONENTS = ("x_mm", "y_mm", "alpha_deg")


def _kernels(n, rng):
    pts = rng.uniform(0, 1, (n, 2)) * [1280, 960]
    groups = np.repeat(["A", "B"], n // 2)
    k = spatial_bias_factor(pts, groups, 300.0, (1280, 960))
    d = np.hypot(*(pts[:, None, :] - pts[None, :, :]).transpose(2, 0, 1))
    return k, np.exp(-d / 300.0), d, groups[:, None] == groups[None, :]


def test_factor_is_the_kernel_within_sections():
    """Up to the image's inducing points (here 2 x 20 x 15) F F^T is exp(-d / L) per axis
    between points of one group to 1e-6, 0 between groups and between axes."""
    f, want, _, same = _kernels(400, np.random.default_rng(0))
    k = f @ f.T
    assert np.allclose(k[0::2, 0::2], want * same, atol=1e-6) and np.allclose(k[1::2, 1::2], k[0::2, 0::2])
    assert np.allclose(k[0::2, 1::2], 0.0)


def test_factor_of_a_long_run_is_bounded_and_close():
    """Beyond them (1,000 points) F keeps the grid's columns (as many as for 700 points) and F F^T
    follows the kernel beyond half a correlation length (each distance bin's mean within 0.01,
    every pair within 0.1), keeps 0.8-1.0 of the variance at a point, 0 between groups."""
    rng = np.random.default_rng(1)
    f, want, d, same = _kernels(1000, rng)
    assert f.shape[1] == _kernels(700, rng)[0].shape[1] < 2 * 1000
    kx = (f @ f.T)[0::2, 0::2]
    for lo, hi in ((150, 300), (300, 600), (600, 2000)):
        m = same & (d > lo) & (d <= hi)
        assert abs(kx[m].mean() - want[m].mean()) < 0.01 and np.abs(kx[m] - want[m]).max() < 0.1
    assert 0.8 < np.diag(kx).min() and np.diag(kx).max() <= 1.0 + 1e-9 and np.allclose(kx[~same], 0.0)


def _biased_run(rng, n_frames=8, sigma=0.1, tau=0.12):
    """(run, frames): centres with white noise ``sigma`` plus a bias field of std ``tau`` per
    axis, one per section and run, correlated exp(-d / L) over the image (L = BIAS_LENGTH image
    diagonals): the same field in every frame of the run."""
    run = docking_run(rng, n_frames)
    uv = np.concatenate([np.vstack([f.uv_a, f.uv_b]) for f in run.frames])
    groups = np.tile(SECTION, n_frames)
    width, height = run.frames[0].image_size
    length = BIAS_LENGTH * float(np.hypot(width, height))
    d = np.hypot(*(uv[:, None, :] - uv[None, :, :]).transpose(2, 0, 1))
    kernel = np.exp(-d / length) * (groups[:, None] == groups[None, :])
    chol = np.linalg.cholesky(kernel + 1e-9 * np.eye(len(uv)))
    field = tau * chol @ rng.standard_normal((len(uv), 2))
    noisy = uv + field + sigma * rng.standard_normal(uv.shape)
    return run, [(IDS, part) for part in np.split(noisy, n_frames)]


@pytest.mark.slow   # 200 synthetic runs of 8 frames, each solved twice (about 15 s)
def test_run_covariance_covers_a_persistent_bias_field():
    """With the run-bias term (the default) the RMS z of X, Y and alpha over 200 runs is within
    0.85-1.2 (measured 0.87 / 1.13 / 0.94); without it every component is under-covered beyond
    1.25 (measured 1.46 / 1.60 / 1.78): the field repeats in every frame, so averaging the
    frames does not shrink it."""
    rng = np.random.default_rng(2912)
    z = {True: [], False: []}
    for _ in range(200):
        run, frames = _biased_run(rng)
        for on in (True, False):
            res = solve_sequence(LAYOUT, run.frames[0].image_centre, frames,
                                 options=replace(DEFAULT_DOCKING, run_marker_bias=on))
            for fr, sc in zip(res.frames, run.frames):
                truth = pose_components(sc.d_from_b)
                z[on].append([(getattr(fr, k) - truth[k]) / fr.std[k] for k in COMPONENTS])
    on, off = (np.sqrt(np.mean(np.square(z[t]), axis=0)) for t in (True, False))
    assert np.all((on > 0.85) & (on < 1.2)), on
    assert np.all(off > 1.25), off


@pytest.mark.slow   # 300 synthetic runs of 8 frames
def test_run_reports_the_bias_field_it_finds():
    """``bias_px``: over 200 runs with a field of std 0.12 px the median is within 15 % of it and
    at least 85 % of the runs count one (measured 0.117 px, 92 %); over 100 runs of white noise
    alone at most 10 % do (BIAS_ALPHA 5 %; measured 5 %)."""
    rng = np.random.default_rng(2912)
    found = []
    for _ in range(200):
        run, frames = _biased_run(rng)
        found.append(solve_sequence(LAYOUT, run.frames[0].image_centre, frames).bias_px)
    assert np.median(found) == pytest.approx(0.12, rel=0.15) and np.mean(np.array(found) > 0) >= 0.85
    rng = np.random.default_rng(5)
    white = []
    for _ in range(100):
        run, frames = _biased_run(rng, tau=0.0)
        white.append(solve_sequence(LAYOUT, run.frames[0].image_centre, frames).bias_px)
    assert np.mean(np.array(white) > 0) <= 0.10
