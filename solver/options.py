"""Options of every solver layer as frozen dataclasses (bottom layer: imports only errors).

Each layer takes one options object (as PoseLib's ``RansacOptions`` and ``BundleOptions``); every threshold and
budget is a documented default defined only here; invalid values raise :class:`solver.errors.InvalidSolverInput`
when the object is built:

- :class:`RefineOptions`: the one Levenberg-Marquardt refinement and the acceptance of its result (focal
  observability); :class:`RansacOptions`: the robust layer (single section and docking);
- :class:`FacingPrior`: what "the camera faces the markers" allows (image roll and scale of the weak-perspective
  similarity), shared by RANSAC's and identification's hypotheses;
- :class:`IdentifyOptions`: marker identification (hypothesise and verify); :class:`ModelChoiceOptions`: the
  automatic camera-model choice (``camera_model="auto"``);
- :class:`LensPrior`: the plausible range of the intrinsics a camera model does not estimate (the model error of
  :mod:`solver.model_error`); :class:`DockingOptions`: the docking pipeline (holds the five above).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from dockfactory.solver.checks import check_shift_px, check_sigma
from dockfactory.solver.errors import InvalidSolverInput

# A known centre noise (the noise card's: the core centre noise of clean three-chip renders) is tested
# at this many times itself wherever a fit must be explained by the camera's noise (the goodness-of-fit
# gate, eval.fit_gate; a rival identification, solver.identify): the cameras users have give residuals
# 1-5x the card (Bayer, JPEG, blur, a white ring), the faults 10-100x (bench/results/fit_gate/README.md).
GATE_NOISE_FACTOR = 3.0

__all__ = ["RefineOptions", "FacingPrior", "RansacOptions", "IdentifyOptions",
           "ModelChoiceOptions", "LensPrior", "DockingOptions", "DEFAULT_IDENTIFY",
           "DEFAULT_MODEL_CHOICE", "DEFAULT_LENS_PRIOR", "DEFAULT_DOCKING"]


def _positive(name: str, value, allow_none: bool = False) -> None:
    if value is None and allow_none:
        return
    try:
        ok = math.isfinite(float(value)) and float(value) > 0
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise InvalidSolverInput(f"{name} must be positive and finite, got {value}")


@dataclass(frozen=True)
class RefineOptions:
    """Levenberg-Marquardt over (R, t, f) (:mod:`solver.refine`) and when to accept its result.

    Budget and stopping rules of the LM loop:
    - ``max_iterations``: LM iterations (each tries up to ``damping_tries`` damped steps);
    - ``initial_damping``: Marquardt damping at the start (relative to diag(J^T J)); divided by
      10 after an accepted step (not below ``min_damping``), multiplied by 10 after a rejected
      one;
    - converged when a step moves no residual by more than ``step_tol_px`` px along any
      parameter, when the cost decreases by less than ``cost_rel_tol`` of itself, when the
      model predicts a decrease below ``predicted_rel_tol`` of the cost, or when the cost is
      below ``exact_cost_per_residual`` x the number of residuals (an exact fit).

    Acceptance:
    - ``max_focal_rel_std``: one section, the focal's standard deviation over its value above
      which the focal counts as unobservable (``FocalNotObservable``): the points are too close
      to planar and fronto-parallel for the noise (the estimate runs off toward an affine
      camera);
    - ``max_joint_focal_rel_std``: the same for the joint (two-section) fit; it only refuses
      a focal that clearly ran off, since X, Y and alpha stay well determined when the shared
      focal is poorly known (they hardly depend on the focal / depth trade-off) and the
      covariances report the rest;
    - ``focal_runaway``: a single-section refinement that ends with f above this many times
      the image extent of the points (px from the principal point, + 1) slid toward the
      orthographic limit, the signature of a start in the wrong basin on a few near-planar
      points: the other closed-form candidates are then tried.
    Fallback of the single-section estimator (:mod:`solver.estimate`):
    - ``accept_rmse_sigmas``: when the pixel noise sigma is known, a fast-path fit whose RMS
      exceeds this many sigma takes the slow path (every closed-form candidate);
    - ``fallback_starts``: closed-form candidates refined on the slow path;
    - ``profile_focals``, ``profile_iterations``: the profile-likelihood last resort refines
      the calibrated pose at that many grid focals for that many iterations;
    - ``plausible_rmse_px``: without a known noise sigma, a slow-path fit with a larger RMS (or
      an undetermined focal) is a suspected wrong minimum: with at most ``subset_max_points``
      points every 4-point subset's closed form is tried as a start (solver.estimate). Detector
      centres are good to a few tenths of a pixel; the wrong minima measured had 30-55 px. The
      subsets' candidates are ranked by their RMS over all points and the best
      ``subset_refines`` refined. With at most ``few_points`` points the subsets are also tried
      whenever the fast fit is above ``accept_rmse`` (identification hypotheses, which skip the
      other rescues when far off).
    Covariance (:func:`solver.refine.covariance_from_jacobian`):
    - ``sigma_floor_px``: when the noise sigma is estimated from a fit's residuals, it is never
      taken below this (the detector's centre noise measured on labelled frames); None: no floor.
    - ``noise_prior_px``: the core of the centre noise the camera is known to have (px per axis:
      the noise card's robust core times the camera class's factor); a disc-model covariance's
      noise scale estimated from few residuals is pulled up toward it
      (:func:`solver.refine.scale_with_prior`); None: no prior.
    """

    max_iterations: int = 60
    initial_damping: float = 1e-6
    min_damping: float = 1e-12
    damping_tries: int = 12
    step_tol_px: float = 1e-9
    cost_rel_tol: float = 1e-9
    predicted_rel_tol: float = 1e-12
    exact_cost_per_residual: float = 1e-28
    max_focal_rel_std: float = 1.0
    max_joint_focal_rel_std: float = 10.0
    focal_runaway: float = 1000.0
    accept_rmse_sigmas: float = 3.0
    fallback_starts: int = 4
    profile_focals: int = 9
    profile_iterations: int = 6
    plausible_rmse_px: float = 5.0
    subset_max_points: int = 7
    subset_refines: int = 3
    few_points: int = 5
    sigma_floor_px: float | None = None
    noise_prior_px: float | None = None

    def __post_init__(self):
        for name in ("max_iterations", "damping_tries", "max_focal_rel_std",
                     "max_joint_focal_rel_std", "focal_runaway", "accept_rmse_sigmas",
                     "fallback_starts", "profile_focals", "profile_iterations", "plausible_rmse_px",
                     "subset_max_points", "subset_refines", "few_points"):
            _positive(name, getattr(self, name))
        for name in ("sigma_floor_px", "noise_prior_px"):
            if getattr(self, name) is not None:
                check_sigma(getattr(self, name))


@dataclass(frozen=True)
class FacingPrior:
    """The docking camera faces the markers: to first order a section's image is a similarity
    ``z = a (X - iY) + b`` of its markers' coordinates (weak perspective).

    - ``max_roll_deg``: largest plausible image roll (angle of ``a``), at most 180: any roll
      (cameras are mounted in any orientation; a roll the image shows is not evidence against
      a hypothesis, the full-perspective verification and the fit test decide);
    - ``scale_range``: plausible |a| = f / depth (px per mm);
    - ``loose_gate``: a projected marker within this fraction of the smallest marker spacing
      (scaled to pixels) of a detection counts as matched by a hypothesis.
    """

    max_roll_deg: float = 180.0
    scale_range: tuple = (0.05, 50.0)
    loose_gate: float = 0.4

    def __post_init__(self):
        _positive("max_roll_deg", self.max_roll_deg)
        if self.max_roll_deg > 180.0:
            raise InvalidSolverInput(f"max_roll_deg must be at most 180 (any roll), got {self.max_roll_deg}")
        _positive("loose_gate", self.loose_gate)
        lo, hi = self.scale_range
        if not (0 < lo < hi and math.isfinite(hi)):
            raise InvalidSolverInput(f"scale_range must be 0 < low < high, got "
                                     f"{self.scale_range}")


@dataclass(frozen=True)
class RansacOptions:
    """LO-RANSAC (:mod:`solver.ransac`).

    - ``threshold_px``: inlier threshold on the reprojection error (px); MSAC scores truncate
      the squared error there;
    - ``confidence``: probability of having drawn one clean sample when sampling stops;
    - single section: at most ``max_iterations`` samples of ``sample_size`` points (6, the
      smallest set with a one-dimensional UPnP null space), each polished by
      ``sample_refine_iterations`` LM iterations; the final fit on the inliers refines the
      best ``final_starts`` closed-form candidates;
    - docking: at most ``section_iterations`` two-point samples per section under ``prior``;
      the points a sample's similarity predicts are fitted by UPnP + LM
      (``loose_refine_iterations``), dropping the worst point up to ``loose_refits`` times;
      a hypothesis whose closed form misses restarts LM (``facing_refine_iterations``) from the
      facing camera at ``facing_distance_mm``; the joint refit of both sections runs
      ``joint_refine_iterations`` per round for up to ``joint_rounds`` rounds;
    - local optimisation: up to ``lo_rounds`` refits (``lo_refine_iterations`` each) on the
      inliers of every new best model.
    """

    threshold_px: float = 4.0
    confidence: float = 0.9999
    max_iterations: int = 2000
    sample_size: int = 6
    sample_refine_iterations: int = 10
    final_starts: int = 3
    section_iterations: int = 300
    prior: FacingPrior = field(default_factory=FacingPrior)
    loose_refine_iterations: int = 15
    loose_refits: int = 3
    facing_distance_mm: float = 1500.0
    facing_refine_iterations: int = 30
    joint_refine_iterations: int = 30
    joint_rounds: int = 3
    lo_rounds: int = 4
    lo_refine_iterations: int = 15

    def __post_init__(self):
        _positive("threshold_px", self.threshold_px)
        if not 0 < self.confidence < 1:
            raise InvalidSolverInput(f"confidence must be in (0, 1), got {self.confidence}")
        for name in ("max_iterations", "sample_size", "sample_refine_iterations",
                     "final_starts", "section_iterations", "loose_refine_iterations",
                     "loose_refits", "facing_distance_mm", "facing_refine_iterations",
                     "joint_refine_iterations", "joint_rounds", "lo_rounds",
                     "lo_refine_iterations"):
            _positive(name, getattr(self, name))


@dataclass(frozen=True)
class IdentifyOptions:
    """Marker identification (:mod:`solver.identify`).

    - ``sigma_px``: expected std of the detected centres (px); a hypothesis explains the
      detections if its reprojection RMS is at most ``max_rmse_sigmas`` x sigma;
    - ``gate_px``: detections match projected markers within this distance (default
      ``gate_sigmas`` x sigma), at most ``max_gate_spacing`` x the projected marker spacing;
    - ``prior``: plausible roll and scale of the hypotheses, and their loose gate;
    - ``max_hypotheses``: similarity hypotheses verified per section and anchor set;
    - ``min_matches``: markers a section hypothesis must explain (at least 4);
    - ``rescue_rmse_factor``: a hypothesis fit whose RMS is above the acceptable RMS but below
      this factor times it is a near miss worth the slow solver path (far worse fits are wrong
      assignments, not local minima).
    """

    sigma_px: float = 1.0
    gate_px: float | None = None
    gate_sigmas: float = 4.0
    max_rmse_sigmas: float = 2.5
    max_gate_spacing: float = 0.3
    prior: FacingPrior = field(default_factory=FacingPrior)
    max_hypotheses: int = 8
    min_matches: int = 4
    rescue_rmse_factor: float = 4.0

    def __post_init__(self):
        _positive("sigma_px", self.sigma_px)
        _positive("gate_px", self.gate_px, allow_none=True)
        for name in ("gate_sigmas", "max_rmse_sigmas", "max_gate_spacing", "max_hypotheses",
                     "min_matches", "rescue_rmse_factor"):
            _positive(name, getattr(self, name))

    @property
    def gate(self) -> float:
        """Match gate (px) before the cap by the projected marker spacing."""
        return float(self.gate_px) if self.gate_px is not None else \
            self.gate_sigmas * float(self.sigma_px)

    @property
    def max_rmse(self) -> float:
        """Largest reprojection RMS (px) of a verified hypothesis."""
        return self.max_rmse_sigmas * float(self.sigma_px)


@dataclass(frozen=True)
class ModelChoiceOptions:
    """Automatic choice of the camera model (:mod:`solver.model_choice`): a model richer than
    the current one is taken only when the data determine it and it explains them better.

    - ``lr_alpha``: false-alarm probability of the likelihood-ratio test of a richer model
      against the current one (chi-square with the added parameters as degrees of freedom when
      the pixel noise is known, F when it is estimated). 1e-3: with up to four richer models
      tested on an ideal camera, fewer than 0.4 % of frames leave the pinhole by chance
      (Bonferroni), so ideal data keep the paper's model. The price: a lens or offset whose
      effect is near the noise stays undetected per frame; a docking run
      (:func:`solver.solve_sequence`) determines them (figures: results/README.md);
    - ``prior_pp_px``, ``prior_k1``, ``prior_k2``, ``prior_p``: half-width of the plausible
      range of each extra intrinsic for a camera nobody calibrated (principal point within
      +-50 px of the centre, |k1| <= 0.2, |k2| <= 0.1, |p1|, |p2| <= 2e-3: a little wider than
      the ranges of configs/realistic.toml, +-40 px, k1 in [-0.15, 0.05],
      |k2| <= 0.05, |p| <= 1e-3);
    - ``max_std_inflation``: a richer model is refused when a parameter of a model it nests sees
      its standard deviation grow by more than this factor in it (its added parameters trade
      off against that one: p1, p2 against the principal point over a docking run; the value
      is checked on two renders, results/README.md);
    - ``max_std_fraction``: a richer model is supported only when the standard deviation of
      every parameter it adds is at most this fraction of its plausible half-range: 0.5 means
      the data, not the prior, fix its sign and size. An ill-conditioned fit (a singular
      information matrix) has infinite deviations and is never chosen;
    - ``min_residual_dof``: with the noise estimated, a model needs at least this many residual
      degrees of freedom (residuals minus parameters) for its F test (fewer: the noise
      estimate is too poor to test anything).
    """

    lr_alpha: float = 1e-3
    prior_pp_px: float = 50.0
    prior_k1: float = 0.2
    prior_k2: float = 0.1
    prior_p: float = 2e-3
    max_std_fraction: float = 0.5
    min_residual_dof: int = 4
    max_std_inflation: float = 1.5

    def __post_init__(self):
        if not 0 < self.lr_alpha < 1:
            raise InvalidSolverInput(f"lr_alpha must be in (0, 1), got {self.lr_alpha}")
        for name in ("prior_pp_px", "prior_k1", "prior_k2", "prior_p", "max_std_fraction",
                     "min_residual_dof", "max_std_inflation"):
            _positive(name, getattr(self, name))

    def prior(self, name: str) -> float:
        """Plausible half-range of an extra intrinsic (``camera_models.EXTRA_NAMES``)."""
        return {"cx": self.prior_pp_px, "cy": self.prior_pp_px, "k1": self.prior_k1,
                "k2": self.prior_k2, "p1": self.prior_p, "p2": self.prior_p}[name]


@dataclass(frozen=True)
class LensPrior:
    """What is plausible for the intrinsics a camera model does not estimate
    (:mod:`solver.model_error`): each is taken as uniform over its half-range around the value
    the solve assumes (the given principal point, no distortion), independent of the others.

    - ``pp_fraction``: half-range of the principal point's offset per axis, as a fraction of the
      image width (taken as 2 cx + 1 from the assumed principal point);
    - ``k1``, ``k2``: half-ranges of the radial coefficients; ``p``: of p1 and p2;
    - ``marginalise``: add the pose error these intrinsics cause over their range to the
      reported covariance (conditioned on what the frame's residuals say about them); False:
      the lens is known (calibrated, or an ideal camera) and the covariance carries only the
      noise and the estimated intrinsics;
    - ``misfit_alpha``: false-alarm probability of the test that flags a solve whose model does
      not explain its residuals (a score test of the intrinsics it does not estimate, made
      whether or not ``marginalise`` is set).
    """

    pp_fraction: float = 0.04
    k1: float = 0.2
    k2: float = 0.1
    p: float = 2e-3
    marginalise: bool = False
    misfit_alpha: float = 1e-3

    def __post_init__(self):
        for name in ("pp_fraction", "k1", "k2", "p"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise InvalidSolverInput(f"{name} must be finite and >= 0, got {v}")
        if not 0 < self.misfit_alpha < 1:
            raise InvalidSolverInput(f"misfit_alpha must be in (0, 1), got {self.misfit_alpha}")

    def half_range(self, name: str, principal_point) -> float:
        """Half-range of an extra intrinsic (``camera_models.EXTRA_NAMES``); the principal
        point's from the image width that ``principal_point`` (2,) px implies."""
        if name in ("cx", "cy"):
            return self.pp_fraction * (2.0 * float(principal_point[0]) + 1.0)
        return {"k1": self.k1, "k2": self.k2, "p1": self.p, "p2": self.p}[name]


@dataclass(frozen=True)
class DockingOptions:
    """The docking pipeline (:func:`solver.solve_docking`).

    - ``refine``, ``ransac``, ``identify``: options of the layers it calls; ``model_choice``:
      the automatic camera-model choice (``camera_model="auto"``);
    - ``min_extent``: a detected box narrower or lower than this fraction of the outline the
      first fit predicts for its marker is a partly hidden marker (:mod:`solver.suspects`);
    - ``eccentricity``: correct detected centres (centroids of the disc's image) by their
      predicted perspective offset and refit (:mod:`solver.eccentricity`).
    - ``disc_noise``: when the noise is estimated from the residuals (no ``sigma_px``), the
      covariance of a fit from detections models each centre's noise by the shape of its
      disc's image (:mod:`solver.disc_noise`: larger along the ellipse's major axis); False:
      isotropic.
    - ``robust`` (with ``disc_noise``): the last refit of a frame from detections is an
      iteratively reweighted least squares under the disc noise model with Student-t tails
      (:func:`solver.disc_noise.robust_refit`); False: unweighted, the disc model's covariance
      only.
    - ``occlusion_bias``, ``occlusion_margin_px`` (with ``disc_noise``): a kept detection whose
      box is shorter than its predicted outline by ``cut`` px along an axis (beyond
      ``occlusion_margin_px``, the box noise of fully visible markers) sees only part of its
      disc, and its centre is off by about ``occlusion_bias`` x (cut - margin) along that axis
      (the centre of the visible part's box moves by cut / 2): that variance is added to the
      point's noise in the last fit (:func:`solver.suspects.occlusion_variances`).
      ``occlusion_bias`` 0 turns it off.
    - ``lens``: the plausible range of the intrinsics the camera model does not estimate: the
      misfit test of every solve, and with ``lens.marginalise`` the model error in its
      covariance (:mod:`solver.model_error`).
    - ``run_marker_bias``: a docking run's covariance (:func:`solver.solve_sequence`) lets the
      centres carry a bias that persists across the run's frames and correlates between nearby
      markers of a section (a field over the image, correlation length
      ``solver.model_error.BIAS_LENGTH`` image diagonals), its variance estimated from the run's
      residuals and counted when they show it (:func:`solver.model_error.
      persistent_bias_covariance`); False: the centres' errors are independent between frames.
    - ``section_shift_px``: None, or the std (x, y) px of a common offset of each section's
      centres that no fit's residuals show (its pose absorbs it: :mod:`solver.section_shift`),
      measured on other labelled frames of the camera class (eval.section_shift, the noise
      card): added to the covariance of every solve, one shift per section over a run.
    """

    refine: RefineOptions = field(default_factory=RefineOptions)
    ransac: RansacOptions = field(default_factory=RansacOptions)
    identify: IdentifyOptions = field(default_factory=IdentifyOptions)
    model_choice: ModelChoiceOptions = field(default_factory=ModelChoiceOptions)
    lens: LensPrior = field(default_factory=LensPrior)
    run_marker_bias: bool = True
    min_extent: float = 0.85
    eccentricity: bool = True
    disc_noise: bool = True
    robust: bool = True
    occlusion_bias: float = 0.5
    occlusion_margin_px: float = 1.0
    section_shift_px: tuple[float, float] | None = None

    def __post_init__(self):
        if self.section_shift_px is not None:
            object.__setattr__(self, "section_shift_px", check_shift_px(self.section_shift_px))
        if not (math.isfinite(self.min_extent) and 0 < self.min_extent <= 1):
            raise InvalidSolverInput(f"min_extent must be in (0, 1], got {self.min_extent}")
        for name in ("occlusion_bias", "occlusion_margin_px"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise InvalidSolverInput(f"{name} must be finite and >= 0, got {v}")


DEFAULT_IDENTIFY = IdentifyOptions()
DEFAULT_MODEL_CHOICE = ModelChoiceOptions()
DEFAULT_LENS_PRIOR = LensPrior()
DEFAULT_DOCKING = DockingOptions()
