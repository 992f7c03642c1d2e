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


def test_factor_is_the_kernel_within_sections():
    """F F^T equals exp(-d / L) per axis between points of one group to 1e-3 of the largest
    eigenvalue, and 0 between groups and between axes."""
    rng = np.random.default_rng(0)
    pts = rng.uniform(0, 1000, (40, 2))
    groups = np.repeat(["A", "B"], 20)
    f = spatial_bias_factor(pts, groups, 250.0)
    k = f @ f.T
    d = np.hypot(*(pts[:, None, :] - pts[None, :, :]).transpose(2, 0, 1))
    want = np.exp(-d / 250.0) * (groups[:, None] == groups[None, :])
    assert np.allclose(k[0::2, 0::2], want, atol=1e-3 * np.linalg.eigvalsh(want)[-1])
    assert np.allclose(k[1::2, 1::2], k[0::2, 0::2]) and np.allclose(k[0::2, 1::2], 0.0)
    assert np.allclose(k[:40, 40:], 0.0)


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
    0.85-1.2 (measured 0.87 / 1.14 / 0.94); without it every component is under-covered beyond
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
