"""VIOLATION: the root package imports a subpackage."""
from dockfactory.core import geometry  # noqa: F401
