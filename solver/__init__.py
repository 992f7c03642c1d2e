"""Uncalibrated pose solver (pure numpy): pose and focal length from marker correspondences.

Layers, bottom to top, as PoseLib and COLMAP structure theirs (each module imports only
``dockfactory.core``, the layers below it and its own layer's base modules; never the
generator, detector or eval packages):

0. base: :mod:`~solver.errors` (one exception subclass per failure category),
   :mod:`~solver.options` (frozen option dataclasses: every threshold and budget once),
   :mod:`~solver.checks` (input validation), :mod:`~solver.lie`, :mod:`~solver.outline`,
   :mod:`~solver.camera_models` (pinhole, k1, k1k2, pp_k1, pp_k1_p: the intrinsics and
   their Jacobian), :mod:`~solver.stats` (chi-square and F tails),
   :mod:`~solver.model_choice` (which model the data support), :mod:`~solver.layout_points`;
1. closed form: :func:`upnp` (UPnP, Penate-Sanchez et al. TPAMI 2013) returns every candidate;
2. refinement: :mod:`~solver.refine`, the one Levenberg-Marquardt loop, the one Jacobian, the
   one covariance (and its propagation to ``d_from_b``), over any number of residual blocks
   and any camera model; bounds :mod:`~solver.crb` use the same Jacobian;
3. estimators: :mod:`~solver.estimate` (one section: closed form -> refinement with fallbacks),
   :mod:`~solver.model_fit` (a camera model refined from a pinhole fit, or chosen: "auto")
   and :mod:`~solver.joint` (two sections, one shared camera: :class:`JointFit`);
4. robust estimation :func:`ransac_pnpf` / :func:`~solver.ransac.ransac_docking` (LO-RANSAC,
   explicit numpy Generator) and identification :func:`identify_markers` (detections without
   ids -> layout ids);
5. entry points and the docking pipeline: :func:`solve_pnpf`; :func:`solve_docking` (identify
   or RANSAC, joint fit, suspects :mod:`~solver.suspects`, eccentricity
   :mod:`~solver.eccentricity`, the disc noise model of the covariance
   :mod:`~solver.disc_noise`); :func:`solve_sequence` (a docking run with shared
   intrinsics: self-calibration, :mod:`~solver.sequence`).

Options: :class:`RefineOptions`, :class:`RansacOptions`, :class:`IdentifyOptions`,
:class:`ModelChoiceOptions`, :class:`DockingOptions` (with :class:`FacingPrior`). Every failure
raises a :class:`SolverError` subclass (a ``ValueError``). Units: mm, degrees at the API (radians
inside), pixels in the OpenCV convention.
"""
from dockfactory.core.names import POSE_NAMES
from dockfactory.solver.camera_models import MODEL_NAMES, IntrinsicsModel, Intrinsics
from dockfactory.solver.crb import (
    DockingBound,
    SequenceBound,
    crb_d_from_b,
    crb_joint,
    crb_pnpf,
    crb_sequence,
)
from dockfactory.solver.docking import DockingResult, solve_docking
from dockfactory.solver.errors import (
    AmbiguousIdentification,
    DegenerateGeometry,
    FocalNotObservable,
    IdentificationFailed,
    InvalidSolverInput,
    NoConsensus,
    NoValidCamera,
    SolverError,
    TooFewPoints,
)
from dockfactory.solver.identify import Identification, identify_markers
from dockfactory.solver.joint import JointFit, fit_joint
from dockfactory.solver.model_choice import ModelChoice, ModelTest
from dockfactory.solver.options import (
    DockingOptions,
    FacingPrior,
    IdentifyOptions,
    ModelChoiceOptions,
    RansacOptions,
    RefineOptions,
)
from dockfactory.solver.pnpf import PnPfResult, solve_pnpf
from dockfactory.solver.ransac import DockingConsensus, ransac_docking, ransac_pnpf
from dockfactory.solver.sequence import SequenceResult, solve_sequence
from dockfactory.solver.upnp import Candidate, upnp

__all__ = [
    # entry points and results
    "solve_pnpf", "PnPfResult", "solve_docking", "DockingResult", "solve_sequence",
    "SequenceResult",
    # camera models
    "MODEL_NAMES", "IntrinsicsModel", "Intrinsics", "ModelChoice", "ModelTest",
    # layers
    "upnp", "Candidate", "fit_joint", "JointFit", "ransac_pnpf", "ransac_docking",
    "DockingConsensus", "identify_markers", "Identification",
    # options
    "RefineOptions", "RansacOptions", "IdentifyOptions", "DockingOptions", "FacingPrior",
    "ModelChoiceOptions",
    # errors
    "SolverError", "InvalidSolverInput", "TooFewPoints", "DegenerateGeometry", "NoValidCamera",
    "FocalNotObservable", "NoConsensus", "IdentificationFailed", "AmbiguousIdentification",
    # bounds
    "crb_pnpf", "crb_joint", "crb_d_from_b", "crb_sequence", "DockingBound", "SequenceBound",
    "POSE_NAMES",
]
