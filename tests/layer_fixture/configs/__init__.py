"""VIOLATION: a data package importing the project."""
import dockfactory.core  # noqa: F401
