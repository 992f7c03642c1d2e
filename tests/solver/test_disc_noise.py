"""Centre noise shaped by the disc's image: the bound, the solver's covariance and the scale (issue 12).

The detector's centres scatter more the thinner a disc's image is (solver.disc_noise). With such
noise:
- the Cramer-Rao bound with per-point noise shapes (solver.crb ``noise_shapes``) is the RMSE of the
  efficient (weighted maximum-likelihood) estimator, Monte-Carlo within 10 %, and the unweighted
  fit errs more than it;
- the covariance of the solver's unweighted fit is the sandwich (covariance_from_jacobian with
  ``point_cov``), and solve_docking's reported std gives RMS z within 0.88-1.12 over 240 frames
  (isotropic: X above 1.1);
- the bound's scale comes from the Fisher information of the whitened centre errors (a Student t
  fit), which gross errors do not inflate the way they inflate the RMS.
Tolerances: 400 Monte-Carlo draws give an RMS to 1 / sqrt(800) = 3.5 % (10 % is 2.8 standard
errors); 240 frames give RMS z to 4.6 % (0.12 is 2.6 standard errors). Seeded throughout.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from dockfactory.core.geometry import polygon_area_centroid, pose_components, transform_points
from dockfactory.core.layout import marker_outline
from dockfactory.eval.centre_noise_disc import frame_noise_px, label_noise_shapes, scale_stats
from dockfactory.solver import DockingOptions, InvalidSolverInput, crb_d_from_b, solve_docking
from dockfactory.solver.disc_noise import (
    MINOR_EXPONENT,
    NOISE_FLOOR,
    REFERENCE_RADIUS_PX,
    disc_ellipses,
    noise_shapes,
    section_noise_shapes,
)
from dockfactory.solver.lie import so3_exp
from dockfactory.solver.refine import (
    covariance_from_jacobian,
    d_from_b_jacobian,
    joint_jacobian,
    refine_joint,
    relative_pose,
    residuals_and_jacobian,
)
from dockfactory.solver.synthetic import default_layout, docking_scene

LAYOUT = default_layout()
KEYS = ("x_mm", "y_mm", "alpha_deg")
SIGMA = 0.1          # px per axis, averaged over the points


def _shapes(sc) -> tuple[np.ndarray, np.ndarray]:
    return (section_noise_shapes([m for m in LAYOUT if m.section == "A"], sc.cam_from_d, sc.focal_px),
            section_noise_shapes([m for m in LAYOUT if m.section == "B"], sc.cam_from_b, sc.focal_px))


def _noise_cov(shapes: np.ndarray, sigma: float) -> np.ndarray:
    """(N, 2, 2) px^2: shapes scaled to a per-axis noise ``sigma`` averaged over the points."""
    return sigma ** 2 * shapes / (np.trace(shapes, axis1=1, axis2=2).mean() / 2.0)


def _joint_jac(sc, uv_a, uv_b, state):
    ra, ja, _ = residuals_and_jacobian(sc.points_a, uv_a, sc.principal_point, state[0], state[1], state[4])
    rb, jb, _ = residuals_and_jacobian(sc.points_b, uv_b, sc.principal_point, state[2], state[3], state[4])
    return np.concatenate([ra, rb]), joint_jacobian(ja, jb)


def _weighted_fit(sc, uv_a, uv_b, cov_inv, iterations=4) -> dict:
    """Gauss-Newton of the weighted (maximum-likelihood) cost from the truth: pose components."""
    ca, cb = sc.cam_from_d, sc.cam_from_b
    st = [ca[:3, :3], ca[:3, 3], cb[:3, :3], cb[:3, 3], sc.focal_px]
    for _ in range(iterations):
        r, j = _joint_jac(sc, uv_a, uv_b, st)
        jr = j.reshape(-1, 2, 13)
        h = np.einsum("nap,nab,nbq->pq", jr, cov_inv, jr)
        d = np.linalg.solve(h, -np.einsum("nap,nab,nb->p", jr, cov_inv, r.reshape(-1, 2)))
        st = [so3_exp(d[:3]) @ st[0], st[1] + d[3:6], so3_exp(d[6:9]) @ st[2], st[3] + d[9:12], st[4] + d[12]]
    return pose_components(relative_pose(*st[:4]))


@pytest.fixture(scope="module")
def monte_carlo():
    """One docking frame, 400 draws of disc-shaped noise: errors of the weighted fit and of the
    solver's unweighted joint LM, the scene and its shapes."""
    rng = np.random.default_rng(7)
    sc = docking_scene(rng)
    ta, tb = _shapes(sc)
    cov = _noise_cov(np.concatenate([ta, tb]), SIGMA)
    chol, cov_inv, na = np.linalg.cholesky(cov), np.linalg.inv(cov), len(ta)
    truth = pose_components(sc.d_from_b)
    ca, cb = sc.cam_from_d, sc.cam_from_b
    weighted, plain = [], []
    for _ in range(400):
        z = np.einsum("nij,nj->ni", chol, rng.normal(size=(len(cov), 2)))
        uv_a, uv_b = sc.uv_a + z[:na], sc.uv_b + z[na:]
        est = _weighted_fit(sc, uv_a, uv_b, cov_inv)
        weighted.append([est[k] - truth[k] for k in KEYS])
        jr = refine_joint(sc.points_a, uv_a, sc.points_b, uv_b, sc.principal_point, ca[:3, :3], ca[:3, 3],
                          cb[:3, :3], cb[:3, 3], sc.focal_px)
        est = pose_components(relative_pose(jr.rotation_a, jr.translation_a, jr.rotation_b, jr.translation_b))
        plain.append([est[k] - truth[k] for k in KEYS])
    return sc, (ta, tb), np.sqrt(np.mean(np.square(weighted), axis=0)), np.sqrt(np.mean(np.square(plain), axis=0))


def test_the_bound_with_disc_shaped_noise_is_the_rmse_of_the_efficient_estimator(monte_carlo):
    sc, shapes, rmse_weighted, rmse_plain = monte_carlo
    args = (sc.points_a, sc.cam_from_d, sc.points_b, sc.cam_from_b, sc.focal_px, sc.principal_point, SIGMA)
    shaped = np.array([crb_d_from_b(*args, noise_shapes=shapes).std[k] for k in KEYS])
    iso = np.array([crb_d_from_b(*args).std[k] for k in KEYS])
    assert rmse_weighted / shaped == pytest.approx(np.ones(3), abs=0.10)
    # the unweighted fit, which ignores the shapes, errs more than the bound (measured 1.19 / 1.21 /
    # 1.27x): a thin disc's centre is worth less than a round one's
    assert np.all(rmse_plain / shaped > 1.1)
    assert not np.allclose(iso, shaped, rtol=0.05)      # the isotropic bound is another number
    # the shapes' scale does not matter, only their form
    scaled = crb_d_from_b(*args, noise_shapes=(5.0 * shapes[0], 5.0 * shapes[1])).std
    assert [scaled[k] for k in KEYS] == pytest.approx(shaped.tolist(), rel=1e-9)


def test_the_covariance_of_the_unweighted_fit_is_the_sandwich(monte_carlo):
    sc, (ta, tb), _, rmse_plain = monte_carlo
    ca, cb = sc.cam_from_d, sc.cam_from_b
    _, jac = _joint_jac(sc, sc.uv_a, sc.uv_b, [ca[:3, :3], ca[:3, 3], cb[:3, :3], cb[:3, 3], sc.focal_px])
    prop = d_from_b_jacobian(ca[:3, :3], ca[:3, 3], cb[:3, :3], cb[:3, 3])
    zero = np.zeros(jac.shape[0])
    cov, sigma = covariance_from_jacobian(jac, zero, SIGMA, point_cov=np.concatenate([ta, tb]))
    std = np.sqrt(np.diag(prop @ cov[:12, :12] @ prop.T))[[0, 1, 3]]
    assert sigma == pytest.approx(SIGMA, rel=1e-12)
    assert rmse_plain / std == pytest.approx(np.ones(3), abs=0.10)
    iso, _ = covariance_from_jacobian(jac, zero, SIGMA)
    iso_std = np.sqrt(np.diag(prop @ iso[:12, :12] @ prop.T))[[0, 1, 3]]
    # the isotropic covariance at the same per-axis noise understates the errors (measured X / Y /
    # alpha 1.16 / 1.23 / 1.08x): its noise is spread evenly over thin and round discs
    assert rmse_plain[1] / iso_std[1] > 1.12 and rmse_plain[0] / iso_std[0] > 1.08


def test_identity_shapes_give_the_isotropic_covariance_and_bound():
    rng = np.random.default_rng(3)
    jac, res = rng.normal(size=(28, 13)), rng.normal(0.0, 0.1, 28)
    eye = np.tile(np.eye(2), (14, 1, 1))
    for sigma, floor in ((None, None), (None, 0.5), (0.2, None)):
        cov, s = covariance_from_jacobian(jac, res, sigma, floor)
        for c in (1.0, 3.0):    # any multiple of I: sigma is per-axis noise, not the shapes' scale
            cov_i, s_i = covariance_from_jacobian(jac, res, sigma, floor, point_cov=c * eye)
            assert cov_i == pytest.approx(cov, rel=1e-9) and s_i == pytest.approx(s, rel=1e-12)
    sc = docking_scene(np.random.default_rng(5))
    args = (sc.points_a, sc.cam_from_d, sc.points_b, sc.cam_from_b, sc.focal_px, sc.principal_point, 0.1)
    ones = (np.tile(np.eye(2), (len(sc.points_a), 1, 1)), np.tile(np.eye(2), (len(sc.points_b), 1, 1)))
    for problem in ("joint", "independent", "calibrated"):
        a = crb_d_from_b(*args, problem=problem).covariance
        b = crb_d_from_b(*args, problem=problem, noise_shapes=ones).covariance
        assert b == pytest.approx(a, rel=1e-9)


def test_bad_noise_shapes_are_refused():
    sc = docking_scene(np.random.default_rng(5))
    args = (sc.points_a, sc.cam_from_d, sc.points_b, sc.cam_from_b, sc.focal_px, sc.principal_point, 0.1)
    na, nb = len(sc.points_a), len(sc.points_b)
    good = np.tile(np.eye(2), (nb, 1, 1))
    for bad in (np.tile(np.eye(2), (na - 1, 1, 1)),                     # one short
                np.tile([[1.0, 2.0], [2.0, 1.0]], (na, 1, 1)),         # not positive definite
                np.tile([[1.0, 0.1], [0.0, 1.0]], (na, 1, 1)),         # not symmetric
                np.full((na, 2, 2), np.nan)):
        with pytest.raises(InvalidSolverInput, match="noise_shapes"):
            crb_d_from_b(*args, noise_shapes=(bad, good))
    with pytest.raises(InvalidSolverInput, match="pair"):
        crb_d_from_b(*args, noise_shapes=good)


def test_noise_shapes_follow_the_minor_axis_law():
    # a disc whose minor semi-axis is the reference radius: T = I, whatever its major axis
    for major in (REFERENCE_RADIUS_PX, 25.0):
        s = np.diag([major ** 2, REFERENCE_RADIUS_PX ** 2])
        assert noise_shapes(s[None])[0] == pytest.approx(np.eye(2), abs=1e-12)
    # semi-axes 12 and 4 px, major axis at 30 deg: isotropic, ((10 / 4)^p + floor) / (1 + floor)
    u = np.array([math.cos(math.radians(30)), math.sin(math.radians(30))])
    v = np.array([-u[1], u[0]])
    t = noise_shapes((144.0 * np.outer(u, u) + 16.0 * np.outer(v, v))[None])[0]
    want = (2.5 ** MINOR_EXPONENT + NOISE_FLOOR) / (1.0 + NOISE_FLOOR)
    assert t == pytest.approx(want * np.eye(2), rel=1e-9)
    # thinner discs are noisier, larger ones quieter, never below the floor's share
    minors = np.array([2.0, 5.0, 10.0, 40.0, 1e4])
    var = noise_shapes(np.stack([np.diag([1e8, b * b]) for b in minors]))[:, 0, 0]
    assert np.all(np.diff(var) < 0) and var[-1] == pytest.approx(NOISE_FLOOR / (1.0 + NOISE_FLOOR), rel=1e-6)


@pytest.mark.parametrize("seed", range(3))
def test_disc_ellipses_match_the_projected_outline(seed):
    """The first-order ellipse of a disc is the second moment of its projected outline (the
    outline's points are at equal angles on the disc: their covariance is S / 2)."""
    sc = docking_scene(np.random.default_rng(seed))
    cams = {"A": sc.cam_from_d, "B": sc.cam_from_b}
    for m in LAYOUT:
        cam = cams[m.section]
        pc = transform_points(cam, marker_outline(m, 64))
        uv = sc.focal_px * pc[:, :2] / pc[:, 2:3]
        s_outline = 2.0 * np.cov(uv.T, bias=True)
        centre = transform_points(cam, np.asarray(m.center_mm)[None])
        s = disc_ellipses(centre, np.asarray(m.normal)[None] @ cam[:3, :3].T, [m.diameter_mm], sc.focal_px)[0]
        assert s == pytest.approx(s_outline, rel=0.02, abs=0.02 * np.trace(s_outline))


def test_label_shapes_are_the_section_shapes():
    """eval's shapes from a label's D-frame geometry equal the solver's from the layout."""
    sc = docking_scene(np.random.default_rng(9))
    cams = {"A": sc.cam_from_d, "B": sc.cam_from_b}
    d_from = {"A": np.eye(4), "B": sc.d_from_b}
    marks = [{"center_d_mm": transform_points(d_from[m.section], np.asarray(m.center_mm)[None])[0].tolist(),
              "normal_d": (d_from[m.section][:3, :3] @ np.asarray(m.normal)).tolist(),
              "diameter_mm": m.diameter_mm} for m in LAYOUT]
    label = {"camera": {"cam_from_d": sc.cam_from_d.tolist(), "focal_px": sc.focal_px}}
    expect = np.concatenate([section_noise_shapes([m], cams[m.section], sc.focal_px) for m in LAYOUT])
    got = label_noise_shapes(label, marks)
    assert got == pytest.approx(expect, rel=1e-9, abs=1e-12)
    assert label_noise_shapes({"camera": label["camera"]}, [{"center_d_mm": [0, 0, 1]}]) is None
    assert frame_noise_px(np.tile(4.0 * np.eye(2), (3, 1, 1)), 0.05) == pytest.approx(0.1)


def test_the_bound_scale_is_the_core_not_the_gross_errors():
    rng = np.random.default_rng(4)
    core = rng.normal(0.0, 0.06, (800, 2))
    gaussian = scale_stats(np.sum(core ** 2, axis=1))
    assert gaussian["fisher_px"] == pytest.approx(0.06, rel=0.05)
    assert gaussian["fisher_px"] == pytest.approx(gaussian["rms_px"], rel=0.05)
    gross = np.vstack([core, rng.normal(0.0, 1.5, (8, 2))])     # 1 % of centres 2 px off
    mixed = scale_stats(np.sum(gross ** 2, axis=1))
    assert mixed["rms_px"] > 2.0 * 0.06                          # the RMS is theirs
    assert mixed["fisher_px"] == pytest.approx(0.06, rel=0.10)   # the Fisher information is the core's
    assert mixed["t_dof"] is not None and mixed["t_dof"] < 30
    assert scale_stats(np.zeros(0))["fisher_px"] is None and scale_stats(np.zeros(3))["fisher_px"] == 0.0


def _image_centroids(sc):
    cams = {"A": sc.cam_from_d, "B": sc.cam_from_b}
    out = []
    for m in LAYOUT:
        pc = transform_points(cams[m.section], marker_outline(m))
        out.append(polygon_area_centroid(sc.focal_px * pc[:, :2] / pc[:, 2:3] + sc.principal_point)[1])
    return np.array(out)


@pytest.mark.slow  # several seconds of solves or pages; the full suite runs it
def test_solve_docking_reports_an_honest_std_under_disc_shaped_noise():
    """Detections at the exact image centroids + disc-shaped noise (0.1 px per axis averaged),
    240 frames: RMS z of X, Y, alpha within 0.88-1.12 with the disc model (the default), off
    without it; the pose itself does not depend on the option."""
    rng = np.random.default_rng(21)
    cls = np.array([0 if m.section == "A" else 1 for m in LAYOUT])
    z = {True: [], False: []}
    for _ in range(240):
        sc = docking_scene(rng)
        cams = {"A": sc.cam_from_d, "B": sc.cam_from_b}
        shapes = np.concatenate([section_noise_shapes([m], cams[m.section], sc.focal_px) for m in LAYOUT])
        chol = np.linalg.cholesky(_noise_cov(shapes, SIGMA))
        uv = _image_centroids(sc) + np.einsum("nij,nj->ni", chol, rng.normal(size=(len(LAYOUT), 2)))
        truth = pose_components(sc.d_from_b)
        res = {d: solve_docking(LAYOUT, sc.principal_point, detections=(cls, uv),
                                options=DockingOptions(disc_noise=d, robust=False)) for d in (True, False)}
        assert res[True].x_mm == res[False].x_mm and res[True].alpha_deg == res[False].alpha_deg
        for d, r in res.items():
            z[d].append([(getattr(r, k) - truth[k]) / r.std[k] for k in KEYS])
    rms = {d: np.sqrt(np.mean(np.square(v), axis=0)) for d, v in z.items()}
    assert rms[True] == pytest.approx(np.ones(3), abs=0.12), rms[True]
    # isotropic (measured 1.21 / 1.13 / 1.10): too confident, most in X
    assert rms[False][0] > 1.1 and np.all(rms[False] > 1.03), rms[False]


def _disc_noise_frame(rng, sigma=SIGMA):
    """(scene, class ids, detections = exact image centroids + disc-shaped Gaussian noise)."""
    sc = docking_scene(rng)
    cams = {"A": sc.cam_from_d, "B": sc.cam_from_b}
    shapes = np.concatenate([section_noise_shapes([m], cams[m.section], sc.focal_px) for m in LAYOUT])
    chol = np.linalg.cholesky(_noise_cov(shapes, sigma))
    uv = _image_centroids(sc) + np.einsum("nij,nj->ni", chol, rng.normal(size=(len(LAYOUT), 2)))
    return sc, np.array([0 if m.section == "A" else 1 for m in LAYOUT]), uv


@pytest.mark.slow   # 2 x 160 synthetic frames through the whole docking pipeline
def test_the_robust_refit_weighs_by_the_disc_noise_on_clean_frames_and_keeps_an_honest_std():
    """Disc-shaped Gaussian noise, no gross error: the reweighted fit, weighted by each disc's
    noise, errs less than the unweighted fit (RMSE below 0.92x on each component; measured 0.77 /
    0.83 / about 0.8) and its RMS z stays within 0.85-1.15."""
    rng = np.random.default_rng(22)
    err, z = {True: [], False: []}, []
    for _ in range(160):
        sc, cls, uv = _disc_noise_frame(rng)
        truth = pose_components(sc.d_from_b)
        for robust in (True, False):
            r = solve_docking(LAYOUT, sc.principal_point, detections=(cls, uv), options=DockingOptions(robust=robust))
            err[robust].append([getattr(r, k) - truth[k] for k in KEYS])
            if robust:
                z.append([(getattr(r, k) - truth[k]) / r.std[k] for k in KEYS])
    rmse = {d: np.sqrt(np.mean(np.square(v), axis=0)) for d, v in err.items()}
    assert np.all(rmse[True] < 0.92 * rmse[False]), rmse
    rms_z = np.sqrt(np.mean(np.square(z), axis=0))
    assert np.all((rms_z > 0.85) & (rms_z < 1.15)), rms_z


@pytest.mark.slow
def test_the_robust_refit_takes_the_pull_of_a_gross_centre():
    """One centre per frame 1.5 px off (a partly hidden or glared disc that passed every other
    rule), 100 frames: the unweighted fit's X and alpha errors grow several times over those of
    an oracle that drops the bad centre; the reweighted fit, which is not told which one it is,
    takes most of that back, and its std follows its errors."""
    rng = np.random.default_rng(23)
    err = {"dropped": [], "plain": [], "robust": []}
    z = []
    unweighted = DockingOptions(robust=False)
    for _ in range(100):
        sc, cls, uv = _disc_noise_frame(rng)
        truth = pose_components(sc.d_from_b)
        k = int(rng.integers(len(LAYOUT)))
        a = rng.uniform(0, 2 * np.pi)
        uv[k] += 1.5 * np.array([np.cos(a), np.sin(a)])
        others = np.arange(len(LAYOUT)) != k
        runs = (("dropped", cls[others], uv[others], unweighted), ("plain", cls, uv, unweighted),
                ("robust", cls, uv, DockingOptions()))
        for name, c, u, options in runs:
            r = solve_docking(LAYOUT, sc.principal_point, detections=(c, u), options=options)
            err[name].append([getattr(r, key) - truth[key] for key in KEYS])
            if name == "robust":
                z.append([(getattr(r, key) - truth[key]) / r.std[key] for key in KEYS])
    rmse = {d: np.sqrt(np.mean(np.square(v), axis=0)) for d, v in err.items()}
    rms_z = np.sqrt(np.mean(np.square(z), axis=0))
    # measured: X / alpha RMSE dropped 0.39 mm / 0.025 deg, unweighted 1.05 / 0.067, reweighted
    # 0.54 / 0.034 (a centre that alone fixes a direction of the pose, e.g. A5 at the end of the
    # layout, cannot be told from the others: the oracle still beats the reweighting there);
    # RMS z 0.90 / 1.04 / 0.95
    assert np.all(rmse["plain"][[0, 2]] > 2.0 * rmse["dropped"][[0, 2]]), rmse
    assert np.all(rmse["robust"][[0, 2]] < 0.6 * rmse["plain"][[0, 2]]), rmse
    assert np.all(rmse["robust"][[0, 2]] < 1.5 * rmse["dropped"][[0, 2]]), rmse
    assert np.all((rms_z > 0.8) & (rms_z < 1.2)), rms_z
