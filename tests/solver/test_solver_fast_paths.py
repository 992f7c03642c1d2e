"""The docking pipeline's fast paths give what the plain paths give (bench/solver/solve_speed.py
measures the speed; issue 11, ``measure``: identification + solve <= 15 ms per frame).

- identification: verifying only the seeds that the hypotheses found so far leave open
  (solver/identify.py ``_settled``, ``_contradicting``) against verifying every seed with the
  estimator's rescue, as the search did before: the same marker ids, swapped flags, inliers and
  (the rest of the pipeline being the same code) bit-identical poses, on seeded frames with
  missing markers, spurious and duplicate detections and swapped classes;
- the docking fit started from identification's joint fit finds the pose (within 5 of its
  standard deviations) where the per-section closed-form start failed;
- the Jacobian (pairs of columns written by one numpy call) against the plain per-column formula
  and against central differences; residuals without the Jacobian equal those with it (the LM
  judges trial steps on residuals alone, so its path is unchanged);
- the similarity seeds against a plain loop over the ranked hypotheses;
- the outlines of a section's markers in one pass (suspects' predicted boxes, eccentricity
  offsets) against the one-marker functions.
No stored numbers: every expectation is recomputed by the plain path.
"""
from __future__ import annotations

import numpy as np
import pytest

from dockfactory.core.geometry import pose_components
from dockfactory.solver import SolverError, solve_docking
from dockfactory.solver import identify as identify_module
from dockfactory.solver.eccentricity import eccentricity_offset, eccentricity_offsets
from dockfactory.solver.lie import so3_exp
from dockfactory.solver.options import DEFAULT_IDENTIFY
from dockfactory.solver.refine import residuals_and_jacobian
from dockfactory.solver.suspects import predicted_outline_box, predicted_outline_boxes
from dockfactory.solver.synthetic import default_layout, docking_scene

LAYOUT = default_layout()
CLASSES = np.array([0 if m.section == "A" else 1 for m in LAYOUT])


def _detections(seed: int):
    """(scene, class ids (N,), centres (N, 2) px) of a seeded frame as a detector gives it:
    noise 0.1-0.5 px, each marker missing with probability 15 % (a section keeps >= 5),
    seed % 3 swapped classes, seed % 3 spurious detections, and for even seeds a duplicate of
    one detection 2.5-3.5 px away (a second box on the same marker)."""
    rng = np.random.default_rng([seed, 4242])
    sc = docking_scene(rng)
    n = len(LAYOUT)
    uv = np.vstack([sc.uv_a, sc.uv_b]) + rng.uniform(0.1, 0.5) * rng.standard_normal((n, 2))
    cls = CLASSES.copy()
    while True:
        keep = rng.random(n) >= 0.15
        if keep[cls == 0].sum() >= 5 and keep[cls == 1].sum() >= 5:
            break
    cls[rng.choice(np.flatnonzero(keep), size=seed % 3, replace=False)] ^= 1
    pts, classes = [uv[keep]], [cls[keep]]
    for _ in range(seed % 3):
        q = rng.uniform([0.0, 0.0], sc.image_size)
        if np.min(np.linalg.norm(uv - q, axis=1)) > 15.0:
            pts.append(q[None])
            classes.append(rng.integers(0, 2, 1))
    if seed % 2 == 0:
        k = rng.choice(np.flatnonzero(keep))
        turn = rng.uniform(0.0, 2.0 * np.pi)
        pts.append(uv[k] + rng.uniform(2.5, 3.5) * np.array([[np.cos(turn), np.sin(turn)]]))
        classes.append(cls[k:k + 1])
    return sc, np.concatenate(classes), np.vstack(pts)


def _outcome(sc, cls, uv):
    try:
        return solve_docking(LAYOUT, sc.image_centre, detections=(cls, uv))
    except SolverError as exc:
        return type(exc)


# 110, 138, 152: a duplicate detection that the first hypothesis explaining every marker takes
# in place of the original; a cruder pruning (no seed verified after such a hypothesis) keeps
# the duplicate there (found by running both over seeds 0-400)
@pytest.mark.parametrize("seed", [*range(24), 110, 138, 152])
def test_pruned_identification_equals_verifying_every_seed(seed, monkeypatch):
    sc, cls, uv = _detections(seed)
    fast = _outcome(sc, cls, uv)
    with monkeypatch.context() as m:
        m.setattr(identify_module, "_settled", lambda pairs, hyps, n_markers: False)
        m.setattr(identify_module, "_contradicting", lambda pairs, hyps: [])
        plain = _outcome(sc, cls, uv)
    if isinstance(plain, type):
        assert fast is plain
        return
    assert not isinstance(fast, type), fast
    assert fast.marker_ids == plain.marker_ids
    assert np.array_equal(fast.swapped, plain.swapped)
    assert np.array_equal(fast.inliers, plain.inliers)
    assert np.array_equal(fast.d_from_b, plain.d_from_b)
    assert fast.focal_px == plain.focal_px


# frames of _detections on which the docking's first joint fit, started from the per-section
# closed forms, ended in a mirrored basin (212, 878: X off by 80 and 220 mm, alpha by 177 deg,
# no error) or refused the frame (41, 170: focal not observable); started from identification's
# joint fit, verified on the same detections, it finds the pose (found by running both starts
# over seeds 0-1500: 4 mirrored, 6 refused, all others within 1e-6 mm / deg)
@pytest.mark.parametrize("seed", [41, 170, 212, 878])
def test_docking_fit_starts_from_identification(seed):
    sc, cls, uv = _detections(seed)
    res = solve_docking(LAYOUT, sc.image_centre, detections=(cls, uv))
    truth = pose_components(sc.d_from_b)
    for k in ("x_mm", "y_mm", "alpha_deg"):
        assert abs(getattr(res, k) - truth[k]) <= 5.0 * res.std[k], (k, getattr(res, k), truth)


def _plain_jacobian(p3, rot, t, focal):
    """The Jacobian (2N, 7) over (w, t, f) written column by column."""
    a = p3 @ rot.T
    pc = a + t
    iz = 1.0 / pc[:, 2]
    xn, yn = pc[:, 0] * iz, pc[:, 1] * iz
    fz = focal * iz
    ax, ay, az = a[:, 0], a[:, 1], a[:, 2]
    j = np.zeros((p3.shape[0], 2, 7))
    j[:, 0, 0] = -fz * ay * xn
    j[:, 0, 1] = fz * (az + ax * xn)
    j[:, 0, 2] = -fz * ay
    j[:, 1, 0] = -fz * (ay * yn + az)
    j[:, 1, 1] = fz * ax * yn
    j[:, 1, 2] = fz * ax
    j[:, 0, 3] = fz
    j[:, 0, 5] = -fz * xn
    j[:, 1, 4] = fz
    j[:, 1, 5] = -fz * yn
    j[:, 0, 6] = xn
    j[:, 1, 6] = yn
    return j.reshape(-1, 7)


def _state(rng, n):
    p3 = rng.normal(size=(n, 3)) * 150.0
    rot = so3_exp(rng.normal(size=3))
    t = np.array([0.0, 0.0, 1500.0]) + rng.normal(size=3) * 40.0
    return p3, rng.normal(size=(n, 2)) * 200 + 600, rot, t, rng.uniform(1200, 2400)


@pytest.mark.parametrize("n", [4, 5, 7, 14])
def test_jacobian_equals_the_plain_formula_and_finite_differences(n):
    rng = np.random.default_rng(n)
    pp = np.array([639.5, 479.5])
    for _ in range(20):
        p3, p2, rot, t, f = _state(rng, n)
        res, jac, z = residuals_and_jacobian(p3, p2, pp, rot, t, f)
        assert np.array_equal(jac, _plain_jacobian(p3, rot, t, f))
        res_only, none, z2 = residuals_and_jacobian(p3, p2, pp, rot, t, f, want_jacobian=False)
        assert none is None and np.array_equal(res, res_only) and np.array_equal(z, z2)
    num = np.zeros_like(jac)
    for k in range(7):
        h = 1e-4 if k == 6 else 1e-7 if k < 3 else 1e-4
        step = np.zeros(7)
        step[k] = h
        hi = residuals_and_jacobian(p3, p2, pp, so3_exp(step[:3]) @ rot, t + step[3:6],
                                    f + step[6], False)[0]
        lo = residuals_and_jacobian(p3, p2, pp, so3_exp(-step[:3]) @ rot, t - step[3:6],
                                    f - step[6], False)[0]
        num[:, k] = (hi - lo) / (2 * h)
    # central differences: truncation ~h^2, rounding ~1e-16 |r| / h; pixels per unit step
    assert np.allclose(jac, num, rtol=1e-6, atol=1e-6 * np.abs(jac).max())


def _plain_similarity_keys(w, z, anchors, prior, spacing_mm, max_keep):
    """Similarity seeds written hypothesis by hypothesis (the ranking by the same score)."""
    hyps = []
    for x, y in ((x, y) for i, x in enumerate(anchors) for y in anchors[i + 1:]):
        for mi in range(w.size):
            for mj in range(w.size):
                if mi == mj:
                    continue
                a = (z[y] - z[x]) / (w[mj] - w[mi])
                s = abs(a)
                if prior.scale_range[0] <= s <= prior.scale_range[1] and \
                        abs(np.angle(a)) <= np.radians(prior.max_roll_deg):
                    hyps.append((a, z[x] - a * w[mi], s))
    keys, scores = [], []
    for a, b, s in hyps:
        d = np.abs((a * w + b)[:, None] - z[None, :])
        gate = prior.loose_gate * spacing_mm * s
        hit = d.min(axis=1) <= gate
        keys.append((hit.sum(), tuple(int(d[k].argmin()) if hit[k] else -1
                                      for k in range(w.size))))
        scores.append(hit.sum() - 1e-3 * (d.min(axis=1) * hit).sum() / max(gate, 1e-9))
    out = []
    for h in np.argsort(-np.array(scores))[:max_keep * 8]:
        if keys[h][0] < 3:
            break
        if keys[h][1] not in out:
            out.append(keys[h][1])
        if len(out) >= max_keep:
            break
    return out


@pytest.mark.parametrize("seed", range(6))
def test_similarity_seeds_equal_the_plain_loop(seed):
    sc, cls, uv = _detections(seed)
    z = uv[:, 0] + 1j * uv[:, 1]
    for section, c in (("A", 0), ("B", 1)):
        p3 = np.array([m.center_mm for m in LAYOUT if m.section == section])
        w = p3[:, 0] - 1j * p3[:, 1]
        spacing = identify_module._min_spacing(w)
        for anchors in (np.flatnonzero(cls == c), np.arange(z.size)):
            got = identify_module._similarity_hypotheses(w, z, anchors, DEFAULT_IDENTIFY.prior,
                                                         spacing, 8)
            assert got == _plain_similarity_keys(w, z, anchors, DEFAULT_IDENTIFY.prior,
                                                 spacing, 8)


@pytest.mark.parametrize("distorted", [False, True])
def test_section_outlines_in_one_pass_equal_the_one_marker_functions(distorted):
    rng = np.random.default_rng(7)
    coeffs = np.array([-0.12, 0.03, 8e-4, -6e-4, 0.0]) if distorted else None
    for _ in range(5):
        sc = docking_scene(rng)
        for section, cam in (("A", sc.cam_from_d), ("B", sc.cam_from_b)):
            markers = [m for m in LAYOUT if m.section == section]
            boxes, valid = predicted_outline_boxes(markers, cam, sc.focal_px,
                                                   sc.principal_point, coeffs)
            assert valid.all()
            assert np.array_equal(boxes, [predicted_outline_box(
                m, cam, sc.focal_px, sc.principal_point, coeffs) for m in markers])
            assert np.array_equal(
                eccentricity_offsets(markers, cam, sc.focal_px, sc.principal_point, coeffs),
                [eccentricity_offset(m, cam, sc.focal_px, sc.principal_point, coeffs)
                 for m in markers])


def test_outline_of_a_disc_behind_the_camera_is_invalid():
    sc = docking_scene(np.random.default_rng(3))
    markers = [m for m in LAYOUT if m.section == "A"]
    behind = sc.cam_from_d.copy()
    behind[:3, 3] -= np.array([0.0, 0.0, behind[2, 3] + 250.0])   # camera moved past A's seam
    boxes, valid = predicted_outline_boxes(markers, behind, sc.focal_px, sc.principal_point)
    for m, ok in zip(markers, valid):
        assert ok == (predicted_outline_box(m, behind, sc.focal_px, sc.principal_point)
                      is not None)
    off = eccentricity_offsets(markers, behind, sc.focal_px, sc.principal_point)
    assert np.array_equal(off, [eccentricity_offset(m, behind, sc.focal_px,
                                                    sc.principal_point) for m in markers])
