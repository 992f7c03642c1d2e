"""ONNX export of trained weights (BatchNorm fused, decoded outputs) and a check with onnxruntime.

The ONNX model takes ``images: (1, 3, H, W) float32`` in [0, 1] (the letterboxed frame, see
``detector.infer.letterbox``) and returns ``predictions: (1, N, 5 + nc)`` rows
[cx, cy, w, h, obj, cls...] in network px, exactly what the torch model returns in eval mode;
NMS and the centre refinement stay in Python. Needs the ``onnx`` package (and ``onnxruntime``
for the check).
"""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from dockfactory.core.errors import DockfactoryError
from dockfactory.core.io import atomic_path


def export_onnx(weights, out, height: int = 480, width: int = 640, check: bool = True, seed: int = 0,
                atol: float = 1e-3) -> dict:
    """Export trained weights to ONNX (BatchNorm fused, decoded outputs) and check it against torch.

    Parameters
    ----------
    weights : str or Path
        A weights file or checkpoint.
    out : str or Path
        The ``.onnx`` file, written atomically (a failed export leaves the old file).
    height, width : int
        The fixed input size, positive multiples of 32 (network pixels).
    check, seed, atol : bool, int, float
        Run the model in onnxruntime on a random input of that seed and compare it with torch,
        within ``atol`` relative to the largest output (at least 1).

    Returns
    -------
    dict
        ``{"path", "input_shape"}``, and ``"max_abs_diff"`` with the check.

    Raises
    ------
    DockfactoryError
        A size that is not a positive multiple of 32.
    CheckpointError
        Unusable weights.
    ValueError
        The ONNX model's output differs from torch's in shape or beyond the tolerance.
    """
    import torch

    from dockfactory.detector.checkpoint import load_model
    if height % 32 or width % 32 or height <= 0 or width <= 0:
        raise DockfactoryError(f"height and width must be positive multiples of 32, got {height} x {width}")
    model, _ = load_model(weights, fuse=True)
    x = torch.rand((1, 3, height, width), generator=torch.Generator().manual_seed(seed))
    out = Path(out)
    with atomic_path(out) as tmp, warnings.catch_warnings():   # a failed write leaves the old file and no temporary
        warnings.simplefilter("ignore")  # tracer warnings about the shape checks (fixed input)
        torch.onnx.export(model, (x,), str(tmp), input_names=["images"], output_names=["predictions"],
                          opset_version=17, dynamo=False)
    info = {"path": str(out), "input_shape": [1, 3, height, width]}
    if check:
        info["max_abs_diff"] = _check_against_torch(model, x, out, atol)
    return info


def _check_against_torch(model, x, path: Path, atol: float) -> float:
    """The largest absolute difference of the ONNX model at ``path`` (onnxruntime, CPU) from the
    torch ``model`` on input ``x``; ValueError when the shapes differ or it is beyond ``atol``
    relative to the largest output (at least 1)."""
    import onnxruntime as ort
    import torch
    sess = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    got = sess.run(None, {"images": x.numpy()})[0]
    with torch.inference_mode():
        ref = model(x).numpy()
    if got.shape != ref.shape:
        raise ValueError(f"ONNX output shape {got.shape} != torch {ref.shape}")
    diff = float(np.abs(got - ref).max())
    if diff > atol * max(1.0, float(np.abs(ref).max())):
        raise ValueError(f"ONNX output differs from torch by {diff:.3g} (tolerance {atol} relative)")
    return diff
