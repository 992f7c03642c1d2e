"""VIOLATION: the judge imports the app layer above it."""
from dockfactory import pipeline  # noqa: F401
