"""The exception types of the solver package (bottom layer: imports only core).

Every failure the solver reports is a :class:`SolverError` (a ``DockfactoryError``, hence a ``ValueError``);
callers that need to tell failures apart catch a subclass, never match the message text:

- :class:`InvalidSolverInput`: malformed arguments (shapes, NaN/inf, unknown ids or classes, option values out of
  range); :class:`TooFewPoints`: fewer usable points (in a section) than a pose needs;
- :class:`DegenerateGeometry`: the points do not determine a pose (collinear points, a singular Fisher information);
- :class:`NoValidCamera`: neither the closed form nor the refinement reaches a valid camera (points behind it, a
  negative squared focal, a diverging refinement);
- :class:`FocalNotObservable`: a pose was found but its focal length is not determined;
- :class:`NoConsensus`: RANSAC found no model with enough inliers;
- :class:`IdentificationFailed`: detections could not be assigned to layout markers;
  :class:`AmbiguousIdentification`, its subclass, when two assignments explain them equally well.
"""
from __future__ import annotations

from dockfactory.core.errors import DockfactoryError

__all__ = ["SolverError", "InvalidSolverInput", "TooFewPoints", "DegenerateGeometry",
           "NoValidCamera", "FocalNotObservable", "NoConsensus", "IdentificationFailed",
           "AmbiguousIdentification"]


class SolverError(DockfactoryError):
    """Bad input or an unsolvable / ambiguous problem; the message says what is wrong.

    A subclass of ``ValueError`` so that callers checking for bad input catch it too. The solver
    never returns a silent garbage pose: whatever it cannot stand behind raises this.
    """


class InvalidSolverInput(SolverError):
    """An argument is malformed: wrong shape, NaN/inf, unknown id or class, bad option value."""


class TooFewPoints(SolverError):
    """Fewer usable points (per section) than a pose needs (``checks.MIN_POINTS``)."""


class DegenerateGeometry(SolverError):
    """The points cannot determine the parameters: collinear or coincident points, or a
    singular Fisher information."""


class NoValidCamera(SolverError):
    """No closed-form candidate or refinement ends at a valid camera (points in front of it,
    positive focal length, finite cost)."""


class FocalNotObservable(SolverError):
    """The estimate's focal length has a relative standard deviation above the threshold of
    :class:`solver.options.RefineOptions`: the pose cannot be trusted."""


class NoConsensus(SolverError):
    """RANSAC found no model supported by enough inliers."""


class IdentificationFailed(SolverError):
    """Detections could not be assigned to layout markers (no hypothesis verified, or no
    assignment consistent across the two sections)."""


class AmbiguousIdentification(IdentificationFailed):
    """Two conflicting marker assignments explain the detections equally well: the solver
    refuses to guess (no second search can settle it)."""
