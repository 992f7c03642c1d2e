"""Batch entry points agree with the single-frame solver; Jacobians and bounds are right."""
from __future__ import annotations

import numpy as np
from dockfactory.core.geometry import pose_components, transform_from_pose_components
from dockfactory.solver import (
    POSE_NAMES,
    crb_d_from_b,
    crb_joint,
    crb_pnpf,
    solve_docking,
    solve_docking_batch,
    solve_pnpf,
    solve_pnpf_batch,
)
from dockfactory.solver.lie import so3_exp
from dockfactory.solver.refine import (
    d_from_b_jacobian,
    relative_pose,
    residuals_and_jacobian,
)
from dockfactory.solver.synthetic import default_layout, docking_scene

LAYOUT = default_layout()
IDS = [m.id for m in LAYOUT]


def _frames(seed, n, sigma):
    rng = np.random.default_rng(seed)
    scenes = [docking_scene(rng) for _ in range(n)]
    uv = np.stack([np.vstack([s.uv_a, s.uv_b]) for s in scenes])
    return scenes, uv + sigma * rng.standard_normal(uv.shape)


def test_docking_batch_matches_single():
    scenes, uv = _frames(1, 30, 0.5)
    pp = scenes[0].principal_point
    out = solve_docking_batch(LAYOUT, pp, uv)
    assert out.ok.all()
    for k in range(len(scenes)):
        single = solve_docking(LAYOUT, pp, correspondences=(IDS, uv[k]))
        std = np.array([single.std[name] for name in POSE_NAMES])
        diff = np.abs(out.pose[k] - np.array([single.pose()[name] for name in POSE_NAMES]))
        assert np.all(diff < 1e-3 * std)                       # the same minimum
        assert abs(out.focal_px[k] / single.focal_px - 1) < 1e-3 * single.std["x_mm"] + 1e-6
        assert np.allclose(out.covariance[k], single.covariance, rtol=1e-2,
                           atol=1e-6 * np.abs(single.covariance).max())
        assert np.allclose(out.rmse_px[k], [single.rmse_px["A"], single.rmse_px["B"]],
                           rtol=1e-4)


def test_docking_batch_missing_markers():
    scenes, uv = _frames(2, 40, 0.3)
    rng = np.random.default_rng(3)
    vis = rng.random((40, 14)) > 0.15
    vis[:, [0, 1, 2, 3, 7, 8, 9, 10]] = True                   # keep >= 4 per section
    uv = np.where(vis[..., None], uv, np.nan)
    out = solve_docking_batch(LAYOUT, scenes[0].principal_point, uv, visible=vis)
    assert out.ok.all(), [m for m in out.messages if m]
    for k in range(0, 40, 7):
        keep = np.flatnonzero(vis[k])
        single = solve_docking(LAYOUT, scenes[0].principal_point,
                               correspondences=([IDS[i] for i in keep], uv[k, keep]))
        assert abs(out.component("x_mm")[k] - single.x_mm) < 1e-3 * single.std["x_mm"]
        assert abs(out.component("alpha_deg")[k] - single.alpha_deg) < \
            1e-3 * single.std["alpha_deg"]


def test_docking_batch_noise_free_exact():
    scenes, uv = _frames(4, 20, 0.0)
    out = solve_docking_batch(LAYOUT, scenes[0].principal_point, uv)
    for k, sc in enumerate(scenes):
        truth = pose_components(sc.d_from_b)
        assert np.allclose(out.pose[k], [truth[n] for n in POSE_NAMES], atol=1e-6)
        assert abs(out.focal_px[k] / sc.focal_px - 1) < 1e-8


def test_pnpf_batch_matches_single():
    scenes, uv = _frames(5, 20, 0.2)
    pts = scenes[0].points_a
    out = solve_pnpf_batch(pts, uv[:, :7], scenes[0].principal_point)
    for k in range(20):
        if not out.ok[k]:
            continue
        single = solve_pnpf(pts, uv[k, :7], scenes[0].principal_point)
        assert abs(out.focal_px[k] / single.focal_px - 1) < 1e-6
        assert np.allclose(out.cam_from_world[k], single.cam_from_world, atol=1e-3)
    assert out.ok.mean() > 0.9


def test_jacobian_matches_finite_differences():
    sc = docking_scene(np.random.default_rng(6))
    r, t, f = sc.cam_from_d[:3, :3], sc.cam_from_d[:3, 3], sc.focal_px
    uv = sc.uv_a
    _, jac, _ = residuals_and_jacobian(sc.points_a, uv, sc.principal_point, r, t, f)
    h = 1e-6
    for k in range(7):
        d = np.zeros(7)
        d[k] = h
        plus = residuals_and_jacobian(sc.points_a, uv, sc.principal_point,
                                      so3_exp(d[:3]) @ r, t + d[3:6], f + d[6], False)[0]
        d[k] = -h
        minus = residuals_and_jacobian(sc.points_a, uv, sc.principal_point,
                                       so3_exp(d[:3]) @ r, t + d[3:6], f + d[6], False)[0]
        num = (plus - minus) / (2 * h)
        assert np.allclose(jac[:, k], num, rtol=1e-5, atol=1e-6 * np.abs(num).max())


def test_d_from_b_jacobian_matches_finite_differences():
    sc = docking_scene(np.random.default_rng(7))
    ca, cb = sc.cam_from_d, sc.cam_from_b
    jac = d_from_b_jacobian(ca[:3, :3], ca[:3, 3], cb[:3, :3], cb[:3, 3])

    def comp(p):
        ra = so3_exp(p[0:3]) @ ca[:3, :3]
        rb = so3_exp(p[6:9]) @ cb[:3, :3]
        d = relative_pose(ra, ca[:3, 3] + p[3:6], rb, cb[:3, 3] + p[9:12])
        c = pose_components(d)
        return np.array([c[n] for n in POSE_NAMES])
    h = 1e-6
    for k in range(12):
        e = np.zeros(12)
        e[k] = h
        num = (comp(e) - comp(-e)) / (2 * h)
        assert np.allclose(jac[:, k], num, rtol=1e-5, atol=1e-7)


def test_crb_consistency():
    sc = docking_scene(np.random.default_rng(8))
    pp = sc.principal_point
    c7 = crb_pnpf(sc.points_a, sc.cam_from_d, sc.focal_px, pp, 1.0)
    c6 = crb_pnpf(sc.points_a, sc.cam_from_d, sc.focal_px, pp, 1.0, focal_known=True)
    c13 = crb_joint(sc.points_a, sc.cam_from_d, sc.points_b, sc.cam_from_b, sc.focal_px, pp, 1.0)
    assert np.allclose(crb_pnpf(sc.points_a, sc.cam_from_d, sc.focal_px, pp, 0.5), c7 / 4)
    # knowing the focal, or adding a second section that shares it, only helps
    assert np.all(np.diag(c6) <= np.diag(c7)[:6] * (1 + 1e-9))
    assert np.all(np.diag(c13)[:6] <= np.diag(c7)[:6] * (1 + 1e-9))
    assert c13[12, 12] <= c7[6, 6]
    joint = crb_d_from_b(sc.points_a, sc.cam_from_d, sc.points_b, sc.cam_from_b,
                         sc.focal_px, pp, 1.0, "joint")
    calib = crb_d_from_b(sc.points_a, sc.cam_from_d, sc.points_b, sc.cam_from_b,
                         sc.focal_px, pp, 1.0, "calibrated")
    for name in ("x_mm", "y_mm", "alpha_deg"):
        assert calib.std[name] <= joint.std[name] * (1 + 1e-9)
        assert np.isfinite(joint.std[name]) and joint.std[name] > 0


def test_pose_components_roundtrip_for_batch_euler():
    from dockfactory.solver.batch import _euler_batch
    rng = np.random.default_rng(9)
    angles = rng.uniform([-20, -20, -20], [20, 20, 20], (50, 3))
    rots = np.stack([transform_from_pose_components(0, 0, 0, *a)[:3, :3] for a in angles])
    got = np.degrees(np.column_stack(_euler_batch(rots)))
    assert np.allclose(got, angles, atol=1e-10)
