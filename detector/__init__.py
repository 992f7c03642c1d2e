"""The marker detector (YOLOv5-style network with attention, plain PyTorch) and its centre
refinement. OpenCV is loaded here through core.cv first, so no module of the package leaves its
loader's LD_LIBRARY_PATH in the caller's environment (detector/centre.py, whose source names the
noise cards' refinement, keeps a plain ``import cv2``)."""
from dockfactory.core import cv as _cv  # noqa: F401
