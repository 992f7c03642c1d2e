"""A stand-in for torchvision, for bench/solver/pose_train.py only: NOT torchvision.

Why: ultralytics' trainer and validator import torchvision, and the PyPI torchvision wheels do not
import beside this project's CPU torch (they want CUDA libraries); installing a matching
torchvision pulls another torch build of several GB. What one YOLO pose train and val on the CPU
use of torchvision (read in ultralytics 8.4.190's source):

- ``ultralytics.utils`` reads torchvision's version from package metadata at import (bench/solver/pose_train.py
  writes a metadata-only ``torchvision-<version>.dist-info`` record beside this package);
- ``engine/validator.py`` runs ``import torchvision`` in ``BaseValidator.__init__`` (timing only);
- ``utils/nms.py`` then calls ``torchvision.ops.nms`` because torchvision is in ``sys.modules``.

Everything else ultralytics takes from torchvision (classification transforms and ImageFolder,
TorchVision backbones, SAM's roi_align, TorchScript export) is not on this path and is absent
here: using it raises AttributeError / ImportError. This package is put on the path only by the
bench script (PYTHONPATH), never installed, never imported by dockfactory.
"""
from . import ops

__version__ = "0.28.0+standin"   # the torchvision release ultralytics pairs with torch 2.13
__all__ = ["ops"]
