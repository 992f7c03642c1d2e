"""measure --calibration: the centres of a calibrated camera are taken to its ideal pinhole camera
(core.calibration_files.ideal_pixels) and solved with its principal point, the lens known. A lens
with its principal point 25 / -18 px off and k1 -0.12 then solves within its uncertainty, every
frame, with Y and alpha errors under half of the uncalibrated solve's; an image of another size
is refused; the CLI refuses estimating what the calibration states."""
from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from cli_run import one_line_error, run_cli
from dockfactory.core.calibration_files import Calibration, ideal_pixels, write_calibration
from dockfactory.core.geometry import pose_components
from dockfactory.eval.solve_frames import docking_options, solve_frame
from dockfactory.measure.images import calibrated_solve
from dockfactory.solver.synthetic import default_layout, docking_scene

LAYOUT = default_layout()
DETECTOR = SimpleNamespace(centre_noise_px=0.05, section_shift_px=None, noise_core_px=None)


def _frame(rng):
    sc = docking_scene(rng, pp_offset_px=(25.0, -18.0), coeffs=(-0.12, 0.03))
    uv = np.vstack([sc.uv_a, sc.uv_b]) + 0.05 * rng.standard_normal((14, 2))
    cal = Calibration(1280, 960, sc.focal_px, sc.focal_px, *sc.principal_point, (-0.12, 0.03, 0.0, 0.0, 0.0))
    return sc, (np.array([0] * 7 + [1] * 7), uv, None, np.ones(14, bool)), cal


def test_ideal_pixels_undo_the_lens():
    rng = np.random.default_rng(4)
    sc, (_, uv, *_), cal = _frame(rng)
    clean = docking_scene(np.random.default_rng(4), pp_offset_px=(25.0, -18.0))   # the same draw, no distortion
    ideal, f = ideal_pixels(cal, np.vstack([sc.uv_a, sc.uv_b]))
    assert f == pytest.approx(sc.focal_px)
    assert np.max(np.abs(ideal - np.vstack([clean.uv_a, clean.uv_b]))) < 1e-6


def test_a_calibrated_camera_solves_within_its_uncertainty():
    rng = np.random.default_rng(8)
    z_cal, e_cal, e_plain = [], [], []
    for _ in range(20):
        sc, centres, cal = _frame(rng)
        truth = pose_components(sc.d_from_b)
        rec, _ = calibrated_solve(DETECTOR, LAYOUT, Path("f.png"), (1280, 960), centres, cal)
        assert rec["ok"] and rec["calibration"]["focal_px"] == pytest.approx(sc.focal_px)
        assert rec["focal_px"] == pytest.approx(sc.focal_px, rel=0.03)
        std = np.sqrt(np.diag(rec["covariance"]))
        z_cal.append([(rec["pose"][k] - truth[k]) / s for k, s in zip(("x_mm", "y_mm"), std[:2])])
        e_cal.append([rec["pose"][k] - truth[k] for k in ("x_mm", "y_mm", "alpha_deg")])
        plain, _ = solve_frame(LAYOUT, (639.5, 479.5), centres, None, "pinhole", docking_options(0.05))
        if plain["ok"]:
            e_plain.append([plain["pose"][k] - truth[k] for k in ("x_mm", "y_mm", "alpha_deg")])
    assert np.sqrt(np.mean(np.square(z_cal))) < 1.5 and np.max(np.abs(z_cal)) < 4.5
    rmse_cal, rmse_plain = np.sqrt(np.mean(np.square(e_cal), axis=0)), np.sqrt(np.mean(np.square(e_plain), axis=0))
    # measured: X / Y / alpha 0.17 / 0.11 / 0.009 calibrated, 0.22 / 0.53 / 0.045 uncalibrated (15 of 20 solved)
    assert rmse_cal[0] < rmse_plain[0] and np.all(rmse_cal[1:] < 0.5 * rmse_plain[1:]), (rmse_cal, rmse_plain)


def test_an_image_of_another_size_is_refused():
    sc, centres, cal = _frame(np.random.default_rng(9))
    rec, used = calibrated_solve(DETECTOR, LAYOUT, Path("f.png"), (1920, 1080), centres, cal)
    assert not rec["ok"] and rec["category"] == "calibration size" and "1920x1080" in rec["reason"] and not used


def test_the_cli_refuses_estimating_what_the_calibration_states(tmp_path, capsys):
    write_calibration(Calibration(1280, 960, 2000.0, 2000.0, 640.0, 480.0), tmp_path / "cam.yaml", "opencv-yaml")
    base = ["measure", str(tmp_path), "--layout", str(tmp_path / "l.json"), "--calibration", str(tmp_path / "cam.yaml")]
    code, _, err = run_cli(base + ["--out", str(tmp_path / "o"), "--camera-model", "auto"], capsys)
    assert code == 2 and "--calibration: the camera is calibrated" in one_line_error(err)
    code, _, err = run_cli(["measure", "--video", "x.mp4", "--layout", "l.json", "--calibration",
                            str(tmp_path / "cam.yaml"), "--self-calibrate", "window:3"], capsys)
    assert code == 2 and "--calibration: the camera is calibrated" in one_line_error(err)


def test_a_calibrations_stated_uncertainty_is_in_the_budget():
    """A calibration whose principal point is off by its stated std (cx +10, cy -10 px with sigma
    10 px; k1 off by 0.03 with sigma 0.03): without the stated std the pose's reported uncertainty
    ignores it and the errors run beyond it (measured RMS z of X / Y / Z / alpha 0.73 / 1.26 /
    4.29 / 2.59); with it they stay within (0.65 / 0.92 / 1.29 / 1.09), the reported std grown."""
    rng = np.random.default_rng(21)
    z_with, z_without, grew = [], [], []
    for _ in range(20):
        sc, centres, cal = _frame(rng)
        truth = pose_components(sc.d_from_b)
        off = Calibration(cal.width, cal.height, cal.fx, cal.fy, cal.cx + 10.0, cal.cy - 10.0,
                          (cal.dist[0] + 0.03, *cal.dist[1:]))
        stated = Calibration(*[getattr(off, k) for k in ("width", "height", "fx", "fy", "cx", "cy", "dist")],
                             std=(2.0, 2.0, 10.0, 10.0, 0.03, 0.005, 1e-4, 1e-4, 0.0))
        recs = [calibrated_solve(DETECTOR, LAYOUT, Path("f.png"), (1280, 960), centres, c)[0] for c in (off, stated)]
        if not all(r["ok"] for r in recs):
            continue
        for rec, out in zip(recs, (z_without, z_with)):
            std = np.sqrt(np.diag(rec["covariance"]))
            keys = ("x_mm", "y_mm", "z_mm", "alpha_deg")
            out.append([(rec["pose"][k] - truth[k]) / s for k, s in zip(keys, std[:4])])
        grew.append(np.sqrt(np.diag(recs[1]["covariance"]))[2] / np.sqrt(np.diag(recs[0]["covariance"]))[2])
        assert recs[1]["calibration"]["std"][2] == 10.0 and "std" not in recs[0]["calibration"]
    assert len(z_with) >= 15
    rms_with, rms_without = np.sqrt(np.mean(np.square(z_with), axis=0)), np.sqrt(np.mean(np.square(z_without), axis=0))
    assert np.all(rms_with <= 1.5) and np.max(rms_without) > 3.0, (rms_with, rms_without)
    assert np.median(grew) > 1.5


def test_the_stated_uncertainty_round_trips_and_is_checked(tmp_path):
    from dockfactory.core.calibration_files import CalibrationError, read_calibration
    cal = Calibration(1280, 960, 2000.0, 2000.5, 640.2, 480.1, (-0.1, 0.02, 0.0, 0.0, 0.0),
                      std=(1.5, 1.6, 0.8, 0.9, 0.004, 0.01, 1e-4, 2e-4, 0.0))
    for suffix, fmt in ((".yaml", "opencv-yaml"), (".json", "opencv-json")):
        write_calibration(cal, tmp_path / f"c{suffix}", fmt)
        assert read_calibration(tmp_path / f"c{suffix}") == cal
    text = (tmp_path / "c.yaml").read_text().replace("data: [ 1.5,", "data: [ -1.5,")
    (tmp_path / "bad.yaml").write_text(text)
    with pytest.raises(CalibrationError, match="std_deviations_intrinsics: expected 9 finite values >= 0"):
        read_calibration(tmp_path / "bad.yaml")


def test_the_overlay_reprojects_through_the_calibrated_lens():
    """The overlay's reprojected layout of a calibrated image is the calibrated camera's projection
    (OpenCV's projectPoints with its K and lens, from the solved pose), not the ideal pinhole's."""
    import cv2

    from dockfactory.measure.overlay import project_layout
    sc, centres, cal = _frame(np.random.default_rng(12))
    rec, _ = calibrated_solve(DETECTOR, LAYOUT, Path("f.png"), (1280, 960), centres, cal)
    got = project_layout(rec, LAYOUT)
    cam_from_a, a_from_b = np.array(rec["cam_from_a"]), np.array(rec["d_from_b"])
    want = []
    for m in LAYOUT:
        t = cam_from_a if m.section == "A" else cam_from_a @ a_from_b
        p, _ = cv2.projectPoints(np.array([m.center_mm]), cv2.Rodrigues(t[:3, :3])[0], t[:3, 3], cal.K, np.array(cal.dist))
        want.append(p.ravel())
    assert np.abs(got - np.array(want)).max() < 1e-6
    assert np.abs(got - np.vstack([sc.uv_a, sc.uv_b])).max() < 1.0   # near the true image points



def test_a_calibrated_records_bias_term_is_the_pose_shift_of_shifted_delivered_centres():
    """A calibrated camera with non-square pixels (fy = 1.08 fx) and its principal point 25 / -18 px
    off the image centre: every delivered centre shifted by 0.1 px along one axis moves the pose
    solved from their ideal pixels (core.calibration_files.ideal_pixels, what measure --calibration
    solves; the plain least squares the budget linearises) by the detector-bias term of the
    measure record's budget, within 1 % (before: 3.6-4.4 % off, the shift taken unscaled by the
    ideal camera's f / fx, f / fy), about the calibration's principal point (before: the image
    centre). A calibration of square pixels centred on the image gives the budget of a record
    without one."""
    import cv2

    from dockfactory.eval.uncertainty_budget import pose_budget, record_geometry
    from dockfactory.solver import solve_docking
    sc = docking_scene(np.random.default_rng(6), pp_offset_px=(25.0, -18.0))
    fx, fy = sc.focal_px, 1.08 * sc.focal_px
    cal = Calibration(1280, 960, fx, fy, *sc.principal_point)
    uv = np.vstack([cv2.projectPoints(pts, cv2.Rodrigues(cam[:3, :3])[0], cam[:3, 3], cal.K, np.zeros(5))[0]
                    .reshape(-1, 2) for pts, cam in ((sc.points_a, sc.cam_from_d), (sc.points_b, sc.cam_from_b))])
    centres = (np.array([0] * 7 + [1] * 7), uv, None, np.ones(14, bool))
    rec = {**calibrated_solve(DETECTOR, LAYOUT, Path("f.png"), (1280, 960), centres, cal)[0], "image_size": [1280, 960]}
    assert rec["ok"] and np.array_equal(record_geometry(rec, LAYOUT)[5].principal_point, sc.principal_point)
    ids = [m.id for m in LAYOUT if m.section == "A"] + [m.id for m in LAYOUT if m.section == "B"]

    def pose(shift):
        return solve_docking(LAYOUT, sc.principal_point, correspondences=(ids, ideal_pixels(cal, uv + shift)[0])).pose()

    base = pose((0.0, 0.0))
    for shift in ((0.1, 0.0), (0.0, 0.1)):
        moved, budget = pose(shift), pose_budget(rec, LAYOUT, bias_px=shift)
        for name in base:
            assert budget[name]["detector_bias"] == pytest.approx(abs(moved[name] - base[name]), rel=0.01), name
    square = {**rec, "calibration": {**rec["calibration"], "fx": fx, "fy": fx, "principal_point": [639.5, 479.5]}}
    plain = {k: v for k, v in rec.items() if k != "calibration"}
    assert pose_budget(square, LAYOUT, bias_px=(0.02, 0.01)) == pose_budget(plain, LAYOUT, bias_px=(0.02, 0.01))
