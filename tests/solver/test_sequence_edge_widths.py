"""A docking run told the detector's edge widths (``solve_sequence(edge_px=...)``): the inputs are
checked, widths not told change nothing, and the run's covariance follows the noise of discs that
are thin for their blur (solver.disc_noise.thin_disc_factor).

Tolerances: 120 seeded runs of 6 frames give an RMS z to about 1 / sqrt(240) = 6.5 % per
component; 0.85-1.2 is the issue's band (measured values in the test's docstring)."""
from __future__ import annotations

import numpy as np
import pytest

from dockfactory.core.geometry import pose_components
from dockfactory.solver import InvalidSolverInput, solve_sequence
from dockfactory.solver.disc_noise import section_noise_shapes
from dockfactory.solver.synthetic import default_layout, docking_run

from test_disc_noise import _noise_cov  # sibling test module (rootdir on sys.path)
from test_thin_disc_noise import section_ellipse

LAYOUT = default_layout()
IDS = [m.id for m in LAYOUT]
COMPONENTS = ("x_mm", "y_mm", "alpha_deg")


def _cams(scene) -> dict:
    return {"A": scene.cam_from_d, "B": scene.cam_from_d @ scene.d_from_b}


def _thin_run(rng, n_frames=6, sigma=0.1):
    """(run, frames [(ids, uv)], edge widths [{id: px}]): every frame's centres with the disc
    noise of its markers, the minor-axis term times the thin-disc factor of widths that make
    each disc 1.2-6 edge widths thick (drawn once per marker: its blur persists over the run)."""
    run = docking_run(rng, n_frames)
    thickness = rng.uniform(1.2, 6.0, len(LAYOUT))
    frames, widths = [], []
    for sc in run.frames:
        cams = _cams(sc)
        minor = np.array([np.sqrt(np.linalg.eigvalsh(section_ellipse(m, cams[m.section], sc.focal_px))[0])
                          for m in LAYOUT])
        edge = minor / thickness
        shapes = np.concatenate([section_noise_shapes([m], cams[m.section], sc.focal_px, edge[[k]])
                                 for k, m in enumerate(LAYOUT)])
        chol = np.linalg.cholesky(_noise_cov(shapes, sigma))
        uv = np.vstack([sc.uv_a, sc.uv_b]) + np.einsum("nij,nj->ni", chol, rng.normal(size=(len(LAYOUT), 2)))
        frames.append((IDS, uv))
        widths.append(dict(zip(IDS, edge.tolist())))
    return run, frames, widths


def test_edge_widths_are_checked():
    """One entry per frame, a mapping of the frame's own markers to finite widths >= 0."""
    run, frames, widths = _thin_run(np.random.default_rng(3), n_frames=3)
    pp = run.frames[0].image_centre
    bad = [(widths[:2], "3 frames"), ([widths[0], widths[1], [1.0] * len(IDS)], "mapping"),
           ([widths[0], widths[1], {**widths[2], "Z99": 1.0}], "Z99"),
           ([widths[0], widths[1], {IDS[0]: -1.0}], ">= 0"),
           ([widths[0], widths[1], {IDS[0]: float("inf")}], "inf")]
    for value, words in bad:
        with pytest.raises(InvalidSolverInput, match=f"edge_px.*{words}|{words}.*edge_px|frame 2: edge_px"):
            solve_sequence(LAYOUT, pp, frames, edge_px=value)


def test_widths_not_told_change_nothing():
    """None, None per frame, empty mappings and NaN widths all give the covariance of a run
    solved without edge widths (to 1e-12 relative)."""
    run, frames, widths = _thin_run(np.random.default_rng(4), n_frames=4)
    pp = run.frames[0].image_centre
    plain = solve_sequence(LAYOUT, pp, frames)
    for value in (None, [None] * 4, [{}] * 4, [{i: float("nan") for i in IDS}] * 4):
        other = solve_sequence(LAYOUT, pp, frames, edge_px=value)
        for a, b in zip(plain.frames, other.frames):
            assert np.allclose(a.covariance, b.covariance, rtol=1e-12, atol=0.0)
    told = solve_sequence(LAYOUT, pp, frames, edge_px=widths)
    assert all(t.std["y_mm"] > p.std["y_mm"] for t, p in zip(told.frames, plain.frames))


@pytest.mark.slow   # 120 synthetic runs of 6 frames, each solved twice
def test_run_covariance_follows_thin_disc_noise_when_told_the_edge_widths():
    """Thin-disc noise over whole runs: told the edge widths, every RMS z of X, Y and alpha is
    within 0.85-1.2 (measured 1.04 / 1.03 / 1.00); not told, Y is under-covered beyond 1.2
    (measured 1.32; X and alpha over-covered, 0.88 / 0.81)."""
    rng = np.random.default_rng(2611)
    z = {True: [], False: []}
    for _ in range(120):
        run, frames, widths = _thin_run(rng)
        for told in (True, False):
            res = solve_sequence(LAYOUT, run.frames[0].image_centre, frames, edge_px=widths if told else None)
            for fr, sc in zip(res.frames, run.frames):
                truth = pose_components(sc.d_from_b)
                z[told].append([(getattr(fr, k) - truth[k]) / fr.std[k] for k in COMPONENTS])
    told, blind = (np.sqrt(np.mean(np.square(z[t]), axis=0)) for t in (True, False))
    assert np.all((told > 0.85) & (told < 1.2)), told
    assert blind[1] > 1.2, blind
