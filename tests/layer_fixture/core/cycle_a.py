"""VIOLATION (cycle): cycle_a -> cycle_b -> cycle_a at module level."""
from dockfactory.core import cycle_b  # noqa: F401
