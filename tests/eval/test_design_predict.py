"""The design predictor against the solver: its covariance model on synthetic centres, the guarded
rule's pass probability against a simulation of the rule, and the layouts it draws."""
from __future__ import annotations

import math

import numpy as np
import pytest

from dockfactory.core.errors import DockfactoryError
from dockfactory.core.geometry import pose_components
from dockfactory.core.layout import DEFAULT_LAYOUT_A, build_layout, layout_problems
from dockfactory.core.layout_patterns import pattern_pair
from dockfactory.eval.confidence import chi2_bounds
from dockfactory.eval.design_noise import RING_REFERENCE_PX, CentreNoiseLaw, over_weights, ring_width_px
from dockfactory.eval.design_predict import NoiseClass, frame_variances
from dockfactory.eval.design_rank import pass_probability, reject_probability
from dockfactory.solver import crb_d_from_b, solve_docking
from dockfactory.solver.disc_noise import MINOR_EXPONENT, NOISE_FLOOR, section_noise_shapes
from dockfactory.solver.synthetic import default_layout, docking_scene

LAYOUT = default_layout()
CLASSES = np.array([0 if m.section == "A" else 1 for m in LAYOUT])
COMPS = (("x_mm", 0), ("y_mm", 1), ("alpha_deg", 3))


def _scene_noise(sc):
    ma = [m for m in LAYOUT if m.section == "A"]
    mb = [m for m in LAYOUT if m.section == "B"]
    return np.concatenate([section_noise_shapes(ma, sc.cam_from_d, sc.focal_px),
                           section_noise_shapes(mb, sc.cam_from_b, sc.focal_px)])


def _draw_centres(rng, sc, shapes, noise: NoiseClass):
    """The scene's exact centres plus disc noise (covariance scale^2 T_i) and a common shift per
    section and axis."""
    uv = np.vstack([sc.uv_a, sc.uv_b])
    chol = np.linalg.cholesky(noise.scale_px ** 2 * shapes)
    uv = uv + np.einsum("nab,nb->na", chol, rng.standard_normal(uv.shape))
    na = len(sc.uv_a)
    for rows in (slice(0, na), slice(na, None)):
        uv[rows] += rng.standard_normal(2) * np.asarray(noise.shift_px)
    return uv


@pytest.mark.slow
def test_predicted_rmse_matches_the_solver_on_synthetic_centres():
    """300 synthetic frames, disc noise 0.02 px and a section offset (0.08, 0.06) px: the solver's
    RMSE of X, Y, alpha (detections, so its robust refit weighs the centres by their disc noise, as
    measure does) is within 0.8-1.25x of the predicted one (the RMS over the frames of the
    predicted std; sampling error of an RMSE over 300 frames about 4 %); left without the offset
    term, the prediction of X or Y is more than 1.25x off."""
    rng = np.random.default_rng(48)
    noise = NoiseClass(0.02, (0.08, 0.06))
    err, var, var_noise = [], [], []
    for _ in range(300):
        sc = docking_scene(rng)
        vn, vs = frame_variances(LAYOUT, sc.cam_from_d, sc.cam_from_b, sc.focal_px, sc.principal_point, noise)
        uv = _draw_centres(rng, sc, _scene_noise(sc), noise)
        res = solve_docking(LAYOUT, sc.principal_point, detections=(CLASSES, uv))   # as measure: the robust refit
        truth = pose_components(sc.d_from_b)
        err.append([getattr(res, k) - truth[k] for k, _ in COMPS])
        var.append([vn[i] + vs[i] for _, i in COMPS])
        var_noise.append([vn[i] for _, i in COMPS])
    rmse = np.sqrt(np.mean(np.square(err), axis=0))
    ratio = rmse / np.sqrt(np.mean(var, axis=0))
    assert np.all((ratio > 0.8) & (ratio < 1.25)), ratio
    assert np.max(rmse / np.sqrt(np.mean(var_noise, axis=0))) > 1.25


def test_without_offset_the_prediction_is_the_bound_of_the_weighted_fit():
    """With no section offset the prediction is the Cramer-Rao bound under the discs' own noise
    shapes (the robust refit weighs each centre by its disc's noise)."""
    rng = np.random.default_rng(3)
    for _ in range(20):
        sc = docking_scene(rng)
        shapes = _scene_noise(sc)
        vn, vs = frame_variances(LAYOUT, sc.cam_from_d, sc.cam_from_b, sc.focal_px, sc.principal_point,
                                 NoiseClass(0.05, (0.0, 0.0)))
        assert np.all(vs == 0)
        sigma = 0.05 * math.sqrt(np.trace(shapes, axis1=1, axis2=2).mean() / 2)
        b = crb_d_from_b(sc.points_a, sc.cam_from_d, sc.points_b, sc.cam_from_b, sc.focal_px,
                         sc.principal_point, sigma, noise_shapes=(shapes[:7], shapes[7:]))
        for key, i in COMPS:
            assert vn[i] == pytest.approx(b.std[key] ** 2, rel=1e-6), key


@pytest.mark.parametrize("rmse,dof", [(0.25, 40), (0.28, 24), (0.2, 10), (0.31, 60), (0.36, 24), (0.45, 10)])
def test_pass_probability_is_the_guarded_rule_s_frequency(rmse, dof):
    """Simulated test campaigns: the share whose chi-square upper bound is within the threshold
    (0.3) equals the predicted probability within 0.03 (4000 campaigns, sd <= 0.008), and the
    share whose lower bound is beyond it the predicted probability of a rejection."""
    rng = np.random.default_rng(int(rmse * 1000) + dof)
    errors = rng.standard_normal((4000, dof)) * rmse
    bounds = [chi2_bounds(float(np.sum(e ** 2)), dof, 0.95) for e in errors]
    assert abs(np.mean([b[1] <= 0.3 for b in bounds]) - pass_probability(rmse, 0.3, dof, 0.95)) < 0.03
    assert abs(np.mean([b[0] > 0.3 for b in bounds]) - reject_probability(rmse, 0.3, dof, 0.95)) < 0.03


def test_pass_probability_grows_with_frames_and_margin():
    p = [pass_probability(0.25, 0.3, n, 0.95) for n in (5, 20, 80, 320)]
    assert all(a < b for a, b in zip(p, p[1:])) and p[-1] > 0.99
    assert pass_probability(0.35, 0.3, 320, 0.95) < 0.01
    assert pass_probability(0.0, 0.3, 5, 0.95) == 1.0


@pytest.mark.parametrize("n", [6, 8, 9, 12])
def test_patterns_are_clean_irregular_and_seeded(n):
    a, b = pattern_pair(n, 300.0, 20.0, seed=5)
    assert len(a) == len(b) == n
    assert layout_problems(build_layout(a, b, 300.0, 20.0)) == []
    assert pattern_pair(n, 300.0, 20.0, seed=5) == (a, b)
    assert all(45.0 <= s <= 160.0 and -60.0 <= phi <= 60.0 for s, phi in a + b)


def test_seven_markers_is_the_shipped_layout_and_bad_counts_are_one_line():
    assert pattern_pair(7, 300.0, 20.0)[0] == DEFAULT_LAYOUT_A
    for n in (5, 17, 7.0):
        with pytest.raises(DockfactoryError, match="markers per section must be an integer"):
            pattern_pair(n, 300.0, 20.0)
    with pytest.raises(DockfactoryError, match="no irregular pattern of 16 markers of 90 mm"):
        pattern_pair(16, 300.0, 90.0)


def test_a_bad_predictor_card_is_one_line(tmp_path):
    import json
    from dockfactory.core.resources import shipped_design_card
    from dockfactory.eval.design_card import load_design_card
    card = json.loads(shipped_design_card().read_text())
    assert load_design_card(shipped_design_card()).scale_px == card["scale_px"] and "edge_px" not in card
    for key, value, needle in (("scale_px", -1, "scale_px: expected a positive number"),
                               ("format", "x", "format: expected 'dockfactory.design_predictor/5'"),
                               ("jpeg_factor", {"none": 3.9, "rggb": 4.1}, "jpeg_factor: expected a table of dark, white"),
                               ("jpeg_factor", {**card["jpeg_factor"], "white": {"none": 0, "rggb": 1.6}},
                                "jpeg_factor.white.none: expected a positive number"),
                               ("centre_noise", {"floor": 1.0}, "centre_noise: expected a table of minor_exponent"),
                               ("centre_noise", {**card["centre_noise"], "floor": -1}, "centre_noise.floor: expected a number >= 0"),
                               ("shift_px", [0.01, -0.001], "shift_px[1]: expected a non-negative number")):
        path = tmp_path / f"{key}.json"
        path.write_text(json.dumps({**card, key: value}))
        with pytest.raises(DockfactoryError) as exc:
            load_design_card(path)
        assert needle in str(exc.value) and str(path) in str(exc.value) and "\n" not in str(exc.value)


def test_a_card_whose_fit_found_no_offset_along_an_axis_loads(tmp_path):
    """A section offset of 0 along an axis (the fit's non-negative least squares found none) is a
    measurement, not a broken card: it loads, and the predicted noise carries no offset there."""
    import json
    from dockfactory.core.resources import shipped_design_card
    from dockfactory.eval.design_card import load_design_card
    card = json.loads(shipped_design_card().read_text())
    path = tmp_path / "zero.json"
    path.write_text(json.dumps({**card, "shift_px": [card["shift_px"][0], 0.0]}))
    assert load_design_card(path).shift_px == (card["shift_px"][0], 0.0)


def _design(cfa: str, ring: str, image_format: str):
    from dockfactory.eval.design_space import Camera, Design, Lens
    return Design(Camera("cam", 1440, 1080, 3.45, cfa), Lens(6.0), (1000.0, 1800.0), 24.0, ring, 7, image_format)


def test_jpeg_costs_each_ring_its_own_factor_and_a_provisional_one_is_named(tmp_path):
    """A card of format /4 has JPEG factors per ring and camera class: a dark-ring JPEG design's
    noise is the dark ring's PNG noise times the dark factor, a white ring's times the white one;
    the Bayer camera's white-ring factor, marked provisional, is named beside the design using it."""
    import json
    from dockfactory.eval.design_card import load_design_card
    from dockfactory.core.resources import shipped_design_card
    card = json.loads(shipped_design_card().read_text())
    path = tmp_path / "four.json"
    path.write_text(json.dumps({**card, "format": "dockfactory.design_predictor/4",
                                "jpeg_factor": {"dark": {"none": 7.0, "rggb": 4.0}, "white": {"none": 2.5, "rggb": 1.5}},
                                "provisional": ["jpeg_factor.white.rggb"]}))
    c = load_design_card(path)
    for cfa, ring, factor in (("none", "dark", 7.0), ("none", "white", 2.5), ("rggb", "dark", 4.0), ("rggb", "white", 1.5)):
        png, _, _ = c.noise_of(_design(cfa, ring, "png"))
        jpeg, prov, _ = c.noise_of(_design(cfa, ring, "jpeg95"))
        assert jpeg.scale_px == pytest.approx(png.scale_px * factor, rel=1e-12)
        assert jpeg.shift_px == pytest.approx(tuple(v * factor for v in png.shift_px), rel=1e-12)
        assert prov == (["jpeg_factor.white.rggb"] if (cfa, ring) == ("rggb", "white") else [])


def test_a_card_with_one_jpeg_factor_per_camera_class_loads_for_both_rings(tmp_path):
    """A card of format /3 (one JPEG factor per camera class, pooled over the rings) still loads:
    both rings take its factor."""
    import json
    from dockfactory.eval.design_card import load_design_card
    from dockfactory.core.resources import shipped_design_card
    card = json.loads(shipped_design_card().read_text())
    path = tmp_path / "three.json"
    path.write_text(json.dumps({**card, "format": "dockfactory.design_predictor/3", "jpeg_factor": {"none": 3.9, "rggb": 4.1}}))
    c = load_design_card(path)
    assert c.jpeg_factor == {"dark": {"none": 3.9, "rggb": 4.1}, "white": {"none": 3.9, "rggb": 4.1}}


def test_a_card_of_the_previous_noise_model_is_refused_with_how_to_refit(tmp_path):
    """A card of format /1 (fitted before the centre noise followed the disc's minor semi-axis, with
    an edge width per camera class) is refused in one line naming the file and the refit command."""
    import json
    from dockfactory.core.resources import shipped_design_card
    from dockfactory.eval.design_card import load_design_card
    card = json.loads(shipped_design_card().read_text())
    path = tmp_path / "old.json"
    path.write_text(json.dumps({**card, "format": "dockfactory.design_predictor/1",
                                "edge_px": {"none": 0.0, "rggb": 4.0}}))
    with pytest.raises(DockfactoryError) as exc:
        load_design_card(path)
    msg = str(exc.value)
    assert msg.startswith(f"{path}: format 'dockfactory.design_predictor/1': fitted under the previous")
    assert "python -m bench.design.design_fit" in msg and "\n" not in msg


def test_a_card_without_a_centre_noise_law_predicts_with_the_solver_s_weights(tmp_path):
    """A card of format /2 (no centre_noise) loads with no law: its designs' centres are noisy as
    the solver weighs them, and its predictions are those of the weighted fit (the sandwich with
    every ratio 1 is the weighted covariance exactly)."""
    import json
    from dockfactory.core.resources import shipped_design_card
    from dockfactory.eval.design_card import load_design_card
    card = json.loads(shipped_design_card().read_text())
    assert load_design_card(shipped_design_card()).law is not None
    old = {k: v for k, v in card.items() if k != "centre_noise"} | {"format": "dockfactory.design_predictor/2",
                                                                     "jpeg_factor": {"none": 3.9, "rggb": 4.1}}
    path = tmp_path / "two.json"
    path.write_text(json.dumps(old))
    assert load_design_card(path).law is None
    sc = docking_scene(np.random.default_rng(5))
    plain = frame_variances(LAYOUT, sc.cam_from_d, sc.cam_from_b, sc.focal_px, sc.principal_point, NoiseClass(0.05, (0.01, 0.01)))
    same = CentreNoiseLaw(MINOR_EXPONENT, NOISE_FLOOR, 0.0, 1.0)   # the solver's law, up to its normalisation
    lawful = frame_variances(LAYOUT, sc.cam_from_d, sc.cam_from_b, sc.focal_px, sc.principal_point,
                             NoiseClass(0.05, (0.01, 0.01), same))
    np.testing.assert_allclose(lawful[0], plain[0] * (1 + NOISE_FLOOR), rtol=1e-9)
    np.testing.assert_array_equal(lawful[1], plain[1])


def test_the_ring_term_makes_a_larger_disc_noisier_at_the_same_image():
    """The factory's ring is RING_EXTRA_MM wide whatever the disc: at the same minor semi-axis a
    30 mm disc's ring is two thirds as wide in the image as a 20 mm disc's, and the law's variance
    is larger by the ring term alone."""
    law = CentreNoiseLaw(1.0, 5.0, 8.0, 3.0)
    b = np.array([6.0, 6.0])
    w = ring_width_px(b, np.array([20.0, 30.0]))
    np.testing.assert_allclose(w, [6.0 * 2.5 / 10.0, 6.0 * 2.5 / 15.0])
    v = law.variance(b, w)
    ring = 8.0 * (RING_REFERENCE_PX / w) ** 3
    np.testing.assert_allclose(v - ring, [10 / 6 + 5] * 2)
    assert v[1] / v[0] > 1.5


@pytest.mark.slow
def test_predicted_rmse_follows_the_solver_when_the_noise_is_not_its_weights():
    """300 synthetic frames whose centres' noise follows a law with a ring term (not the solver's
    weights: the solver still weighs by its own law): the solver's RMSE of X, Y, alpha is within
    0.8-1.25x of the sandwich's prediction (the RMS over the frames of the predicted std)."""
    rng = np.random.default_rng(71)
    law = CentreNoiseLaw(1.0, 5.0, 8.0, 3.0)
    noise = NoiseClass(0.004, (0.0, 0.0), law)
    err, var = [], []
    for _ in range(300):
        sc = docking_scene(rng)
        vn, _ = frame_variances(LAYOUT, sc.cam_from_d, sc.cam_from_b, sc.focal_px, sc.principal_point, noise)
        ratio = np.r_[over_weights([m for m in LAYOUT if m.section == "A"], sc.cam_from_d, sc.focal_px, law),
                      over_weights([m for m in LAYOUT if m.section == "B"], sc.cam_from_b, sc.focal_px, law)]
        shapes = _scene_noise(sc) * ratio[:, None, None]
        uv = _draw_centres(rng, sc, shapes, NoiseClass(noise.scale_px, (0.0, 0.0)))
        res = solve_docking(LAYOUT, sc.principal_point, detections=(CLASSES, uv))
        truth = pose_components(sc.d_from_b)
        err.append([getattr(res, k) - truth[k] for k, _ in COMPS])
        var.append([vn[i] for _, i in COMPS])
    rmse = np.sqrt(np.mean(np.square(err), axis=0))
    ratio_law = rmse / np.sqrt(np.mean(var, axis=0))
    assert np.all((ratio_law > 0.8) & (ratio_law < 1.25)), ratio_law


def test_the_sandwich_is_the_covariance_of_the_weighted_fit_under_other_noise():
    """A linear model fitted with the solver's whitening while each point's true variance is
    ``ratio`` times its weight: the estimates' covariance over 20,000 draws is
    _weighted_fit_covariance's to 3 %, and it differs from the weighted fit's own (J_w^T J_w)^-1."""
    from dockfactory.eval.design_predict import _weighted_fit_covariance
    rng = np.random.default_rng(9)
    jw = rng.normal(size=(16, 3))
    ratio = rng.uniform(0.3, 6.0, 8)
    pred = _weighted_fit_covariance(jw, ratio)
    noise = rng.standard_normal((20_000, 16)) * np.sqrt(np.repeat(ratio, 2))
    est = noise @ jw @ np.linalg.inv(jw.T @ jw)
    np.testing.assert_allclose(np.cov(est.T), pred, rtol=0.03, atol=0.03 * np.abs(pred).max())
    assert not np.allclose(pred, np.linalg.inv(jw.T @ jw), rtol=0.2)
