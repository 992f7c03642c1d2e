"""The goodness-of-fit gate (eval.fit_gate): a fit the known centre noise cannot explain is never ok.

On the painted smoke dataset (tests/pipeline_data.py; exact centroids) the detections are the
centroids plus seeded noise of SIGMA px, the noise the "card" states. Each fault below was solved
ok before the gate, with a pose far off; the gate refuses it, or leaves out the one bad centre.
"""
import math

import numpy as np
import pytest

from dockfactory.core.layout import DEFAULT_LAYOUT_A, DEFAULT_LAYOUT_B, build_layout
from dockfactory.eval import fit_gate
from dockfactory.eval.confidence import chi2_cdf
from dockfactory.eval.fit_gate import MISFIT, fit_test
from dockfactory.eval.solve_frames import KNOWN_LENS, UNCALIBRATED_LENS, docking_options, solve_frame
from dockfactory.generator.datasets.reader import Dataset
from dockfactory.solver.synthetic import default_layout, docking_scene

SIGMA = 0.05


@pytest.fixture(scope="module")
def frames(painted_source):
    """(dataset, [(frame id, class ids, centres (N, 2), pp)]) of every test frame, seeded noise."""
    ds = Dataset.open(painted_source)
    rng = np.random.default_rng(7)
    w, h = ds.config.image.width, ds.config.image.height
    out = []
    for fid in ds.frames(("test", "repeat")):
        vis = [m for m in ds.labels[fid]["markers"] if m["visibility"] == 2]
        uv = np.array([m["outline_centroid_px"] for m in vis]) + rng.normal(0, SIGMA, (len(vis), 2))
        out.append((fid, np.array([m["class_id"] for m in vis]), uv, ((w - 1) / 2, (h - 1) / 2), [m["id"] for m in vis]))
    return ds, out


def _solve(markers, f, uv=None):
    fid, cls, uv0, pp, _ = f
    rec, _, _ = solve_frame(markers, pp, (cls, uv0 if uv is None else uv, None, None, None), None, "pinhole",
                            docking_options(SIGMA))
    return rec


def _error(ds, fid, rec):
    truth = ds.labels[fid]["pose_b_in_d"]
    return {k: rec["pose"][k] - truth[k] for k in ("x_mm", "y_mm", "z_mm")}


def test_frames_with_the_stated_noise_pass_and_say_so(frames):
    ds, fs = frames
    recs = [_solve(ds.markers(), f) for f in fs]
    assert len(recs) >= 6 and all(r["ok"] for r in recs)
    assert all(r["fit_test"]["explains"] is True and "left_out" not in r for r in recs)
    ratios = [r["fit_test"]["ratio"] for r in recs]
    assert 0.6 < float(np.median(ratios)) < 1.4            # the residuals follow the stated noise


@pytest.mark.slow  # several seconds of solves or pages; the full suite runs it
def test_another_scenes_layout_is_refused_in_one_line(frames, monkeypatch):
    ds, fs = frames
    other = build_layout(ds.config.markers.layout_a, ds.config.markers.layout_b, 450.0, 30.0)
    with monkeypatch.context() as m:                                      # the solver without the gate
        m.setattr(fit_gate, "fit_test", lambda record, sigma: {"explains": None, "dof": 0})
        before = [_solve(other, f) for f in fs[:4]]
    wrong = [abs(_error(ds, f[0], r)["x_mm"]) for f, r in zip(fs, before) if r["ok"]]
    assert len(wrong) >= 3 and min(wrong) > 100                          # ok without the gate, far off
    after = [_solve(other, f) for f in fs[:4]]
    assert all(not r["ok"] for r in after)
    misfits = [r for r in after if r["category"] == MISFIT]
    assert len(misfits) >= 3 and all("x the camera's centre noise" in r["reason"] and "wrong layout" in r["reason"]
                                     and "\n" not in r["reason"] for r in misfits)


@pytest.mark.slow  # several seconds of solves or pages; the full suite runs it
def test_a_stretched_image_is_refused(frames):
    ds, fs = frames
    for f in fs[:3]:
        pp = np.array(f[3])
        uv = pp + (f[2] - pp) * np.array([1.5, 1.0])           # width stretched 1.5x
        rec = _solve(ds.markers(), f, uv=uv)
        assert not rec["ok"] and rec["category"] in (MISFIT, "ambiguous identification"), rec


def test_one_bad_centre_is_left_out_and_named(frames):
    ds, fs = frames
    for f in fs[:4]:
        uv = f[2].copy()
        uv[3] += (1.5, -1.0)                                    # a glare spot moves one refined centre 1.8 px
        rec = _solve(ds.markers(), f, uv=uv)
        assert rec["ok"] and rec["left_out"] == [f[4][3]], rec.get("reason")
        assert rec["fit_test"]["explains"] and rec["fit_test"]["before"]["ratio"] > 3
        err = _error(ds, f[0], rec)
        cov = np.array(rec["covariance"])
        assert all(abs(err[k]) < 4 * math.sqrt(cov[i, i]) for i, k in enumerate(("x_mm", "y_mm", "z_mm")))


def test_fit_test_is_the_chi_square_of_the_residuals_or_says_not_tested():
    rec = {"n_markers": {"A": 7, "B": 7}, "rmse_px": {"A": 0.1, "B": 0.2}, "camera_model": "pinhole"}
    got = fit_test(rec, 0.1 / fit_gate.GATE_NOISE_FACTOR)           # the test's noise: 0.1 px
    rss = 0.1 ** 2 * 7 + 0.2 ** 2 * 7
    assert got["dof"] == 28 - 13 and got["statistic"] == pytest.approx(rss / 0.01)
    assert got["p_value"] == pytest.approx(1 - chi2_cdf(rss / 0.01, 15), rel=1e-6)
    assert got["ratio"] == pytest.approx(math.sqrt(rss / 15) / (0.1 / fit_gate.GATE_NOISE_FACTOR))
    assert got["explains"] is True
    assert fit_test(rec, 0.02 / fit_gate.GATE_NOISE_FACTOR)["explains"] is False   # 5x the test's noise: p ~ 1e-40
    assert fit_test(rec, None) == {"explains": None, "not_tested": "no known centre noise", "dof": 15}
    few = {**rec, "n_markers": {"A": 3, "B": 3}}
    assert fit_test(few, 0.1) == {"explains": None, "not_tested": "no degrees of freedom", "dof": 0}
    k1k2 = fit_test({**rec, "camera_model": "k1k2"}, 0.1)
    assert k1k2["dof"] == 13


CARD = 0.0258   # a card at which the chi-square alone passes the crop (the default weights' card before the light tree)
FAR = dict(radius_mm=450.0, distance_range=(2000.0, 2500.0), focal_range=(2000.0, 3600.0))   # scene B's geometry


def _synthetic(seed: int, pp_offset_px, lens=KNOWN_LENS, coeffs=None, far: bool = True):
    """One frame of a camera (principal point ``pp_offset_px`` off the image centre, distortion
    ``coeffs``) seeing a docking layout of radius 450 mm and 30 mm discs from 2.0-2.5 m (``far``;
    else the default layout and geometry of solver.synthetic), its centres + N(0, CARD^2), solved
    with the principal point at the image centre and the lens prior ``lens`` through the gate."""
    layout = build_layout(DEFAULT_LAYOUT_A, DEFAULT_LAYOUT_B, 450.0, 30.0) if far else default_layout()
    sc = docking_scene(np.random.default_rng(seed), markers=layout, pp_offset_px=pp_offset_px, coeffs=coeffs,
                       **(FAR if far else {}))
    n_a, n_b = len(sc.uv_a), len(sc.uv_b)
    uv = np.vstack([sc.uv_a, sc.uv_b]) + CARD * np.random.default_rng(seed + 1000).standard_normal((n_a + n_b, 2))
    cls = np.r_[np.zeros(n_a, dtype=int), np.ones(n_b, dtype=int)]
    return solve_frame(layout, sc.image_centre, (cls, uv, None, None, None), None, "pinhole",
                       docking_options(CARD, lens))[0]


@pytest.mark.parametrize("seed", [3, 6])
def test_a_principal_point_off_centre_is_refused_by_the_camera_model_check(seed, monkeypatch):
    """A crop (principal point 160 / 120 px off centre) of a camera whose lens is stated known, at the
    card's noise: without the camera-model check the chi-square passes after two centres are left
    out (residuals about 6x the card); with it the frame is refused in one line. Centred, the same
    frame is ok as is."""
    with monkeypatch.context() as m:                                      # the gate without the check
        m.setattr(fit_gate, "camera_misfit", lambda record: None)
        before = _synthetic(seed, (160.0, 120.0))
    assert before["ok"] and before["left_out"], before.get("reason")
    cropped = _synthetic(seed, (160.0, 120.0))
    assert not cropped["ok"] and cropped["category"] == MISFIT
    assert "camera-model check" in cropped["reason"] and "principal point" in cropped["reason"]
    assert "\n" not in cropped["reason"]
    centred = _synthetic(seed, (0.0, 0.0))
    assert centred["ok"] and "left_out" not in centred, centred.get("reason")
    assert centred["model_check"]["known_noise_p_value"] > 1e-3


def test_lenses_within_the_uncalibrated_prior_are_not_refused_by_the_camera_model_check():
    """An uncalibrated camera (the lens prior marginalised), the default geometry: a lens drawn within
    the prior's ranges is what the covariance already carries, so the check tests the departure
    against it, not against none (which refuses about half of these frames)."""
    rng = np.random.default_rng(4)
    for seed in range(6):
        pp, coeffs = tuple(rng.uniform(-40.0, 40.0, 2)), (rng.uniform(-0.15, 0.05), 0.0, *rng.uniform(-1e-3, 1e-3, 2))
        rec = _synthetic(seed, pp, UNCALIBRATED_LENS, coeffs, far=False)
        assert rec["ok"] or "camera-model check" not in rec["reason"], rec["reason"]
        assert not rec["ok"] or rec["model_check"]["known_noise_p_value"] >= fit_gate.GATE_P


def test_camera_misfit_reads_the_known_noise_p_value():
    assert fit_gate.camera_misfit({"model_check": {"known_noise_p_value": 1e-9}}) == 1e-9
    assert fit_gate.camera_misfit({"model_check": {"known_noise_p_value": 0.0}}) == 0.0
    assert fit_gate.camera_misfit({"model_check": {"known_noise_p_value": 0.2}}) is None
    assert fit_gate.camera_misfit({"model_check": {"known_noise_p_value": None}}) is None
    assert fit_gate.camera_misfit({}) is None
