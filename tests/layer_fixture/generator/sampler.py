"""VIOLATION (module level): generator imports blender_scenes at module level."""
from dockfactory.blender_scenes.render import RADIUS  # noqa: F401
