"""dockfactory: synthetic-data factory and acceptance judge for uncalibrated monocular docking.

One import root; the subpackages live in the repository's folders (package-dir mapping):
``dockfactory.core`` (core/), ``dockfactory.generator`` (generator/), ``dockfactory.blender_scenes``
(blender_scenes/), ``dockfactory.solver`` (solver/), ``dockfactory.detector`` (detector/),
``dockfactory.eval`` (eval/); shipped configs and weights are ``dockfactory.configs`` and
``dockfactory.models``. Layers: core <- generator, blender_scenes, solver, detector <- eval.
"""
from importlib import metadata

try:
    __version__ = metadata.version("dockfactory")
except metadata.PackageNotFoundError:  # running from an uninstalled source tree
    __version__ = "0+unknown"
