"""The covariance's noise prior (solver.refine.scale_with_prior, RefineOptions.noise_prior_px): a
noise scale estimated from few residuals is pulled up toward the noise the camera is known to have,
never down; the pose itself does not change. Synthetic frames, seeded; the figures are exact
(closed forms) or ratios of the same solve with and without the prior."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from dockfactory.eval.solve_frames import docking_options, with_class_prior
from dockfactory.solver import DockingOptions, InvalidSolverInput, solve_docking
from dockfactory.solver.options import RefineOptions
from dockfactory.solver.refine import NOISE_PRIOR_DOF, scale_with_prior, student_t_factor
from dockfactory.solver.synthetic import default_layout, docking_scene

from test_disc_noise import _image_centroids  # sibling test module (rootdir on sys.path)

LAYOUT = default_layout()
CLASSES = np.array([0 if m.section == "A" else 1 for m in LAYOUT])


def test_the_law():
    # no prior, or residuals above it: the estimate with its own Student-t factor
    assert scale_with_prior(0.04, 15, None) == (0.04, 0.04 * student_t_factor(15))
    assert scale_with_prior(0.04, 15, 0.01) == (0.04, 0.04 * student_t_factor(15))
    # residuals far below it at 3 dof: the conjugate mean with nu0 pseudo dof, its factor at 3 + nu0
    s2, k2 = scale_with_prior(1e-6, 3, 0.01)
    want = (3 * 1e-6 + NOISE_PRIOR_DOF * 0.01) / (3 + NOISE_PRIOR_DOF)
    assert s2 == pytest.approx(want) and k2 == pytest.approx(max(3e-6, want * student_t_factor(3 + NOISE_PRIOR_DOF)))
    # never below the estimate's own scale, and more dof weigh the residuals more
    assert scale_with_prior(0.009, 40, 0.01)[1] >= 0.009 * student_t_factor(40)
    assert scale_with_prior(1e-6, 40, 0.01)[0] < scale_with_prior(1e-6, 3, 0.01)[0]


def _solve(sc, uv, prior):
    options = DockingOptions(refine=RefineOptions(noise_prior_px=prior))
    return solve_docking(LAYOUT, sc.principal_point, detections=(CLASSES, uv), options=options)


@pytest.mark.parametrize("noise, pulled", [(0.001, True), (0.3, False)])
def test_a_fit_quieter_than_the_camera_is_pulled_up_and_a_noisier_one_is_not(noise, pulled):
    """Centres at 0.001 px against a camera known to have 0.05 px: the reported std grows (by about
    the ratio of the noises, shrunk by the fit's own dof) and the pose is the same; at 0.3 px the
    prior changes nothing."""
    rng = np.random.default_rng(5)
    sc = docking_scene(rng)
    uv = _image_centroids(sc) + noise * rng.standard_normal((len(LAYOUT), 2))
    plain, prior = _solve(sc, uv, None), _solve(sc, uv, 0.05)
    assert prior.x_mm == plain.x_mm and prior.alpha_deg == plain.alpha_deg
    ratio = prior.std["x_mm"] / plain.std["x_mm"]
    if pulled:
        assert 10 < ratio < 50 and prior.sigma_px > 0.05 * np.sqrt(NOISE_PRIOR_DOF / (2 * len(LAYOUT)))
    else:
        assert ratio == pytest.approx(1.0, rel=1e-12)


def test_the_prior_is_the_camera_class_s_and_checked():
    base = docking_options(0.02, None, None, 0.007)
    assert base.refine.noise_prior_px == 0.007 and base.refine.sigma_floor_px == 0.02
    assert with_class_prior(base, 7.9).refine.noise_prior_px == pytest.approx(0.007 * 7.9)
    assert with_class_prior(docking_options(0.02), 7.9).refine.noise_prior_px is None
    with pytest.raises(InvalidSolverInput):
        replace(base.refine, noise_prior_px=-1.0)
