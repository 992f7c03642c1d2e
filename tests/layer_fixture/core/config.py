"""VIOLATION (upward): core imports eval."""
from dockfactory.eval.report import build_report  # noqa: F401
