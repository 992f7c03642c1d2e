"""Uncalibrated pose solver (pure numpy): pose and focal length from marker correspondences.

Layers, bottom to top, as PoseLib and COLMAP structure theirs (each module imports only
``dockfactory.core``, the layers below it and its own layer's base modules; never the
generator, detector or eval packages):

0. base: :mod:`~solver.errors` (one exception subclass per failure category),
   :mod:`~solver.options` (frozen option dataclasses: every threshold and budget once),
   :mod:`~solver.checks` (input validation), :mod:`~solver.lie`, :mod:`~solver.outline`;
1. closed form: :func:`upnp` (UPnP, Penate-Sanchez et al. TPAMI 2013) returns every candidate;
2. refinement: :mod:`~solver.refine`, the one Levenberg-Marquardt loop, the one Jacobian, the
   one covariance (and its propagation to ``d_from_b``); bounds :mod:`~solver.crb` use the same
   Jacobian;
3. estimators: :mod:`~solver.estimate` (one section: closed form -> refinement with fallbacks)
   and :mod:`~solver.joint` (two sections, one shared focal: :class:`JointFit`);
4. robust estimation :func:`ransac_pnpf` / :func:`~solver.ransac.ransac_docking` (LO-RANSAC,
   explicit numpy Generator) and identification :func:`identify_markers` (detections without
   ids -> layout ids);
5. entry points and the docking pipeline: :func:`solve_pnpf`; :func:`solve_docking` (identify
   or RANSAC, joint fit, suspects :mod:`~solver.suspects`, eccentricity
   :mod:`~solver.eccentricity`).

Options: :class:`RefineOptions`, :class:`RansacOptions`, :class:`IdentifyOptions`,
:class:`DockingOptions` (with :class:`FacingPrior`). Every failure raises a
:class:`SolverError` subclass (a ``ValueError``). Units: mm, degrees at the API (radians
inside), pixels in the OpenCV convention.
"""
from dockfactory.core.names import POSE_NAMES
from dockfactory.solver.crb import DockingBound, crb_d_from_b, crb_joint, crb_pnpf
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
from dockfactory.solver.options import (
    DockingOptions,
    FacingPrior,
    IdentifyOptions,
    RansacOptions,
    RefineOptions,
)
from dockfactory.solver.pnpf import PnPfResult, solve_pnpf
from dockfactory.solver.ransac import DockingConsensus, ransac_docking, ransac_pnpf
from dockfactory.solver.upnp import Candidate, upnp

__all__ = [
    # entry points and results
    "solve_pnpf", "PnPfResult", "solve_docking", "DockingResult",
    # layers
    "upnp", "Candidate", "fit_joint", "JointFit", "ransac_pnpf", "ransac_docking",
    "DockingConsensus", "identify_markers", "Identification",
    # options
    "RefineOptions", "RansacOptions", "IdentifyOptions", "DockingOptions", "FacingPrior",
    # errors
    "SolverError", "InvalidSolverInput", "TooFewPoints", "DegenerateGeometry", "NoValidCamera",
    "FocalNotObservable", "NoConsensus", "IdentificationFailed", "AmbiguousIdentification",
    # bounds
    "crb_pnpf", "crb_joint", "crb_d_from_b", "DockingBound", "POSE_NAMES",
]
