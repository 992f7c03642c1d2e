"""VIOLATION (sideways): solver imports detector."""
from dockfactory.detector import infer  # noqa: F401
