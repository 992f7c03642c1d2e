"""Uncalibrated pose solver (pure numpy): pose and focal length from marker correspondences.

Layers, bottom to top (each imports only core and the layers below): base (errors, options, checks, camera
models), closed form (:func:`upnp`), refinement (:mod:`~solver.refine`), estimators (:func:`fit_joint`), robust
estimation and identification (:func:`ransac_pnpf`, :func:`identify_markers`), entry points (:func:`solve_pnpf`,
:func:`solve_docking`, :func:`solve_sequence`).

Options: :class:`RefineOptions`, :class:`RansacOptions`, :class:`IdentifyOptions`,
:class:`ModelChoiceOptions`, :class:`DockingOptions` (with :class:`FacingPrior`). Every failure
raises a :class:`SolverError` subclass (a ``ValueError``). Units: mm, degrees at the API (radians
inside), pixels in the OpenCV convention.

Why and how: docs/solver.md, "Layers".
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
