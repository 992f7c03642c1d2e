"""The bound on d_from_b when the centres' errors are correlated (solver.crb.crb_d_from_b_structured).

Detected centres share errors within a frame and each marker has its own noise, so the bound of
independent centres is not the bound of the frame. On one synthetic docking frame with disc-shaped
noise, each marker's variance scaled 0.5-2x and a shared offset per section:
- the structured bound is the RMSE of the efficient (full-covariance weighted) fit, and the
  sandwich is the RMSE of the fit weighted by the per-point shapes only (as the solver weights),
  Monte-Carlo within 10 % (400 draws: an RMS to 3.5 %, 10 % is 2.8 standard errors);
- the bound is at most the sandwich; both equal crb_d_from_b's when the covariance is block
  diagonal and proportional to the weights;
- a covariance of the wrong size or not positive definite is refused. Seeded throughout.
"""
from __future__ import annotations

import numpy as np
import pytest

from dockfactory.core.geometry import pose_components
from dockfactory.solver import InvalidSolverInput, crb_d_from_b
from dockfactory.solver.crb import crb_d_from_b_structured
from dockfactory.solver.disc_noise import section_noise_shapes
from dockfactory.solver.lie import so3_exp
from dockfactory.solver.refine import joint_jacobian, relative_pose, residuals_and_jacobian
from dockfactory.solver.synthetic import default_layout, docking_scene

LAYOUT = default_layout()
KEYS = ("x_mm", "y_mm", "alpha_deg")
SIGMA, SHARED = 0.1, 0.06      # px: per-axis noise of a centre, std of a section's shared offset


def _scene():
    rng = np.random.default_rng(31)
    sc = docking_scene(rng)
    shapes = np.concatenate([section_noise_shapes([m for m in LAYOUT if m.section == s], cam, sc.focal_px)
                             for s, cam in (("A", sc.cam_from_d), ("B", sc.cam_from_b))])
    shapes = shapes / (np.trace(shapes, axis1=1, axis2=2).mean() / 2.0)
    return sc, shapes, rng


def _structured_covariance(sc, shapes, rng) -> np.ndarray:
    """(2N, 2N) px^2: own noise SIGMA^2 T_i x a factor 0.5-2 per marker, plus a shared offset per section."""
    n, na = len(shapes), len(sc.points_a)
    cov = np.zeros((2 * n, 2 * n))
    for i, f in enumerate(rng.uniform(0.5, 2.0, n)):
        cov[2 * i:2 * i + 2, 2 * i:2 * i + 2] = f * SIGMA ** 2 * shapes[i]
    section = np.repeat(np.arange(n) >= na, 2)
    same = section[:, None] == section[None, :]
    axis = np.tile(np.eye(2), (n, n)).astype(bool)
    return cov + SHARED ** 2 * (same & axis)


def _fit(sc, uv, weight, iterations=4) -> np.ndarray:
    """Gauss-Newton from the truth of the cost r^T W r (W (2N, 2N)): X, Y, alpha errors."""
    ca, cb, na = sc.cam_from_d, sc.cam_from_b, len(sc.points_a)
    st = [ca[:3, :3], ca[:3, 3], cb[:3, :3], cb[:3, 3], sc.focal_px]
    for _ in range(iterations):
        ra, ja, _ = residuals_and_jacobian(sc.points_a, uv[:na], sc.principal_point, st[0], st[1], st[4])
        rb, jb, _ = residuals_and_jacobian(sc.points_b, uv[na:], sc.principal_point, st[2], st[3], st[4])
        r, j = np.concatenate([ra, rb]), joint_jacobian(ja, jb)
        d = np.linalg.solve(j.T @ weight @ j, -j.T @ weight @ r)
        st = [so3_exp(d[:3]) @ st[0], st[1] + d[3:6], so3_exp(d[6:9]) @ st[2], st[3] + d[9:12], st[4] + d[12]]
    est, truth = pose_components(relative_pose(*st[:4])), pose_components(sc.d_from_b)
    return np.array([est[k] - truth[k] for k in KEYS])


def _block_inverse(shapes) -> np.ndarray:
    w = np.zeros((2 * len(shapes),) * 2)
    for i, t in enumerate(np.linalg.inv(shapes)):
        w[2 * i:2 * i + 2, 2 * i:2 * i + 2] = t
    return w


@pytest.fixture(scope="module")
def monte_carlo():
    sc, shapes, rng = _scene()
    cov = _structured_covariance(sc, shapes, rng)
    chol, full, block = np.linalg.cholesky(cov), np.linalg.inv(cov), _block_inverse(shapes)
    uv0 = np.vstack([sc.uv_a, sc.uv_b])
    efficient, weighted = [], []
    for _ in range(400):
        uv = uv0 + (chol @ rng.normal(size=len(cov))).reshape(-1, 2)
        efficient.append(_fit(sc, uv, full))
        weighted.append(_fit(sc, uv, block))
    rms = [np.sqrt(np.mean(np.square(e), axis=0)) for e in (efficient, weighted)]
    return sc, shapes, cov, rms[0], rms[1]


def _args(sc):
    return sc.points_a, sc.cam_from_d, sc.points_b, sc.cam_from_b, sc.focal_px, sc.principal_point


def test_the_structured_bound_and_sandwich_are_the_monte_carlo_rmse(monte_carlo):
    sc, shapes, cov, rms_efficient, rms_weighted = monte_carlo
    bound, fit = crb_d_from_b_structured(*_args(sc), cov, shapes)
    assert rms_efficient / np.array([bound.std[k] for k in KEYS]) == pytest.approx(np.ones(3), abs=0.10)
    assert rms_weighted / np.array([fit.std[k] for k in KEYS]) == pytest.approx(np.ones(3), abs=0.10)
    # the independent bound at the same per-axis noise is another number (the structure matters)
    independent = crb_d_from_b(*_args(sc), float(np.sqrt(np.diag(cov).mean())), noise_shapes=(
        shapes[:len(sc.points_a)], shapes[len(sc.points_a):]))
    assert max(abs(independent.std[k] / bound.std[k] - 1) for k in KEYS) > 0.05


def test_the_bound_is_at_most_the_weighted_fits_covariance(monte_carlo):
    sc, shapes, cov, _, _ = monte_carlo
    bound, fit = crb_d_from_b_structured(*_args(sc), cov, shapes)
    gap = np.linalg.eigvalsh(fit.covariance - bound.covariance)
    assert gap.min() >= -1e-9 * np.abs(fit.covariance).max()


def test_a_block_diagonal_covariance_gives_the_independent_bound():
    sc, shapes, _ = _scene()
    cov = SIGMA ** 2 * np.linalg.inv(_block_inverse(shapes))
    bound, fit = crb_d_from_b_structured(*_args(sc), cov, 3.0 * shapes)
    na = len(sc.points_a)
    ref = crb_d_from_b(*_args(sc), SIGMA, noise_shapes=(shapes[:na], shapes[na:]))
    for b in (bound, fit):
        assert b.covariance == pytest.approx(ref.covariance, rel=1e-8, abs=1e-14)


def test_a_bad_covariance_is_refused():
    sc, shapes, _ = _scene()
    n = 2 * len(shapes)
    with pytest.raises(InvalidSolverInput, match="covariance"):
        crb_d_from_b_structured(*_args(sc), np.eye(n - 2), shapes)
    with pytest.raises(InvalidSolverInput, match="positive definite"):
        crb_d_from_b_structured(*_args(sc), -np.eye(n), shapes)
