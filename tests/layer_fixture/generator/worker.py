"""Fine: blender_scenes inside a function."""
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from dockfactory.eval.report import Report  # VIOLATION (upward) even if only for types


def run():
    from dockfactory.blender_scenes.render import RADIUS
    return RADIUS
