"""``solve_docking``: relative pose of B in A (``d_from_b``) from one uncalibrated image.

Detections are identified (correspondences taken as given, or cleaned by LO-RANSAC); both sections are fitted
jointly with one unknown focal; for detections, suspects are left out, the eccentricity corrected and each centre's
noise modelled by its disc's image. Options: :class:`solver.options.DockingOptions`.

Why and how: docs/solver.md, "The docking pipeline".
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from dockfactory.core.geometry import pose_components
from dockfactory.core.names import POSE_NAMES, SECTIONS
from dockfactory.solver.camera_models import (
    EXTRA_NAMES,
    MODELS,
    PINHOLE,
    check_model_name,
    project_normalized,
)
from dockfactory.solver.checks import (
    MIN_POINTS,
    as_principal_point,
    check_sigma,
    row_array,
)
from dockfactory.solver.disc_noise import robust_refit, with_disc_noise, with_model_error
from dockfactory.solver.eccentricity import eccentricity_corrected, section_keep
from dockfactory.solver.errors import InvalidSolverInput, NoValidCamera
from dockfactory.solver.identify import identify_markers, parse_detections
from dockfactory.solver.joint import JointFit, JointFitter, SectionPoints
from dockfactory.solver.layout_points import (
    LayoutArrays,
    checked_correspondences,
    section_arrays,
)
from dockfactory.solver.model_choice import ModelChoice
from dockfactory.solver.model_error import ModelCheck
from dockfactory.solver.options import DEFAULT_DOCKING, DockingOptions
from dockfactory.solver.ransac import ransac_docking
from dockfactory.solver.refine import d_from_b_jacobian
from dockfactory.solver.suspects import leave_out_suspects, occlusion_variances

__all__ = ["DockingResult", "solve_docking"]


@dataclass(frozen=True)
class DockingResult:
    """Result of :func:`solve_docking`.

    - ``d_from_b`` (4, 4): pose of B in D (= A's frame); ``x_mm``, ``y_mm``, ``z_mm``,
      ``alpha_deg``, ``beta_deg``, ``gamma_deg`` its components (R = Rz(a) Ry(b) Rx(g));
    - ``focal_px``: the shared focal length (px);
    - ``covariance`` (6, 6) over (X, Y, Z mm, alpha, beta, gamma deg) = ``POSE_NAMES``;
      ``std`` the matching dict of standard deviations;
    - ``covariance_params`` (13, 13) over (w_A, t_A, w_B, t_B, f) (see :mod:`solver.refine`);
    - ``rmse_px``: {"A": ..., "B": ...} reprojection RMS per section (px, per point);
    - ``marker_ids``: per input row, the marker id ("A3") or None (not identified, or rejected
      by RANSAC);
    - ``inliers`` (N,) bool per input row: used in the final fit (an identified detection left
      out as suspect keeps its id and is not an inlier);
    - ``swapped`` (N,) bool: detections whose class label disagreed with the section of the
      marker they were identified as (all False for correspondences);
    - ``cam_from_a``, ``cam_from_b`` (4, 4); ``sigma_px``: noise std used for the covariances;
    - ``camera_model``: the camera model fitted (chosen, for "auto"); ``intrinsics``: {"cx",
      "cy" (px), "k1", "k2", "p1", "p2"} of that camera (fixed ones at the value assumed: the
      given principal point, no distortion); ``intrinsics_std``: {"focal_px", "cx", ..., "p2"}
      standard deviations (0.0 for the intrinsics the model keeps fixed);
      ``covariance_params`` is then (13 + e, 13 + e) over (w_A, t_A, w_B, t_B, f, *free);
      ``model_choice``: the automatic choice's tests (:class:`solver.model_choice.ModelChoice`)
      or None;
    - ``model_check``: the model error of the camera model (:class:`solver.model_error.
      ModelCheck`): whether it explains the residuals (``model_warning`` says so in a sentence
      when not) and, with ``DockingOptions.lens.marginalise``, the pose error of the intrinsics
      it does not estimate, already in ``covariance`` and ``std``;
    - ``section_shift_covariance`` (6, 6) over POSE_NAMES or None: what a common offset of each
      section's centres (``DockingOptions.section_shift_px``, :mod:`solver.section_shift`) added
      to ``covariance``.
    """

    d_from_b: np.ndarray
    x_mm: float
    y_mm: float
    z_mm: float
    alpha_deg: float
    beta_deg: float
    gamma_deg: float
    focal_px: float
    covariance: np.ndarray
    std: dict
    covariance_params: np.ndarray
    rmse_px: dict
    marker_ids: tuple
    inliers: np.ndarray
    swapped: np.ndarray
    cam_from_a: np.ndarray
    cam_from_b: np.ndarray
    sigma_px: float
    iterations: int = field(default=0)
    camera_model: str = PINHOLE.name
    intrinsics: dict = field(default_factory=dict)
    intrinsics_std: dict = field(default_factory=dict)
    model_choice: ModelChoice | None = None
    model_check: ModelCheck | None = None
    section_shift_covariance: np.ndarray | None = None

    @property
    def model_error_covariance(self) -> np.ndarray:
        """(6, 6) over ``POSE_NAMES``: the part of ``covariance`` that marginalising the
        intrinsics the camera model does not estimate added (zeros when nothing was added)."""
        if self.model_check is None:
            return np.zeros((6, 6))
        prop = d_from_b_jacobian(self.cam_from_a[:3, :3], self.cam_from_a[:3, 3], self.cam_from_b[:3, :3],
                                 self.cam_from_b[:3, 3])
        return prop @ self.model_check.added[:12, :12] @ prop.T

    @property
    def model_warning(self) -> str:
        """"" when the camera model explains the residuals (or was not checked), else why not."""
        return "" if self.model_check is None else self.model_check.warning()

    def pose(self) -> dict:
        """{"x_mm": ..., ..., "gamma_deg": ...}."""
        return {k: getattr(self, k) for k in POSE_NAMES}

    @classmethod
    def from_fit(cls, fit: JointFit, marker_ids, inliers, swapped) -> DockingResult:
        """The result of the final joint fit, with the per-row identities and masks."""
        comp = pose_components(fit.d_from_b)
        std = dict(zip(POSE_NAMES, np.sqrt(np.diag(fit.covariance)).tolist()))
        intr, intr_std = _intrinsics_report(fit)
        return cls(camera_model=fit.model, intrinsics=intr, intrinsics_std=intr_std,
                   model_choice=fit.choice, model_check=fit.model_check, d_from_b=fit.d_from_b, focal_px=fit.focal_px,
                   covariance=fit.covariance, std=std, covariance_params=fit.covariance_params,
                   rmse_px={"A": fit.rmse_a, "B": fit.rmse_b}, marker_ids=marker_ids,
                   inliers=np.asarray(inliers, dtype=bool),
                   swapped=np.asarray(swapped, dtype=bool), cam_from_a=fit.cam_from_a,
                   cam_from_b=fit.cam_from_b, sigma_px=fit.sigma_px,
                   iterations=fit.iterations, section_shift_covariance=fit.shift_covariance, **comp)


def _intrinsics_report(fit: JointFit):
    """({name: value}, {name: std}) of a fit's intrinsics (empty when it has none); fixed
    intrinsics have std 0.0."""
    if fit.intrinsics is None:
        return {}, {}
    var = np.diag(fit.covariance_params)[12:]
    std = {"focal_px": float(np.sqrt(var[0]))}
    std.update({name: 0.0 for name in EXTRA_NAMES})
    for k, name in enumerate(MODELS[fit.model].free, start=1):
        std[name] = float(np.sqrt(var[k]))
    return fit.intrinsics.values(), std


def solve_docking(markers, principal_point, *, detections=None, correspondences=None, boxes=None, refined=None,
                  sigma_px: float | None = None, robust: bool = False,
                  rng: np.random.Generator | None = None, camera_model: str = PINHOLE.name,
                  options: DockingOptions = DEFAULT_DOCKING) -> DockingResult:
    """Pose of B relative to A from one image of both sections (shared unknown focal length).

    Parameters
    ----------
    markers, principal_point : layout, (2,) px
        :class:`core.layout.Marker` of both sections, ``center_mm`` in each marker's own section frame.
    detections, boxes, refined : (class_ids (N,), points_2d (N, 2) px), (N, 4) px, (N,) bool
        Exactly one of ``detections`` / ``correspondences``. Classes 0 / "A" red, 1 / "B" blue; ids from
        :func:`solver.identify.identify_markers` (missing markers, strays, swapped classes tolerated); suspect centres
        left out while each section keeps ``MIN_POINTS`` (:mod:`solver.suspects`): ``boxes`` the outlines [x0, y0, x1,
        y1]; ``refined`` False where the detector could not refine the centre.
        With ``options.eccentricity`` centres are corrected by their perspective offset and refitted.
    correspondences, robust, rng : dict marker id -> (u, v) or (marker_ids (N,), points_2d (N, 2)); bool; Generator
        ``robust=True`` (with ``rng``, a numpy Generator) rejects outliers by LO-RANSAC.
    sigma_px : float or None
        Pixel noise std for the covariances (None: from the residuals).
    camera_model, options : str, DockingOptions
        "pinhole" (the paper's: f only, no distortion), a model of :data:`solver.camera_models.MODELS` (refined from the
        pinhole fit) or "auto" (the model the frame determines, :mod:`solver.model_choice`); identification and RANSAC
        use the pinhole.

    Returns
    -------
    DockingResult

    Raises
    ------
    SolverError : InvalidSolverInput (bad input, not one of detections / correspondences, boxes etc. without detections,
        robust without rng), TooFewPoints, DegenerateGeometry, FocalNotObservable, IdentificationFailed,
        AmbiguousIdentification (two assignments fit equally), NoValidCamera, NoConsensus.
    """
    if (detections is None) == (correspondences is None):
        raise InvalidSolverInput("give exactly one of detections= or correspondences=")
    layout = LayoutArrays.of(markers)
    pp = as_principal_point(principal_point)
    fitter = JointFitter(pp, check_sigma(sigma_px), options.refine,
                         check_model_name(camera_model), options.model_choice, options.lens,
                         options.section_shift_px)
    if detections is not None:
        return _solve_detections(markers, layout, detections, (boxes, refined), fitter, options)
    if boxes is not None or refined is not None:
        raise InvalidSolverInput("boxes= and refined= describe detections: give them with detections=")
    if robust and not isinstance(rng, np.random.Generator):
        raise InvalidSolverInput("robust=True needs rng, a numpy.random.Generator (explicit seed)")
    return _solve_correspondences(layout, correspondences, rng if robust else None, fitter, options)


def _solve_detections(markers, layout: LayoutArrays, detections, per_detection,
                      fitter: JointFitter, options: DockingOptions) -> DockingResult:
    """Identify, fit, leave out suspects, correct the eccentricity, refit; the robust refit and
    the covariance of the disc noise model (``options.disc_noise``, ``options.robust``).
    ``per_detection``: (boxes, refined) as :func:`solve_docking` takes them."""
    n_det = len(parse_detections(detections)[0])
    boxes = row_array(per_detection[0], n_det, (4,), "boxes", float)
    refined = row_array(per_detection[1], n_det, (), "refined", bool)
    ident = identify_markers(markers, fitter.principal_point, detections, options.identify,
                             options.refine, trusted=refined)
    ids = list(ident.marker_ids)
    used = np.array([i is not None for i in ids])
    rows, p3, p2 = section_arrays(layout, ids, used, ident.points_2d)
    # started from identification's joint fit (verified on these detections), not from the
    # per-section closed forms: measured on 1630 seeded frames (bench/solve_speed.py), the
    # closed-form start ended in a mirrored basin on 5 of them (pose off by 400-650 mm and
    # 150-180 deg, no error raised) and refused 2 more (focal not observable); the poses of
    # all the others moved by at most 6e-8 mm and 1.3e-8 deg (the LM's stopping tolerance)
    fit = fitter.fit(p3["A"], p2["A"], p3["B"], p2["B"], start=ident.start)
    points = SectionPoints(rows, p3, p2, tuple(layout.by_id.get(i) for i in ids))
    fit, inliers = leave_out_suspects(fit, points, fitter, used.copy(), boxes, refined,
                                      options.min_extent)
    keep, points_2d = section_keep(points, inliers), points.points_2d
    if options.eccentricity:
        points_2d = eccentricity_corrected(fit, points, fitter)
        fit = fitter.refit(fit, points, keep, points_2d=points_2d)
    if options.disc_noise and fitter.sigma_px is None:
        pp, coeffs = (fitter.principal_point, None) if fit.intrinsics is None else \
            (fit.intrinsics.principal_point, fit.intrinsics.coeffs)
        extra = occlusion_variances(fit, points, pp, boxes, options.occlusion_bias,
                                    options.occlusion_margin_px, coeffs)
        fit = (robust_refit if options.robust else with_disc_noise)(fit, points, fitter, keep, points_2d,
                                                                     extra)
    else:
        fit = with_model_error(fit, *_kept(points, keep, points_2d), fitter)
    marker_ids = tuple(ids[k] if used[k] else None for k in range(len(ids)))
    return DockingResult.from_fit(fit, marker_ids, inliers, ident.swapped)


def _solve_correspondences(layout: LayoutArrays, correspondences, rng, fitter: JointFitter,
                           options: DockingOptions) -> DockingResult:
    """Fit the given correspondences; with ``rng`` (robust) after LO-RANSAC, and with a final
    inlier check against the joint model."""
    ids, uv = checked_correspondences(layout, correspondences)
    inliers = np.ones(len(ids), dtype=bool)
    rows, p3, p2 = section_arrays(layout, ids, inliers, uv)
    start = None
    if rng is not None:
        pp = fitter.principal_point
        consensus = ransac_docking(p3["A"], p2["A"], p3["B"], p2["B"], pp, rng, options.ransac,
                                   options.refine)
        for s, keep in (("A", consensus.inliers_a), ("B", consensus.inliers_b)):
            for k, ok in zip(rows[s], keep):
                inliers[k] = bool(ok)
            p3[s], p2[s] = p3[s][keep], p2[s][keep]
        start = consensus.start
    # a closed-form start can end in a mirrored basin without an error (results/README.md): a
    # joint RMS above the plausible one makes fit_joint try every section's candidates and keep
    # the lowest cost
    plausible = (options.refine.accept_rmse_sigmas * fitter.sigma_px if fitter.sigma_px
                 else options.ransac.threshold_px)
    fit = fitter.fit(p3["A"], p2["A"], p3["B"], p2["B"], start=start,
                     accept_rmse=plausible if start is None else None)
    # still above the inlier threshold: most points would be outliers of this camera, so the
    # pose is not trusted (a lens the pinhole cannot model stays below it: a few px at k1 -0.2)
    limit = max(plausible, options.ransac.threshold_px)
    if start is None and max(fit.rmse_a, fit.rmse_b) > limit:   # never a silently wrong pose
        raise NoValidCamera(f"no camera explains the correspondences: reprojection RMS A {fit.rmse_a:.2f} px, "
                            f"B {fit.rmse_b:.2f} px (inlier threshold {limit:.2f} px)")
    if rng is not None:
        fit, inliers = _recheck_inliers(fit, layout, ids, uv, fitter,
                                        options.ransac.threshold_px, inliers)
    marker_ids = tuple(ids[k] if inliers[k] else None for k in range(len(ids)))
    fit = with_model_error(fit, *section_arrays(layout, ids, inliers, uv)[1:], fitter)
    return DockingResult.from_fit(fit, marker_ids, inliers, np.zeros(len(ids), dtype=bool))


def _kept(points: SectionPoints, keep: dict, points_2d: dict) -> tuple:
    """({section: points_3d}, {section: points_2d}) of the points ``keep`` (n_s,) bool."""
    return ({s: points.points_3d[s][keep[s]] for s in SECTIONS},
            {s: points_2d[s][keep[s]] for s in SECTIONS})


def _recheck_inliers(fit: JointFit, layout: LayoutArrays, ids, uv, fitter: JointFitter, thr,
                     inliers):
    """Re-classify every correspondence against the joint model (within ``thr`` px); refit
    once if the inlier set changed and each section keeps MIN_POINTS. (fit, inliers (N,))."""
    cams = fit.cams
    new = np.zeros(len(ids), dtype=bool)
    for k, mid in enumerate(ids):
        if mid is None:
            continue
        cam = cams[layout.sections[layout.index[mid]]]
        pc = cam[:3, :3] @ layout.points[layout.index[mid]] + cam[:3, 3]
        if pc[2] <= 0:
            continue
        if fit.intrinsics is None or fit.model == PINHOLE.name:
            e = fit.focal_px * pc[:2] / pc[2] + fitter.principal_point - uv[k]
        else:
            e = project_normalized(pc[None, :2] / pc[2], fit.intrinsics)[0] - uv[k]
        new[k] = float(e @ e) <= thr * thr
    rows = {s: [k for k in range(len(ids)) if new[k]
                and layout.sections[layout.index[ids[k]]] == s] for s in SECTIONS}
    if all(len(rows[s]) >= MIN_POINTS for s in rows) and not np.array_equal(new, inliers):
        p3 = {s: layout.points[[layout.index[ids[k]] for k in rows[s]]] for s in rows}
        p2 = {s: uv[rows[s]] for s in rows}
        return fitter.fit(p3["A"], p2["A"], p3["B"], p2["B"], start=fit.start), new
    return fit, inliers
