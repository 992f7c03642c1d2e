"""The marker detector (YOLOv5-style network with attention, plain PyTorch) and its centre
refinement, behind a small facade. OpenCV is loaded here through core.cv first, so no module of
the package leaves its loader's LD_LIBRARY_PATH in the caller's environment (detector/centre.py,
whose source names the noise cards' refinement, keeps a plain ``import cv2``).

Importing the package loads neither torch nor a model: the names that need torch
(:mod:`~dockfactory.detector.infer` detection, ``train`` whose ``train`` is the facade's
``train_detector``, ``checkpoint``) are imported from their module when first used; the centre
refinement, the noise card and the ONNX export (torch inside its function) at once.
"""
from dockfactory.core import cv as _cv  # noqa: F401
from dockfactory.detector.centre import refine_centre
from dockfactory.detector.noise_card import card_figures, write_noise_card
from dockfactory.detector.onnx_export import export_onnx

__all__ = [
    # detection of a dataset's frames, or of one image
    "detect_dataset", "MarkerDetector",
    # training, weights, export
    "train_detector", "TrainConfig", "load_model", "CheckpointError", "export_onnx",
    # the centre refinement and the weights' noise card
    "refine_centre", "card_figures", "write_noise_card",
]


def __getattr__(name: str):
    """The facade's names that need torch, imported from their module on first use (PEP 562)."""
    if name == "detect_dataset":
        from dockfactory.detector.infer import detect_dataset as value
    elif name == "MarkerDetector":
        from dockfactory.detector.infer import MarkerDetector as value
    elif name == "train_detector":
        from dockfactory.detector.train import train as value
    elif name == "TrainConfig":
        from dockfactory.detector.train import TrainConfig as value
    elif name == "load_model":
        from dockfactory.detector.checkpoint import load_model as value
    elif name == "CheckpointError":
        from dockfactory.detector.checkpoint import CheckpointError as value
    else:
        raise AttributeError(f"module 'dockfactory.detector' has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))
