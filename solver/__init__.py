"""Uncalibrated pose solver (pure numpy): pose and focal length from marker correspondences.

Layers (as PoseLib and COLMAP structure theirs):
- closed form: :func:`upnp` (UPnP, Penate-Sanchez et al. TPAMI 2013) returns every candidate;
- refinement: :mod:`solver.refine` (Levenberg-Marquardt over (R, t, f), one section or two
  sections with a shared focal length) with covariances;
- robust: :func:`ransac_pnpf` (LO-RANSAC with an explicit numpy Generator);
- identification: :func:`identify_markers` (detections without ids -> layout ids);
- bounds: :mod:`solver.crb` (Cramer-Rao lower bounds).

Public entry points: :func:`solve_pnpf`, :func:`solve_docking`, :func:`solve_pnpf_batch`,
:func:`solve_docking_batch`. Bad input raises :class:`SolverError` (a ``ValueError``).
Units: mm, degrees at the API (radians inside), pixels in the OpenCV convention.
"""
from dockfactory.solver.batch import (
    DockingBatch,
    PnPfBatch,
    solve_docking_batch,
    solve_pnpf_batch,
)
from dockfactory.solver.crb import (
    POSE_NAMES,
    DockingBound,
    crb_d_from_b,
    crb_joint,
    crb_pnpf,
)
from dockfactory.solver.docking import DockingResult, solve_docking
from dockfactory.solver.errors import AmbiguousIdentification, SolverError
from dockfactory.solver.identify import Identification, identify_markers
from dockfactory.solver.pnpf import PnPfResult, solve_pnpf
from dockfactory.solver.ransac import ransac_pnpf
from dockfactory.solver.upnp import Candidate, upnp

__all__ = [
    "SolverError", "AmbiguousIdentification", "solve_pnpf", "PnPfResult", "solve_docking", "DockingResult",
    "solve_pnpf_batch", "PnPfBatch", "solve_docking_batch", "DockingBatch", "upnp", "Candidate",
    "ransac_pnpf", "identify_markers", "Identification", "crb_pnpf", "crb_joint",
    "crb_d_from_b", "DockingBound", "POSE_NAMES",
]
