"""A camera class whose centre noise grows faster than the law's as the discs shrink (the design
card's ``cfa_size_exponent``): the per-marker ratio, the frame's covariance, the card's key, and
the prediction against the solver on synthetic centres."""
from __future__ import annotations

import json

import numpy as np
import pytest

from dockfactory.core.errors import DockfactoryError
from dockfactory.core.geometry import pose_components
from dockfactory.core.resources import shipped_design_card
from dockfactory.eval.design_card import load_design_card
from dockfactory.eval.design_noise import CentreNoiseLaw, disc_minor_px, over_weights, size_factors
from dockfactory.eval.design_predict import NoiseClass, frame_variances
from dockfactory.eval.design_space import Camera, Design, Lens
from dockfactory.solver import solve_docking
from dockfactory.solver.disc_noise import REFERENCE_RADIUS_PX, section_noise_shapes
from dockfactory.solver.synthetic import default_layout, docking_scene

LAYOUT = default_layout()
MA = [m for m in LAYOUT if m.section == "A"]
MB = [m for m in LAYOUT if m.section == "B"]
LAW = CentreNoiseLaw(1.0, 5.0, 8.0, 3.0)
COMPS = (("x_mm", 0), ("y_mm", 1), ("alpha_deg", 3))


def test_size_factors_are_one_at_the_reference_disc_and_grow_as_the_disc_shrinks():
    f = size_factors([REFERENCE_RADIUS_PX, REFERENCE_RADIUS_PX / 2, REFERENCE_RADIUS_PX * 2], 0.75)
    np.testing.assert_allclose(f, [1.0, 2 ** 0.75, 2 ** -0.75])
    np.testing.assert_array_equal(size_factors([3.0, 30.0], 0.0), [1.0, 1.0])


def test_the_size_exponent_scales_each_marker_s_ratio_by_its_factor_squared():
    """over_weights at exponent k is the law's ratio times (REFERENCE_RADIUS_PX / b)^(2k) per marker,
    b each disc's minor semi-axis; with no law the ratio is the factor squared alone."""
    sc = docking_scene(np.random.default_rng(3))
    minor, _ = disc_minor_px(MA, sc.cam_from_d, sc.focal_px)
    base = over_weights(MA, sc.cam_from_d, sc.focal_px, LAW)
    np.testing.assert_allclose(over_weights(MA, sc.cam_from_d, sc.focal_px, LAW, 0.75),
                               base * (REFERENCE_RADIUS_PX / minor) ** 1.5, rtol=1e-12)
    np.testing.assert_allclose(over_weights(MA, sc.cam_from_d, sc.focal_px, None, 1.0),
                               (REFERENCE_RADIUS_PX / minor) ** 2, rtol=1e-12)
    assert np.ptp(minor) > 0.5   # the discs differ: the factor is not one number


def test_a_frame_s_variances_grow_by_the_markers_factors():
    """The noise variance of every pose component at exponent 1 over exponent 0 lies within the
    smallest and largest squared factor of the frame's markers; the offset's is their mean square."""
    sc = docking_scene(np.random.default_rng(11))
    args = (LAYOUT, sc.cam_from_d, sc.cam_from_b, sc.focal_px, sc.principal_point)
    vn0, vs0 = frame_variances(*args, NoiseClass(0.01, (0.02, 0.01), LAW))
    vn1, vs1 = frame_variances(*args, NoiseClass(0.01, (0.02, 0.01), LAW, 1.0))
    f2 = size_factors(np.r_[disc_minor_px(MA, sc.cam_from_d, sc.focal_px)[0],
                            disc_minor_px(MB, sc.cam_from_b, sc.focal_px)[0]], 1.0) ** 2
    assert np.all(vn1 / vn0 >= f2.min() * (1 - 1e-9)) and np.all(vn1 / vn0 <= f2.max() * (1 + 1e-9))
    np.testing.assert_allclose(vs1 / vs0, np.mean(f2), rtol=1e-9)


def _card(tmp_path, **changes):
    card = json.loads(shipped_design_card().read_text())
    path = tmp_path / "card.json"
    path.write_text(json.dumps({**card, **changes}))
    return path


def _design(cfa: str):
    return Design(Camera("cam", 1440, 1080, 3.45, cfa), Lens(6.0), (1000.0, 1800.0), 24.0, "dark", 7, "png")


def test_the_card_gives_each_camera_class_its_size_exponent(tmp_path):
    path = _card(tmp_path, format="dockfactory.design_predictor/5", cfa_size_exponent={"none": 0.0, "rggb": 0.75})
    card = load_design_card(path)
    assert card.noise_of(_design("rggb"))[0].size_exponent == 0.75
    assert card.noise_of(_design("none"))[0].size_exponent == 0.0


def test_a_card_of_format_4_loads_with_one_factor_for_every_disc(tmp_path):
    data = {k: v for k, v in json.loads(shipped_design_card().read_text()).items() if k != "cfa_size_exponent"}
    path = tmp_path / "four.json"
    path.write_text(json.dumps({**data, "format": "dockfactory.design_predictor/4"}))
    assert load_design_card(path).noise_of(_design("rggb"))[0].size_exponent == 0.0


@pytest.mark.parametrize("table, needle", [({"none": 0.0, "rggb": -0.5}, "cfa_size_exponent.rggb: expected a non-negative number"),
                                           ({"rggb": 0.5}, "cfa_size_exponent: expected a table of none, rggb")])
def test_a_bad_size_exponent_is_one_line(tmp_path, table, needle):
    path = _card(tmp_path, format="dockfactory.design_predictor/5", cfa_size_exponent=table)
    with pytest.raises(DockfactoryError) as exc:
        load_design_card(path)
    assert needle in str(exc.value) and str(path) in str(exc.value) and "\n" not in str(exc.value)


@pytest.mark.slow
def test_predicted_rmse_follows_the_solver_under_a_size_exponent():
    """300 synthetic frames whose centres' noise is the law times the size factors at exponent 1
    (the solver still weighs by its own law): the solver's RMSE of X, Y, alpha is within 0.8-1.25x
    of the prediction; the prediction at exponent 0 with the same scale is further off on some
    component than 1.25x."""
    rng = np.random.default_rng(75)
    noise = NoiseClass(0.004, (0.0, 0.0), LAW, 1.0)
    classes = np.array([0 if m.section == "A" else 1 for m in LAYOUT])
    err, var, var0 = [], [], []
    for _ in range(300):
        sc = docking_scene(rng)
        args = (LAYOUT, sc.cam_from_d, sc.cam_from_b, sc.focal_px, sc.principal_point)
        ratio = np.r_[over_weights(MA, sc.cam_from_d, sc.focal_px, LAW, 1.0),
                      over_weights(MB, sc.cam_from_b, sc.focal_px, LAW, 1.0)]
        shapes = np.concatenate([section_noise_shapes(MA, sc.cam_from_d, sc.focal_px),
                                 section_noise_shapes(MB, sc.cam_from_b, sc.focal_px)]) * ratio[:, None, None]
        uv = np.vstack([sc.uv_a, sc.uv_b])
        uv = uv + np.einsum("nab,nb->na", np.linalg.cholesky(noise.scale_px ** 2 * shapes), rng.standard_normal(uv.shape))
        res = solve_docking(LAYOUT, sc.principal_point, detections=(classes, uv))
        truth = pose_components(sc.d_from_b)
        err.append([getattr(res, k) - truth[k] for k, _ in COMPS])
        var.append([frame_variances(*args, noise)[0][i] for _, i in COMPS])
        var0.append([frame_variances(*args, NoiseClass(0.004, (0.0, 0.0), LAW))[0][i] for _, i in COMPS])
    rmse = np.sqrt(np.mean(np.square(err), axis=0))
    ratio = rmse / np.sqrt(np.mean(var, axis=0))
    assert np.all((ratio > 0.8) & (ratio < 1.25)), ratio
    assert np.max(rmse / np.sqrt(np.mean(var0, axis=0))) > 1.25


def _jpeg_design(fmt: str, ring: str = "dark"):
    return Design(Camera("cam", 1440, 1080, 3.45, "none"), Lens(6.0), (1000.0, 1800.0), 24.0, ring, 7, fmt)


def test_a_jpeg_takes_the_figure_of_the_highest_quality_measured_at_or_below_its_own(tmp_path):
    """jpeg_factor at q90, jpeg_factor_above at q95: a q90-94 design takes the q90 figure (the
    noisier), q95-100 the q95 one, each named by its key."""
    q95 = {"dark": {"none": 4.0, "rggb": 3.0}, "white": {"none": 1.5, "rggb": 2.0}}
    path = _card(tmp_path, format="dockfactory.design_predictor/5", cfa_size_exponent={"none": 0.0, "rggb": 0.0},
                 jpeg_factor={"dark": {"none": 8.0, "rggb": 6.0}, "white": {"none": 2.0, "rggb": 2.5}},
                 jpeg_factor_above={"95": q95}, provisional=["jpeg_factor_above.95.white.none"])
    card = load_design_card(path)
    png = card.noise_of(_jpeg_design("png"))[0].scale_px
    for fmt, ring, factor, prov in (("jpeg90", "dark", 8.0, []), ("jpeg94", "dark", 8.0, []), ("jpeg95", "dark", 4.0, []),
                                    ("jpeg100", "dark", 4.0, []), ("jpeg97", "white", 1.5, ["jpeg_factor_above.95.white.none"])):
        noise, used, _ = card.noise_of(_jpeg_design(fmt, ring))
        base = png if ring == "dark" else card.noise_of(_jpeg_design("png", "white"))[0].scale_px
        assert noise.scale_px == pytest.approx(base * factor, rel=1e-12), fmt
        assert used == prov


@pytest.mark.parametrize("table, needle", [({"85": {}}, "jpeg_factor_above.85: expected an integer quality in 91-100"),
                                           ({"q95": {}}, "jpeg_factor_above.q95: expected an integer quality"),
                                           ({"95": {"dark": {"none": 2.0, "rggb": 2.0}}},
                                            "jpeg_factor_above.95: expected a table of dark, white")])
def test_a_bad_jpeg_figure_above_q90_is_one_line(tmp_path, table, needle):
    path = _card(tmp_path, format="dockfactory.design_predictor/5", cfa_size_exponent={"none": 0.0, "rggb": 0.0},
                 jpeg_factor_above=table)
    with pytest.raises(DockfactoryError) as exc:
        load_design_card(path)
    assert needle in str(exc.value) and str(path) in str(exc.value) and "\n" not in str(exc.value)
