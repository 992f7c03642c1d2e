"""eval.uncertainty_budget: the GUM budget of one solved pose. The layout term is checked against
a Monte Carlo of perturbed layouts (JCGM 101), the detector-bias term against a re-solve of
shifted centres, the intrinsics split against the Cramer-Rao bounds with and without the focal."""
import numpy as np
import pytest

from dockfactory.core.geometry import pose_components
from dockfactory.core.names import POSE_NAMES
from dockfactory.eval.solve_frames import pose_record
from dockfactory.eval.uncertainty_budget import Sensitivity, pose_budget, record_geometry
from dockfactory.solver import solve_docking
from dockfactory.solver.camera_models import PINHOLE, Intrinsics
from dockfactory.solver.crb import crb_d_from_b
from dockfactory.solver.synthetic import default_layout, docking_scene, project

MARKERS = default_layout()
IDS = [m.id for m in MARKERS if m.section == "A"] + [m.id for m in MARKERS if m.section == "B"]
LAYOUT_SIGMA_MM = 0.5   # large enough to see, small enough to stay linear (errors of about 1 mm)
MC_TRIALS = 500
MC_TOL = 0.10           # relative: the std of a 500-sample std is 3.2 %; first-order terms add ~1 %


def _uv(scene, pa, pb):
    return np.vstack([project(scene.cam_from_d, scene.focal_px, scene.image_centre, pa),
                      project(scene.cam_from_b, scene.focal_px, scene.image_centre, pb)])


def _sensitivity(scene):
    return Sensitivity(scene.points_a, scene.points_b, scene.cam_from_d, scene.cam_from_b,
                       Intrinsics.pinhole(scene.focal_px, scene.image_centre), PINHOLE)


@pytest.mark.parametrize("seed", [7, 8])
def test_layout_term_matches_a_monte_carlo_of_perturbed_layouts(seed):
    """The camera sees markers displaced by N(0, sigma_mm^2) per coordinate from the nominal layout
    the solver assumes (no pixel noise): the spread of the solved poses over 500 layouts matches
    the first-order layout term within 10 % on every component."""
    rng = np.random.default_rng(seed)
    scene = docking_scene(rng, markers=MARKERS)
    predicted = np.sqrt(_sensitivity(scene).layout_var(np.full(len(IDS), LAYOUT_SIGMA_MM)))
    truth = pose_components(scene.d_from_b)
    errors = []
    for _ in range(MC_TRIALS):
        pa = scene.points_a + rng.normal(0.0, LAYOUT_SIGMA_MM, scene.points_a.shape)
        pb = scene.points_b + rng.normal(0.0, LAYOUT_SIGMA_MM, scene.points_b.shape)
        res = solve_docking(MARKERS, scene.image_centre, correspondences=(IDS, _uv(scene, pa, pb)))
        errors.append([res.pose()[n] - truth[n] for n in POSE_NAMES])
    rms = np.sqrt(np.mean(np.square(errors), axis=0))
    assert rms == pytest.approx(predicted, rel=MC_TOL)


def test_bias_term_is_the_pose_shift_of_shifted_centres():
    """Every centre shifted by (b, 0) px: the re-solved pose moves by the bias term of (b, 0)."""
    scene = docking_scene(np.random.default_rng(3), markers=MARKERS)
    uv = _uv(scene, scene.points_a, scene.points_b)
    base = solve_docking(MARKERS, scene.image_centre, correspondences=(IDS, uv)).pose()
    sens = _sensitivity(scene)
    for shift in ((0.3, 0.0), (0.0, 0.3)):
        moved = solve_docking(MARKERS, scene.image_centre, correspondences=(IDS, uv + shift)).pose()
        actual = np.abs([moved[n] - base[n] for n in POSE_NAMES])
        assert actual == pytest.approx(np.sqrt(sens.bias_var(shift)), rel=0.02, abs=1e-6)


def test_intrinsics_share_is_what_estimating_the_focal_adds():
    """The share of the focal's estimation = 1 - (bound with f known) / (bound with f estimated):
    the Cramer-Rao bounds of the calibrated and the joint problems."""
    scene = docking_scene(np.random.default_rng(5), markers=MARKERS)
    args = (scene.points_a, scene.cam_from_d, scene.points_b, scene.cam_from_b, scene.focal_px,
            scene.image_centre, 1.0)
    joint = np.diag(crb_d_from_b(*args, problem="joint").covariance)
    known = np.diag(crb_d_from_b(*args, problem="calibrated").covariance)
    assert _sensitivity(scene).intrinsics_share() == pytest.approx(1.0 - known / joint, abs=1e-6)


def _record(seed: int, sigma_px: float = 0.1):
    rng = np.random.default_rng(seed)
    scene = docking_scene(rng, markers=MARKERS)
    uv = _uv(scene, scene.points_a, scene.points_b) + rng.normal(0.0, sigma_px, (len(IDS), 2))
    res = solve_docking(MARKERS, scene.image_centre, correspondences=(IDS, uv), sigma_px=sigma_px)
    return {**pose_record(res, len(IDS)), "image_size": list(scene.image_size)}


def test_budget_terms_add_up_to_the_reported_uncertainty_and_the_layout():
    rec = _record(11)
    reported = np.sqrt(np.diag(np.array(rec["covariance"])))
    plain = pose_budget(rec, MARKERS)
    for i, n in enumerate(POSE_NAMES):
        b = plain[n]
        assert b["layout"] is None and b["detector_bias"] is None
        assert np.hypot(b["centre_noise"], b["intrinsics"]) == pytest.approx(reported[i], rel=1e-9)
        assert b["combined"] == pytest.approx(reported[i], rel=1e-9)
        assert b["expanded"] == pytest.approx(2 * b["combined"]) and b["k"] == 2.0
        assert b["intrinsics"] > 0   # the focal is always estimated
    sigmas = {m.id: 0.05 for m in MARKERS}
    # the record's sigma was given (known): nothing of the layout error is in its covariance
    with_layout = pose_budget(rec, MARKERS, sigmas, bias_px=(0.02, 0.01), noise_from_residuals=False)
    for i, n in enumerate(POSE_NAMES):
        b = with_layout[n]
        assert b["layout"] > 0 and b["detector_bias"] >= 0
        assert b["combined"] ** 2 == pytest.approx(reported[i] ** 2 + b["layout"] ** 2 + b["detector_bias"] ** 2)
    # the layout term scales with sigma_mm
    doubled = pose_budget(rec, MARKERS, {m.id: 0.1 for m in MARKERS}, noise_from_residuals=False)
    assert doubled["x_mm"]["layout"] == pytest.approx(2 * with_layout["x_mm"]["layout"])


def test_a_noise_estimated_from_residuals_holds_part_of_the_layout_error_not_counted_twice():
    """With the covariance scaled by a residual noise estimate, the layout's share of that noise
    (its expected residual variance over sigma_px^2) moves from the centre-noise term to the
    layout term; a layout error the residuals would show in full empties the centre term."""
    rec = _record(13)
    pa, pb, ids, ca, cb, intr, model = record_geometry(rec, MARKERS)
    sens = Sensitivity(pa, pb, ca, cb, intr, model)
    s = np.full(len(ids), 0.05)
    share = sens.layout_residual_px2(s) / rec["sigma_px"] ** 2
    assert 0 < share < 1
    known = pose_budget(rec, MARKERS, {m.id: 0.05 for m in MARKERS}, noise_from_residuals=False)
    seen = pose_budget(rec, MARKERS, {m.id: 0.05 for m in MARKERS})
    for n in POSE_NAMES:
        assert seen[n]["centre_noise"] ** 2 == pytest.approx(known[n]["centre_noise"] ** 2 * (1 - share))
        assert seen[n]["layout"] == known[n]["layout"] and seen[n]["combined"] < known[n]["combined"]
    huge = pose_budget(rec, MARKERS, {m.id: 5.0 for m in MARKERS})
    assert all(huge[n]["centre_noise"] == 0.0 for n in POSE_NAMES)


def test_a_docking_runs_intrinsics_term_is_its_focal_std_propagated():
    """A frame of a run solved with shared intrinsics: the run's focal std through this frame's
    sensitivity, linear in it, never above the reported variance."""
    rec = {**_record(12), "self_calibrated": "sequence", "intrinsics_std": {"focal_px": 2.0}}
    one = pose_budget(rec, MARKERS)
    two = pose_budget({**rec, "intrinsics_std": {"focal_px": 4.0}}, MARKERS)
    reported = np.sqrt(np.diag(np.array(rec["covariance"])))
    for i, n in enumerate(POSE_NAMES):
        assert one[n]["combined"] == pytest.approx(reported[i], rel=1e-9)
        if two[n]["intrinsics"] < reported[i] * (1 - 1e-9):
            assert two[n]["intrinsics"] == pytest.approx(2 * one[n]["intrinsics"], rel=1e-6)
    huge = pose_budget({**rec, "intrinsics_std": {"focal_px": 1e6}}, MARKERS)
    assert all(huge[n]["intrinsics"] <= reported[i] * (1 + 1e-9) for i, n in enumerate(POSE_NAMES))


def test_budget_block_is_the_rms_over_frames_and_the_report_shows_the_gated_components():
    from dockfactory.eval.report.budget import html_budget
    from dockfactory.eval.uncertainty_budget import budget_block
    recs = [_record(s) for s in (21, 22, 23)]
    sizes = {tuple(r.pop("image_size")) for r in recs}
    block = budget_block(recs + [{"ok": True, "marker_ids": ["nope"]}], MARKERS, sizes.pop(), bias_px=(0.01, -0.02))
    assert block["n"] == 3   # the unreadable record is left out
    singles = [pose_budget({**r, "image_size": [1280, 960]}, MARKERS, bias_px=(0.01, -0.02)) for r in recs]
    for n in POSE_NAMES:
        row = block["components"][n]
        assert row["combined"] == pytest.approx(np.sqrt(np.mean([b[n]["combined"] ** 2 for b in singles])))
        assert row["expanded"] == pytest.approx(2 * row["combined"]) and row["layout"] is None
    metrics = {"uncertainty_budget": block,
               "acceptance": {"criteria": [{"block": "localization", "component": "x"},
                                           {"block": "localization", "component": "alpha"},
                                           {"block": "estimation", "component": "y"}]}}
    text = "".join(html_budget(metrics))
    assert "x (mm)" in text and "alpha (deg)" in text and "y (mm)" not in text
    assert "U (k = 2)" in text and "marker layout" in text and "(0.010, -0.020) px" in text
    assert html_budget({"acceptance": {"criteria": []}}) == []


def test_camera_model_term_is_what_marginalising_the_lens_added():
    """Solved with the unestimated intrinsics marginalised (solver.model_error), the budget's
    camera-model term is the difference between that covariance and the same solve's with the
    lens known, and the terms still add up to the reported uncertainty."""
    from dataclasses import replace

    from dockfactory.solver.options import DEFAULT_DOCKING, LensPrior
    rng = np.random.default_rng(13)
    scene = docking_scene(rng, markers=MARKERS)
    uv = _uv(scene, scene.points_a, scene.points_b) + rng.normal(0.0, 0.1, (len(IDS), 2))
    solves = {m: solve_docking(MARKERS, scene.image_centre, correspondences=(IDS, uv), sigma_px=0.1,
                               options=replace(DEFAULT_DOCKING, lens=LensPrior(marginalise=m)))
              for m in (False, True)}
    added = np.diag(solves[True].covariance) - np.diag(solves[False].covariance)
    assert np.all(added > 0)
    rec = {**pose_record(solves[True], len(IDS)), "image_size": list(scene.image_size)}
    known = {**pose_record(solves[False], len(IDS)), "image_size": list(scene.image_size)}
    budget, plain = pose_budget(rec, MARKERS), pose_budget(known, MARKERS)
    reported = np.sqrt(np.diag(np.array(rec["covariance"])))
    for i, n in enumerate(POSE_NAMES):
        b = budget[n]
        assert b["model_error"] ** 2 == pytest.approx(added[i], rel=1e-6)
        assert np.sqrt(b["centre_noise"] ** 2 + b["intrinsics"] ** 2 + b["model_error"] ** 2) == \
            pytest.approx(reported[i], rel=1e-9)
        assert plain[n]["model_error"] is None
        assert b["centre_noise"] == pytest.approx(plain[n]["centre_noise"], rel=1e-6)


def test_section_offset_term_is_what_the_section_shift_added():
    """Solved with a section shift (solver.section_shift), the budget's section-offset term is
    the difference between that covariance and the same solve's without it; the other terms are
    those of the solve without it, and all add up to the reported uncertainty."""
    from dataclasses import replace

    from dockfactory.solver.options import DEFAULT_DOCKING
    rng = np.random.default_rng(14)
    scene = docking_scene(rng, markers=MARKERS)
    uv = _uv(scene, scene.points_a, scene.points_b) + rng.normal(0.0, 0.1, (len(IDS), 2))
    solves = {s: solve_docking(MARKERS, scene.image_centre, correspondences=(IDS, uv), sigma_px=0.1,
                               options=replace(DEFAULT_DOCKING, section_shift_px=s))
              for s in (None, (0.05, 0.08))}
    added = np.diag(solves[(0.05, 0.08)].covariance) - np.diag(solves[None].covariance)
    assert np.all(added[:2] > 0)
    rec = {**pose_record(solves[(0.05, 0.08)], len(IDS)), "image_size": list(scene.image_size)}
    plain_rec = {**pose_record(solves[None], len(IDS)), "image_size": list(scene.image_size)}
    assert "section_shift_variance" not in plain_rec
    budget, plain = pose_budget(rec, MARKERS), pose_budget(plain_rec, MARKERS)
    reported = np.sqrt(np.diag(np.array(rec["covariance"])))
    for i, n in enumerate(POSE_NAMES):
        b = budget[n]
        assert b["section_shift"] ** 2 == pytest.approx(max(added[i], 0.0), rel=1e-6, abs=1e-15)
        assert b["combined"] == pytest.approx(reported[i], rel=1e-9)
        assert plain[n]["section_shift"] is None
        assert b["centre_noise"] == pytest.approx(plain[n]["centre_noise"], rel=1e-6)
