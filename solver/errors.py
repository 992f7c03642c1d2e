"""The exception types of the solver package."""
from __future__ import annotations

from dockfactory.core.errors import DockfactoryError

__all__ = ["SolverError", "AmbiguousIdentification"]


class SolverError(DockfactoryError):
    """Bad input or an unsolvable / ambiguous problem; the message says what is wrong.

    A subclass of ``ValueError`` so that callers checking for bad input catch it too. The solver
    never returns a silent garbage pose: whatever it cannot stand behind raises this.
    """


class AmbiguousIdentification(SolverError):
    """Two conflicting marker assignments explain the detections equally well: the solver
    refuses to guess (no second search can settle it)."""
