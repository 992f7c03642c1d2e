"""``dockfactory solve``: poses of B relative to A for a dataset's frames.

Input per frame: detections (class and refined centre from ``dockfactory detect``) or, for the
oracle, what a perfect detector would measure for the visible markers (the exact centroid of
each disc's image, label ``outline_centroid_px``) plus Gaussian noise. Output POSES.json:
  {"format": "dockfactory.poses/1", "dataset_version": ..., "source": "detections" | "oracle",
   "sigma_px": ..., "frames": {frame_id: {"ok": true, "d_from_b": 4x4, "pose": {...},
   "focal_px": ..., "covariance": 6x6, "rmse_px": {"A", "B"},
   "marker_ids": [...] (used in the fit), "rejected_ids": [...] (identified, left out as
   suspect), "n_markers": {"A", "B"}, "camera_class": ...} | {"ok": false, "reason": ...,
   "category": ..., "camera_class": ...}}}
Frames without a pose are kept with their reason: never dropped. Each frame's camera class is its
label's (eval.simulated_cameras.frame_camera_class); detected centres are judged by it as measure's.
"""
from __future__ import annotations

import math

from dataclasses import asdict, replace

import numpy as np

from dockfactory.core.distortion import undistort_pixels
from dockfactory.core.errors import DockfactoryError
from dockfactory.core.io import sha256_file, write_json_atomic
from dockfactory.core.names import MIN_SCORE
from dockfactory.generator.datasets.reader import Dataset
from dockfactory.generator.random_draws import rng_for
from dockfactory.eval.camera_classes import classes_factor, classes_section_shift
from dockfactory.eval.fit_gate import MISFIT, gate, run_misfit_reason, run_misfits
from dockfactory.eval.pixel_aspect import label_pixel_aspect
from dockfactory.eval.simulated_cameras import frame_camera_class
from dockfactory.solver import (
    AmbiguousIdentification,
    DockingOptions,
    SolverError,
    TooFewPoints,
    solve_docking,
)
from dockfactory.solver.camera_models import MODELS
from dockfactory.solver.options import DEFAULT_DOCKING, LensPrior
from dockfactory.solver.sequence import solve_sequence

POSES_FORMAT = "dockfactory.poses/1"
ORACLE_STREAM = 101  # rng stream of the oracle's centre noise (see generator.sampler.rng_for)


def failure_category(exc: SolverError) -> str:
    """Category of a solver failure in POSES.json and the report, by exception type."""
    if isinstance(exc, AmbiguousIdentification):
        return "ambiguous identification"
    if isinstance(exc, TooFewPoints):
        return "too few markers"
    return "solver error"


def oracle_detections(label: dict, sigma_px: float, rng: np.random.Generator):
    """(class_ids (N,), points (N, 2)): exact image centroids of the visible, legible markers
    + N(0, sigma^2). The centroid of a disc's image, not the projection of its centre, is what
    a detector measures; the solver corrects the difference (solver.eccentricity)."""
    vis = [m for m in label["markers"] if m.get("visibility") == 2 and m.get("legible", True)]
    cls = np.array([m["class_id"] for m in vis], dtype=int)
    uv = np.array([m.get("outline_centroid_px") or m["center_px"] for m in vis],
                  dtype=float).reshape(-1, 2)
    return cls, uv + rng.normal(0.0, sigma_px, size=uv.shape) if sigma_px > 0 else uv


def detection_arrays(dets: list[dict], min_score: float):
    """(class_ids (N,), centres (N, 2), boxes (N, 4) or None, refined (N,) bool or None) of the
    detections scoring at least ``min_score``: the centres :func:`solve_frame` takes; boxes /
    refined are None unless every detection has them."""
    keep = [d for d in dets if d.get("score", 1.0) >= min_score]
    cls = np.array([d["class_id"] for d in keep], dtype=int)
    uv = np.array([d["center_px"] for d in keep], dtype=float).reshape(-1, 2)
    boxes = (np.array([d["bbox_px"] for d in keep], dtype=float).reshape(-1, 4)
             if all("bbox_px" in d for d in keep) else None)
    refined = (np.array([bool(d["refined"]) for d in keep], dtype=bool)
               if all("refined" in d for d in keep) else None)
    return cls, uv, boxes, refined


def pose_record(res, n_detections: int) -> dict:
    """The poses-file record of a solved frame (a solver.DockingResult); with a section shift in
    its covariance, ``section_shift_variance`` (6,) over POSE_NAMES: what the shift added."""
    used = [i for i, ok in zip(res.marker_ids, res.inliers) if ok and i is not None]
    rejected = [i for i, ok in zip(res.marker_ids, res.inliers) if not ok and i is not None]
    rec = {"ok": True, "d_from_b": res.d_from_b.tolist(), "cam_from_a": res.cam_from_a.tolist(),
           "pose": res.pose(), "focal_px": res.focal_px,
           "covariance": res.covariance.tolist(), "sigma_px": float(res.sigma_px), "rmse_px": res.rmse_px,
           "marker_ids": used,
           "n_markers": {"A": sum(i.startswith("A") for i in used), "B": sum(i.startswith("B") for i in used)},
           "rejected_ids": rejected, "n_detections": n_detections}
    if res.camera_model != "pinhole":
        rec.update(camera_model=res.camera_model, intrinsics=dict(res.intrinsics),
                   intrinsics_std=dict(res.intrinsics_std))
    if res.model_check is not None:
        rec["model_check"] = model_check_record(res.model_check)
        rec["model_check"]["pose_variance"] = np.diag(res.model_error_covariance).tolist()
    if res.section_shift_covariance is not None:
        rec["section_shift_variance"] = np.diag(res.section_shift_covariance).tolist()
    return rec


def model_check_record(check) -> dict:
    """The poses-file record of a solve's model error (solver.model_error.ModelCheck): the misfit
    test (``explains``, ``p_value``, ``statistic``, ``dof``, the intrinsics ``tested``), the
    ``warning`` sentence ("" when the model explains the residuals; ``explains`` None when no
    intrinsic was testable: dof 0, nothing tested) and whether the intrinsics
    it does not estimate were ``marginalised`` into the covariance (:func:`pose_record` adds
    ``pose_variance``, (6,) over POSE_NAMES: what that added to the pose's variances);
    ``known_noise_p_value`` the same test against the known centre noise (None: none known; the
    goodness-of-fit gate reads it, eval.fit_gate); ``pp_offset_ncp`` the test's power against a
    principal point off by the lens prior's half-range (solver.model_error.pp_offset_ncp; None:
    not computable)."""
    explains = bool(check.explains) if check.dof > 0 else None    # nothing the data determine: not tested
    known = None if check.known_log_p is None else float(math.exp(check.known_log_p))
    return {"explains": explains, "p_value": float(check.p_value), "statistic": float(check.statistic),
            "dof": int(check.dof), "tested": list(check.tested), "warning": check.warning(),
            "marginalised": bool(np.any(check.added != 0.0)), "known_noise_p_value": known,
            "pp_offset_ncp": None if check.pp_offset_ncp is None else float(check.pp_offset_ncp)}


SELF_CALIBRATE = ("frame", "sequence")


def resolve_camera_model(camera_model: str | None, self_calibrate: str | None) -> str:
    """The model: as given, else "auto" when self-calibrating, else the paper's "pinhole"."""
    if self_calibrate is not None and self_calibrate not in SELF_CALIBRATE:
        raise DockfactoryError(f"--self-calibrate: expected frame or sequence, got {self_calibrate!r}")
    if camera_model is not None:
        if camera_model not in (*MODELS, "auto"):
            raise DockfactoryError(f"--camera-model: {camera_model!r} is not one of {', '.join((*MODELS, 'auto'))}")
        return camera_model
    return "auto" if self_calibrate else "pinhole"


def frame_centres(ds: Dataset, fid: str, detections: dict | None, oracle_sigma_px, min_score: float):
    """(class_ids, centres, boxes, refined) of a frame (:func:`detection_arrays`): its detections, or the
    oracle's noisy exact centroids (seeded per frame); None when the detections file has no entry for it."""
    if detections is not None:
        dets = detections["frames"].get(fid)
        return None if dets is None else detection_arrays(dets, min_score)
    label = ds.labels[fid]   # the oracle reads the exact centroids
    rng = rng_for(ds.config.dataset.seed, ORACLE_STREAM, label["spec"]["index"])
    cls, uv = oracle_detections(label, oracle_sigma_px, rng)
    return cls, uv, None, None


def true_camera_centres(label: dict, centres):
    """(principal point (2,), centres) of a frame seen through its label's true camera: the
    centres and boxes undistorted with the true K and coefficients, its pixel aspect taken out
    (square pixels at its fx: the reference of a calibrated camera, the same frames solved with the
    true intrinsics; the focal length is still estimated)."""
    cam = label["camera"]
    pp, dist = tuple(cam["principal_point"]), cam.get("distortion") or [0.0] * 5
    aspect = label_pixel_aspect(label)

    def ideal(uv):
        return undistort_pixels(uv, cam["focal_px"], pp, dist, aspect)

    cls, uv, boxes, refined = centres
    if boxes is not None:
        corners = ideal(boxes.reshape(-1, 2)).reshape(-1, 4)
        boxes = np.concatenate([np.minimum(corners[:, :2], corners[:, 2:]),
                                np.maximum(corners[:, :2], corners[:, 2:])], axis=1)
    return pp, (cls, ideal(uv), boxes, refined)


def solve_dataset(ds: Dataset, splits=("test", "repeat"), detections: dict | None = None,
                  oracle_sigma_px: float | None = None, min_score: float = MIN_SCORE, sigma_px: float | None = None,
                  camera_model: str = "pinhole", self_calibrate: str | None = None, sigma_floor_px: float | None = None,
                  true_camera: bool = False, lens: LensPrior | None = None, section_shift_px=None) -> dict:
    """Solve the pose of every frame of a dataset's splits, from detections or from the labels.

    Parameters
    ----------
    ds, splits : Dataset, tuple of str
        The opened dataset (its layout, image size and labels); the splits solved.
    detections, oracle_sigma_px : dict or None, float or None
        Exactly one: a detections document (``detect``), or the labels' centres with Gaussian
        noise of this sigma (px; 0: exact).
    min_score, sigma_px, sigma_floor_px : float, float or None, float or None
        The detection score kept; the centre noise the covariance assumes (None: estimated), and
        no estimate below ``sigma_floor_px`` (default: the detections' noise card figure).
    camera_model, self_calibrate : str, str or None
        The solver's model (pinhole, k1, k1k2, pp_k1, pp_k1_p, auto); ``sequence`` solves each
        docking run with shared intrinsics, ``frame`` (or None) each frame alone.
    true_camera, lens, section_shift_px : bool, LensPrior or None, (float, float) or None
        Each frame with its label's principal point and distortion (a calibrated camera's
        reference); the lens prior (:func:`lens_prior_for`, None: its choice); every frame's section
        shift (eval.section_shift; None: the card's, raised to its camera class's: :func:`class_options`).

    Returns
    -------
    dict
        The poses document: its settings and ``frames`` (frame id -> solved record or ``{"ok": False,
        "reason", "category"}``, each with its ``camera_class``), mm, degrees, OpenCV pixels.

    Raises
    ------
    ValueError
        Both or neither of detections and oracle, an unknown mode, true_camera with another model.
    DockfactoryError
        A joint solve (``sequence``) of a dataset without docking runs (one line).
    """
    _check_modes(ds, detections, oracle_sigma_px, self_calibrate, true_camera, camera_model)
    w, h = ds.config.image.width, ds.config.image.height
    pp = ((w - 1) / 2.0, (h - 1) / 2.0)   # uncalibrated: only the image size is known
    sigma = sigma_px if sigma_px is not None or detections is not None else (oracle_sigma_px or None)
    options = _dataset_options(ds, detections, sigma_floor_px, lens, true_camera, section_shift_px)
    frames = _solve_frames(ds, splits, detections, oracle_sigma_px, min_score, pp, sigma, camera_model, self_calibrate,
                           true_camera, options, None if detections is None else section_shift_px is None)
    return {"format": POSES_FORMAT, "dataset_version": ds.version_id,
            "source": "detections" if detections is not None else "oracle", "oracle_sigma_px": oracle_sigma_px,
            "min_score": min_score, "principal_point": list(pp), "camera_model": camera_model,
            "self_calibrate": self_calibrate, "sigma_floor_px": options.refine.sigma_floor_px,
            "section_shift_px": options.section_shift_px and list(options.section_shift_px),
            "true_camera": bool(true_camera), "lens_prior": asdict(options.lens), "splits": list(splits), "frames": frames}


def _solve_frames(ds: Dataset, splits, detections, oracle_sigma_px, min_score, pp, sigma, camera_model,
                  self_calibrate, true_camera: bool, options, by_class: bool | None = None) -> dict:
    """Frame id -> record of every frame of ``splits`` (:func:`solve_dataset`'s ``frames``): each
    frame alone, then, with ``self_calibrate`` "sequence", each docking run with shared intrinsics;
    every record names the frame's ``camera_class``, and :func:`class_options` of ``by_class`` says
    what the class changes in its solve."""
    markers = ds.markers()
    per_frame = "pinhole" if self_calibrate == "sequence" else camera_model
    classes = {fid: frame_camera_class(ds.labels[fid], ds.config) for fid in ds.frames(splits)}
    frames, used = {}, {}
    for fid in ds.frames(splits):
        centres = frame_centres(ds, fid, detections, oracle_sigma_px, min_score)
        if centres is None:
            frames[fid] = {"ok": False, "reason": "no detections for this frame", "category": "no detections"}
            continue
        frame_pp, centres = true_camera_centres(ds.labels[fid], centres) if true_camera else (pp, centres)
        frame_options, factor = class_options(options, [classes[fid]], by_class)
        frames[fid], used[fid] = solve_frame(markers, frame_pp, centres, sigma, per_frame, frame_options, factor)
    if self_calibrate == "sequence":
        for group in docking_runs(ds, [f for f in frames if frames[f]["ok"]]):
            run_pp = tuple(ds.labels[group[0]]["camera"]["principal_point"]) if true_camera else pp
            run_options, run_factor = class_options(options, [classes[f] for f in group], by_class)
            frames.update(solve_run(markers, run_pp, group, frames, used, sigma, camera_model, run_options,
                                    run_factor))
    return name_camera_classes(frames, classes)


def name_camera_classes(records: dict, classes: dict) -> dict:
    """``records`` (id -> record) with each record naming its frame's ``camera_class`` (``classes``:
    id -> class, eval.camera_classes), in place (a run's joint records replace the frames' own,
    which named it); returns ``records``."""
    for key, rec in records.items():
        rec["camera_class"] = classes[key]
    return records


def class_options(options: DockingOptions, classes, by_class: bool | None) -> tuple[DockingOptions, float]:
    """(options, gate class factor) of frames of the camera classes ``classes`` (one frame's, or a
    run's) solved together, as measure solves an image of its class. ``by_class`` None (the oracle:
    label centroids with the stated noise, which no camera class changes): ``options`` and 1.
    Else the factor is the class's (eval.camera_classes.classes_factor; of several: the largest,
    which a run's gate takes) and, when ``by_class`` is True, the section shift per axis the largest of
    ``options``' (the card's) and the classes' (eval.camera_classes.classes_section_shift); False:
    the shift of ``options`` as given; the noise prior the class's (:func:`with_class_prior`)."""
    if by_class is None:
        return options, 1.0
    factor = classes_factor(classes)
    shift = classes_section_shift(classes, options.section_shift_px) if by_class else options.section_shift_px
    out = options if shift == options.section_shift_px else replace(options, section_shift_px=shift)
    return with_class_prior(out, factor), factor


def with_class_prior(options: DockingOptions, factor: float) -> DockingOptions:
    """``options`` whose noise prior (the card's robust core, ``refine.noise_prior_px``) is the
    camera class's: times the class ``factor`` (eval.camera_classes); unchanged without one."""
    prior = options.refine.noise_prior_px
    if prior is None or factor == 1.0:
        return options
    return replace(options, refine=replace(options.refine, noise_prior_px=prior * factor))


def _check_modes(ds: Dataset, detections, oracle_sigma_px, self_calibrate, true_camera: bool, camera_model) -> None:
    """ValueError for a combination :func:`solve_dataset` cannot solve; DockfactoryError for a
    joint solve of a dataset without docking runs."""
    if (detections is None) == (oracle_sigma_px is None):
        raise ValueError("give detections or an oracle noise level, not both")
    if self_calibrate is not None and self_calibrate not in SELF_CALIBRATE:
        raise ValueError(f"self_calibrate must be one of {SELF_CALIBRATE}, got {self_calibrate!r}")
    if true_camera and (self_calibrate == "frame" or camera_model != "pinhole"):
        raise ValueError("true_camera solves with the labels' intrinsics: the pinhole model, per frame or per run")
    if self_calibrate == "sequence":
        require_docking_runs(ds)


def _dataset_options(ds: Dataset, detections, sigma_floor_px, lens, true_camera: bool, section_shift_px):
    """:func:`docking_options` of :func:`solve_dataset`: the floor and the section shift the
    detections carry (from the weights' noise card) unless given, the lens prior of the
    dataset's config unless given (known with ``true_camera``)."""
    if sigma_floor_px is None and detections is not None:
        sigma_floor_px = detections.get("centre_noise_px")   # the weights' noise card (detect)
    if section_shift_px is None and detections is not None:
        section_shift_px = detections.get("section_shift_px")
    lens = lens or (KNOWN_LENS if true_camera else lens_prior_for(ds.config))
    core = None if detections is None else detections.get("centre_noise_core_px")
    return docking_options(sigma_floor_px, lens, section_shift_px, core)


UNCALIBRATED_LENS = LensPrior(marginalise=True)   # the app's lens: nobody calibrated it
KNOWN_LENS = LensPrior(marginalise=False)         # calibrated, or an ideal camera


def lens_is_known(config) -> bool:
    """Whether a dataset ``config`` (core.config) pins every camera unit to an ideal lens
    (principal point at the image centre, no distortion): the lens is then known, as a
    calibrated one is."""
    cu = config.camera_units
    ranges = (cu.principal_offset_x_px, cu.principal_offset_y_px, cu.k1, cu.k2, cu.k3, cu.p1, cu.p2)
    return all(float(lo) == 0.0 and float(hi) == 0.0 for lo, hi in ranges)


def lens_prior_for(config) -> LensPrior:
    """The lens prior a solve of a dataset with this ``config`` uses: :data:`KNOWN_LENS` when
    :func:`lens_is_known`, else the ranges the config's camera units are drawn from
    (:func:`config_lens_prior`): the judge knows the lens population it simulated, as a user who
    knows the lens class of the camera states it to ``measure --lens-prior``."""
    return KNOWN_LENS if lens_is_known(config) else config_lens_prior(config)


def config_lens_prior(config) -> LensPrior:
    """The lens prior of the camera units a dataset ``config`` draws (marginalised): each half-range
    h matches the second moment about the assumed value (0; the image centre) of the config's
    uniform range [lo, hi], h = sqrt(lo^2 + lo hi + hi^2) (a uniform over [-h, h] has variance h^2 / 3,
    as U[lo, hi] has E[x^2] = (lo^2 + lo hi + hi^2) / 3): the prior of a user who knows the lens
    class the factory drew from. The principal point's as a fraction of the image width (the larger
    axis); p the larger of p1's and p2's. k3 is not in :class:`LensPrior` (not marginalised)."""
    cu, width = config.camera_units, float(config.image.width)

    def half(rng) -> float:
        lo, hi = (float(v) for v in rng)
        return math.sqrt(max(lo * lo + lo * hi + hi * hi, 0.0))

    return LensPrior(pp_fraction=max(half(cu.principal_offset_x_px), half(cu.principal_offset_y_px)) / width,
                     k1=half(cu.k1), k2=half(cu.k2), p=max(half(cu.p1), half(cu.p2)), marginalise=True)


def docking_options(sigma_floor_px: float | None, lens: LensPrior | None = None,
                    section_shift_px=None, prior_px: float | None = None) -> DockingOptions:
    """The solver's options with the detector's measured centre noise as the covariance's floor,
    ``lens`` the plausible range of the intrinsics its camera model does not estimate (None: an
    uncalibrated camera's, :data:`UNCALIBRATED_LENS`, marginalised into the covariance) and
    ``section_shift_px`` (x, y) the measured common offset of a section's centres (None: none;
    eval.section_shift)."""
    refine = replace(DEFAULT_DOCKING.refine, sigma_floor_px=None if sigma_floor_px is None else float(sigma_floor_px),
                     noise_prior_px=None if prior_px is None else float(prior_px))
    return replace(DEFAULT_DOCKING, refine=refine, lens=UNCALIBRATED_LENS if lens is None else lens,
                   section_shift_px=None if section_shift_px is None else tuple(section_shift_px))


def solve_frame(markers, pp, centres, sigma, camera_model: str,
                options: DockingOptions = DEFAULT_DOCKING, class_factor: float = 1.0) -> tuple[dict, dict]:
    """(poses record, marker id -> centre (u, v) px the fit used) of one frame whose ``centres`` are
    (class_ids, centres, boxes, refined) as :func:`detection_arrays` gives them, through the
    goodness-of-fit gate (eval.fit_gate) against the known centre noise: the noise card's
    (``options.refine.sigma_floor_px``), else ``sigma`` when given; ``class_factor`` the frame's
    camera class's (eval.camera_classes.CAMERA_CLASS_FACTORS: 1 for the three-chip camera the card was
    measured on)."""
    known = options.refine.sigma_floor_px if options.refine.sigma_floor_px is not None else sigma

    def refit(keep, ids):
        rows = [k for k in np.flatnonzero(keep) if ids[k] is not None]
        res = solve_docking(markers, pp, correspondences=([ids[k] for k in rows], centres[1][rows]), sigma_px=sigma,
                            camera_model=camera_model, options=options)
        return pose_record(res, len(rows))
    return gate(lambda keep: _solve_rows(markers, pp, centres, keep, sigma, camera_model, options), refit,
                len(centres[0]), known, class_factor)


def _solve_rows(markers, pp, centres, keep: np.ndarray, sigma, camera_model: str, options: DockingOptions):
    """:func:`solve_frame`'s solve of the detection rows ``keep`` (bool); (record, used, ids: per
    row of ``centres`` the marker id the fit used it as, else None)."""
    cls, uv, boxes, refined = (None if a is None else a[keep] for a in centres)
    ids = [None] * len(keep)
    try:
        res = solve_docking(markers, pp, detections=(cls, uv), sigma_px=sigma, boxes=boxes, refined=refined,
                            camera_model=camera_model, options=options)
    except SolverError as exc:
        return {"ok": False, "reason": str(exc), "category": failure_category(exc)}, {}, ids
    rows = np.flatnonzero(keep)
    kept = [(k, mid) for k, (mid, ok) in enumerate(zip(res.marker_ids, res.inliers)) if ok and mid]
    for k, mid in kept:
        ids[rows[k]] = mid
    used = {mid: (float(uv[k, 0]), float(uv[k, 1])) for k, mid in kept}
    return pose_record(res, int(len(centres[0]))), used, ids


def has_docking_runs(ds: Dataset) -> bool:
    """Whether the dataset's frames share cameras: with ``[runs]`` each camera unit keeps one fixed
    camera (pose, zoom, lens) for all its frames; without, every frame draws its own camera."""
    return ds.config.runs.frames_per_run > 0


def require_docking_runs(ds: Dataset) -> None:
    """DockfactoryError unless the dataset has docking runs: solving frames that do not share a
    camera with shared intrinsics gives one focal length for many and a confident wrong pose."""
    if not has_docking_runs(ds):
        raise DockfactoryError(f"--self-calibrate sequence: dataset {ds.root} has no docking runs "
                               "([runs] frames_per_run = 0): its frames do not share a camera; "
                               "use --self-calibrate frame")


def docking_runs(ds: Dataset, frame_ids) -> list[list[str]]:
    """The frames of a dataset with docking runs grouped by run (camera unit and run of their
    labels); a frame outside any run (a repeatability capture, run -1) is grouped with its unit's
    other such frames: the unit's camera is fixed. ``require_docking_runs`` first."""
    groups: dict = {}
    for fid in frame_ids:
        spec = ds.labels[fid]["spec"]
        groups.setdefault((spec.get("unit", 0), spec.get("run", -1)), []).append(fid)
    return [groups[k] for k in sorted(groups)]


def solve_run(markers, pp, group: list[str], frames: dict, used: dict, sigma, camera_model: str,
              options: DockingOptions = DEFAULT_DOCKING, class_factor: float = 1.0) -> dict:
    """The records of one docking run solved with shared intrinsics (solver.solve_sequence); when
    the joint solve fails, every frame of the run says why. ``used``: per frame id the centres
    :func:`solve_frame` returned.
    Through the run gate (eval.fit_gate.run_misfits, against the noise card's centre noise, else
    ``sigma``, and the run's camera class's ``class_factor``: eval.camera_classes.classes_factor of
    its frames'): the worst frame the run's intrinsics cannot explain is left out (not ok, the reason
    in one line) and the rest solved again, at most a quarter of the run (at least one frame)
    while three remain; frames still unexplained after that are not ok either. The records name no
    ``camera_class``: the caller's (:func:`name_camera_classes`)."""
    known = options.refine.sigma_floor_px if options.refine.sigma_floor_px is not None else sigma
    left: dict = {}
    while True:
        members = [f for f in group if f not in left]
        out = _joint_records(markers, pp, members, frames, used, sigma, camera_model, options)
        bad = run_misfits(out, known, class_factor)
        if not bad or len(members) <= 2 or len(left) >= max(1, len(group) // 4):
            left.update({f: _left_out(test, known) for f, test in bad.items()})
            return {f: left.get(f) or out[f] for f in group}
        worst = max(bad, key=lambda f: bad[f]["ratio"])
        left[worst] = _left_out(bad[worst], known)


def _left_out(test: dict, known: float) -> dict:
    """The record of a frame the run gate refused."""
    return {"ok": False, "category": MISFIT, "reason": run_misfit_reason(test, known), "self_calibrated": "sequence",
            "fit_test": test}


def _joint_records(markers, pp, group, frames, used, sigma, camera_model, options) -> dict:
    """:func:`solve_run`'s joint solve of the frames ``group`` (no gate)."""
    try:
        run = solve_sequence(markers, pp, [used[f] for f in group], camera_model=camera_model, sigma_px=sigma,
                             options=options)
    except SolverError as exc:
        return {f: {"ok": False, "reason": f"docking run solve: {exc}", "category": failure_category(exc)}
                for f in group}
    out = {}
    for fid, res in zip(group, run.frames):
        out[fid] = {**pose_record(res, frames[fid]["n_detections"]), "camera_model": run.camera_model,
                    "intrinsics": dict(run.intrinsics), "intrinsics_std": dict(run.intrinsics_std),
                    "self_calibrated": "sequence", "run_frames": len(group), "run_bias_px": run.bias_px}
    return out


def write_poses(path, poses: dict, detections_path=None) -> None:
    """Write a poses document (:func:`solve_dataset`) atomically.

    Parameters
    ----------
    path : str or Path
        The poses JSON.
    poses : dict
        The document.
    detections_path : str, Path or None
        The detections it was solved from, bound to it by their sha256.

    Returns
    -------
    None

    Raises
    ------
    OSError
        The detections cannot be read or the file cannot be written (the one before stays).
    """
    if detections_path is not None:
        poses = {**poses, "detections_sha256": sha256_file(detections_path)}
    write_json_atomic(path, poses, indent=None)
