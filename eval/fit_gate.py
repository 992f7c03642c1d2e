"""A goodness-of-fit gate on every solved frame: residuals the camera's known noise cannot explain.

``fit_test``: the chi-square of a solve's residuals against that noise, T = RSS / (k sigma)^2 over
dof = 2 n - p (n points used, p = 13 pose and focal parameters plus the free intrinsics of its
camera model; k = GATE_NOISE_FACTOR), and its p-value; the frame ``explains`` the residuals when
p >= GATE_P. Without a known noise, or without degrees of freedom, nothing is tested (``explains``
None). ``camera_misfit``: the camera-model check (solver.model_error) against the same noise.
``class_test``: a noisier camera class's second test (its noise, and no pattern of the image's
geometry in the residuals). ``run_misfits``: the test on each frame of a docking run solved with
shared intrinsics (eval.solve_frames.solve_run), the class's too: a frame the run's intrinsics
cannot explain is left out of the run, the run solved again without it.

Why and how: docs/acceptance.md, "The goodness-of-fit gate".
"""
from __future__ import annotations

import math

import numpy as np

from dockfactory.core.errors import DockfactoryError
from dockfactory.eval.camera_classes import CAMERA_CLASS_FACTORS
from dockfactory.solver.camera_models import camera_model as model_named
from dockfactory.solver.options import GATE_NOISE_FACTOR
from dockfactory.solver.stats import chi2_logsf, ncp_for_power

GATE_P = 1e-6          # a frame is refused below this p-value (its false alarms: bench/results/fit_gate/README.md)

PATTERN_P = 0.1        # the class's test needs the residuals' geometry pattern at least this likely
PATTERN_MIN_DOF = 3    # ... over at least this many tested directions (fewer: no class test, the card's,
PATTERN_POWER = None   # unless the test would catch a principal point off by PATTERN_OFFSET lens-prior
PATTERN_OFFSET = 2.0   # half-ranges with at least this probability (None, the default: never; _pattern_testable)
MAX_LEFT_OUT = 2       # centres the gate may leave out of one frame
LEFT_OUT_NEEDS_PATTERN = True   # a camera class noisier than the card keeps a fit with centres left out only
                                # where the camera-model check can still test PATTERN_MIN_DOF directions
LEFT_OUT_MIN_FACTOR = CAMERA_CLASS_FACTORS["three-chip"]   # ... the classes above this factor (the card's)
MISFIT = "misfit"      # the failure category of a frame the gate refuses
POSE_AND_FOCAL = 13    # the parameters every fit estimates: two poses and the focal length


def fit_parameters(record: dict) -> float:
    """The parameters the solve of ``record`` estimated for its frame: 13 + its model's free ones;
    a frame of a docking run solved with shared intrinsics (``run_frames`` F) has its two poses
    and a 1 / F share of the intrinsics."""
    shared = 1 + model_named(record.get("camera_model", "pinhole")).n_extra
    frames = record.get("run_frames") if record.get("self_calibrated") in ("sequence", "window") else None
    return POSE_AND_FOCAL - 1 + shared / frames if frames else POSE_AND_FOCAL - 1 + shared


def residual_dof(record: dict) -> float:
    """The residual degrees of freedom of the solve of ``record``: 2 per centre it used less
    :func:`fit_parameters` (what its fit test and its camera-model check's F test count)."""
    return 2 * sum(record["n_markers"][s] for s in ("A", "B")) - fit_parameters(record)


def _dof(dof: float) -> int | float:
    """An integral count as an int, a run's share of the intrinsics to 3 decimals."""
    return int(dof) if float(dof).is_integer() else round(float(dof), 3)


def fit_test(record: dict, sigma_px: float | None) -> dict:
    """{"explains": True | False | None, "statistic", "dof", "p_value", "ratio"} of a solved
    poses record against the known centre noise ``sigma_px`` (px per axis; None: not tested).
    ``ratio``: the residuals' per-axis RMS over ``sigma_px`` (the test's noise is
    ``GATE_NOISE_FACTOR`` times it)."""
    n = {s: record["n_markers"][s] for s in ("A", "B")}
    rss = sum(record["rmse_px"][s] ** 2 * n[s] for s in n)
    dof = residual_dof(record)
    if sigma_px is None or not sigma_px > 0 or dof < 1:
        why = "no known centre noise" if dof > 0 else "no degrees of freedom"
        return {"explains": None, "not_tested": why, "dof": _dof(max(dof, 0))}
    stat = rss / (GATE_NOISE_FACTOR * sigma_px) ** 2
    log_p = chi2_logsf(stat, dof)
    return {"explains": bool(log_p >= math.log(GATE_P)), "statistic": float(stat), "dof": _dof(dof),
            "p_value": float(math.exp(log_p)), "ratio": float(math.sqrt(rss / dof) / sigma_px)}


def misfit_reason(test: dict, sigma_px: float, left_out: int) -> str:
    """One line: why the gate refused a frame."""
    tried = f" (and with up to {left_out} centres left out)" if left_out else ""
    return (f"residuals {test['ratio']:.1f}x the camera's centre noise ({sigma_px:.3g} px; chi-square "
            f"{test['statistic']:.3g} over {test['dof']:g} dof at {GATE_NOISE_FACTOR:g}x it, p {test['p_value']:.2g})"
            f"{tried}: wrong layout, wrong image geometry or a bad centre")


def camera_misfit(record: dict) -> float | None:
    """The p-value of ``record``'s camera-model check against the known centre noise when it is
    below GATE_P, else None (explained, or not tested: no known noise, nothing testable). Below
    GATE_P the residuals show the model's unestimated intrinsics (principal point, distortion)
    departing from what the lens prior allows (from none when the lens is stated known): a
    principal point off centre the chi-square alone cannot tell from a noisier camera."""
    p = (record.get("model_check") or {}).get("known_noise_p_value")
    return p if p is not None and p < GATE_P else None


def _pattern_testable(record: dict) -> bool:
    """Whether the camera-model check of a solved poses ``record`` (its ``model_check``) can tell a
    noisier camera's residuals from an image geometry's pattern: it tests at least
    PATTERN_MIN_DOF directions, or fewer that would show a principal point off by PATTERN_OFFSET
    lens-prior half-ranges (a cropped image) at PATTERN_P with probability PATTERN_POWER (None, the
    default: never): its ``pp_offset_ncp`` times PATTERN_OFFSET^2 at least the noncentrality the F
    test needs at the fit's residual degrees of freedom (more than the chi-square's). Why the
    offset: a principal point within the prior's range is in the pose's marginalised uncertainty;
    at twice it, 3.5 of the prior's standard deviations, the pose is confidently wrong in the
    components it moves. Why both: the count says how many combinations of the intrinsics the
    data determine, the power whether the one a crop moves is among them. Why off by default: at
    0.9 and two half-ranges it gave honest frames back and let crops of that size through with a
    confident wrong pose, a miss its 0.9 allows (bench/results/fit_gate/README.md, "The pattern's
    power")."""
    check = record.get("model_check") or {}
    dof = check.get("dof", 0)
    if dof >= PATTERN_MIN_DOF:
        return True
    ncp = check.get("pp_offset_ncp")
    dof_res = round(residual_dof(record))
    return (PATTERN_POWER is not None and dof >= 1 and ncp is not None and dof_res >= 1
            and ncp * PATTERN_OFFSET ** 2 >= ncp_for_power(dof, PATTERN_P, PATTERN_POWER, dof_res))


def class_test(record: dict, sigma_px: float | None, factor: float) -> dict | None:
    """The fit test of ``record`` at its camera class's noise (``factor`` times ``sigma_px``, the
    card's), with ``camera_class_factor`` and ``pattern_p``, when the residuals pass it and show no
    pattern of the image's geometry (the camera-model check's own p-value at least PATTERN_P over
    at least PATTERN_MIN_DOF directions); else None (no class, no known noise, too few directions
    to tell a pattern: :func:`_pattern_testable`, or a misfit)."""
    check = record.get("model_check") or {}
    if not (factor > 1.0 and sigma_px is not None and _pattern_testable(record)):
        return None
    test = fit_test(record, factor * sigma_px)
    if not (test["explains"] and check["p_value"] >= PATTERN_P):
        return None
    return {**test, "camera_class_factor": factor, "pattern_p": float(check["p_value"])}


def camera_misfit_reason(record: dict, p_value: float) -> str:
    """One line: why the gate refused a frame its camera model does not explain."""
    model = record.get("camera_model", "pinhole")
    return (f"the {model} camera does not explain the residuals (camera-model check against the known centre "
            f"noise, p {p_value:.2g}): principal point off centre (a crop) or a lens; give --calibration, "
            "or --camera-model pp_k1")


def gate(solve, refit, n_rows: int, sigma_px: float | None, class_factor: float = 1.0):
    """Run ``solve(keep)`` through the gate. ``keep`` (n_rows,) bool: the detection rows to use;
    ``solve`` returns (record, used, ids) with ids (n_rows,) the marker id of each row the
    fit used, else None; ``refit(keep, ids)`` the record of a quick fit of the rows ``keep`` as
    the markers ``ids`` (no identification; raises or returns a not-ok record when it fails),
    which picks the centre to leave out. Returns (record, used) of the first fit that
    passes (its ``fit_test`` and :func:`camera_misfit`; with ``left_out``, the ids of the centres it
    left out), else a not-ok record. A first fit the card's noise does not explain passes whole when
    its camera class (``class_factor``, eval.camera_classes) explains it (:func:`class_test`);
    otherwise one :func:`camera_misfit` flags is refused at once."""
    keep = np.ones(n_rows, dtype=bool)
    first = solve(keep)
    if not first[0].get("ok"):
        return first[:2]
    test = first[0]["fit_test"] = fit_test(first[0], sigma_px)
    lens_p = camera_misfit(first[0])
    if lens_p is None and test["explains"] is not False:
        return first[:2]
    if (by_class := class_test(first[0], sigma_px, class_factor)) is not None:
        first[0]["fit_test"] = _class_passed(by_class, test)
        return first[:2]
    if lens_p is not None:
        return {"ok": False, "category": MISFIT, "reason": camera_misfit_reason(first[0], lens_p)}, {}
    ids, left = first[2], []
    for _ in range(MAX_LEFT_OUT):
        k = _worst_row(refit, keep, ids, sigma_px)
        if k is None:
            break
        keep[k] = False
        left.append(ids[k])
        best = solve(keep)
        if not best[0].get("ok"):
            break
        ids = best[2]
        best[0]["fit_test"] = fit_test(best[0], sigma_px)
        if best[0]["fit_test"]["explains"] and camera_misfit(best[0]) is None:
            if _untestable(best[0], class_factor):
                return {"ok": False, "category": MISFIT, "reason": untestable_reason(best[0], len(left))}, {}
            best[0]["left_out"] = left
            best[0]["fit_test"]["before"] = {"ratio": test["ratio"], "p_value": test["p_value"]}
            return best[:2]
    return {"ok": False, "category": MISFIT, "reason": misfit_reason(test, sigma_px, len(left))}, {}


def _untestable(record: dict, class_factor: float) -> bool:
    """Whether a fit the gate reached by leaving centres out cannot be told from a crop: its camera
    class is noisier than the card's (``class_factor`` above LEFT_OUT_MIN_FACTOR: Bayer, JPEG or both)
    and its camera-model check has fewer than PATTERN_MIN_DOF directions left to test. Such a
    camera's honest residuals exceed the card's everywhere, so leaving out the centres that stand
    out most also absorbs an image geometry's pattern (a principal point off centre), and too few
    directions remain to see it. A Bayer camera alone was exempt while none of its frames cropped
    160 / 120 px passed this way; cropped by half that, on thin discs, they did, with confident wrong
    poses, and uncalibrated (measure's default) the larger crop too (bench/results/fit_gate/README.md,
    "The rule's classes", "The leave-out rule for a Bayer camera again")."""
    dof = (record.get("model_check") or {}).get("dof", 0)
    return LEFT_OUT_NEEDS_PATTERN and class_factor > LEFT_OUT_MIN_FACTOR and dof < PATTERN_MIN_DOF


def untestable_reason(record: dict, left_out: int) -> str:
    """One line: why the gate refused a fit of a noisy camera class with centres left out."""
    dof = (record.get("model_check") or {}).get("dof", 0)
    return (f"the residuals fit only with {left_out} centre(s) left out, and the {dof} image-geometry direction(s) "
            f"left cannot tell this camera's noise from a crop or a lens: give --calibration (the principal point)")


def _class_passed(by_class: dict, card: dict) -> dict:
    """The ``fit_test`` of a fit its camera class explains (:func:`class_test`'s ``by_class``) after
    the card's test ``card`` refused it: the class's, with the card's ratio and p-value under ``card``."""
    return {**by_class, "card": {k: card.get(k) for k in ("ratio", "p_value")}}


def run_misfits(records: dict, sigma_px: float | None, class_factor: float = 1.0) -> dict:
    """{frame id: fit_test} of the solved frames of a docking run solved with shared intrinsics
    (records with ``run_frames``) whose residuals the known noise cannot explain: a frame whose
    camera is not the run's (zoom, focus or image geometry changed) fits alone but not with the
    run's intrinsics. Each record gets its ``fit_test``. As in :func:`gate`, a frame the card's
    test refuses passes when the run's camera class explains it (:func:`class_test` at
    ``class_factor``: the largest of the run's frames' factors, eval.camera_classes.classes_factor);
    the pattern that test asks about is the run's camera-model check (one for the run's shared
    intrinsics, in every frame's record): a run whose residuals show the image's geometry gets the
    card's test alone."""
    out = {}
    for fid, rec in records.items():
        if not rec.get("ok"):
            continue
        test = rec["fit_test"] = fit_test(rec, sigma_px)
        if test["explains"] is not False:
            continue
        if (by_class := class_test(rec, sigma_px, class_factor)) is not None:
            rec["fit_test"] = _class_passed(by_class, test)
        else:
            out[fid] = test
    return out


def run_misfit_reason(test: dict, sigma_px: float) -> str:
    """One line: why the run gate left a frame out of its docking run."""
    return (f"docking run solve: residuals {test['ratio']:.1f}x the camera's centre noise ({sigma_px:.3g} px) with "
            "the run's shared intrinsics (the frame fits alone): not the run's camera (zoom, focus or image "
            "geometry changed) or a bad frame; left out of the run")


def _worst_row(refit, keep: np.ndarray, ids, sigma_px: float) -> int | None:
    """The used row whose removal leaves the smallest statistic in a quick refit, or None when
    no removal gives a fit."""
    best = None
    for k in np.flatnonzero(keep):
        if ids[k] is None:
            continue
        trial = keep.copy()
        trial[k] = False
        try:
            record = refit(trial, ids)
        except DockfactoryError:
            continue
        if record.get("ok"):
            stat = fit_test(record, sigma_px).get("statistic", math.inf)
            if best is None or stat < best[0]:
                best = (stat, int(k))
    return None if best is None else best[1]
