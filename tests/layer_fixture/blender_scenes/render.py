import bpy  # noqa: F401  (fine: the adapter imports bpy)

from dockfactory.core.layout import RADIUS  # noqa: F401  fine
