"""The detector network run by ONNX Runtime (the ``onnx`` extra): same inputs and outputs as the
torch model in eval mode, about 2.4x faster on 2 CPU cores for a 640x480 input (18 ms against
44 ms, bench/cli/measure_speed.py).

The model is exported in memory from the loaded (BatchNorm-fused) torch model, once per input
shape, so nothing is written and the weights file stays the only artefact. The export is checked
against torch on a seeded random input; a difference above ``atol`` (relative to the largest
output) raises rather than detecting with a different network.
"""
from __future__ import annotations

import io
import threading
import warnings

import numpy as np
import torch

BACKENDS = ("torch", "onnx")


def onnxruntime_available() -> bool:
    try:
        import onnxruntime  # noqa: F401
    except ImportError:
        return False
    return True


def resolve_backend(backend: str | None) -> str:
    """``None``/"auto" -> "onnx" when onnxruntime imports, else "torch"; a named backend is checked."""
    if backend in (None, "auto"):
        return "onnx" if onnxruntime_available() else "torch"
    if backend not in BACKENDS:
        raise ValueError(f"backend must be auto, {' or '.join(BACKENDS)}, got {backend!r}")
    if backend == "onnx" and not onnxruntime_available():
        raise ValueError("backend onnx needs the onnxruntime package (pip install -e '.[onnx]')")
    return backend


class OnnxNetwork:
    """``net(x: (1, 3, H, W) float32 tensor) -> (1, N, 5 + nc) tensor``, one ORT session per shape."""

    def __init__(self, model: torch.nn.Module, threads: int | None = None, atol: float = 1e-3, seed: int = 0):
        self.model, self.threads, self.atol, self.seed = model, threads, atol, seed
        self.sessions: dict[tuple, object] = {}
        self.lock = threading.Lock()   # one export per shape when threads share the network

    def _session(self, shape: tuple):
        import onnxruntime as ort
        x = torch.rand(shape, generator=torch.Generator().manual_seed(self.seed))
        buf = io.BytesIO()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # tracer warnings about the shape checks (fixed input)
            torch.onnx.export(self.model, (x,), buf, input_names=["images"], output_names=["predictions"],
                              opset_version=17, dynamo=False)
        opts = ort.SessionOptions()
        opts.intra_op_num_threads = self.threads or torch.get_num_threads()
        opts.inter_op_num_threads = 1
        opts.add_session_config_entry("session.intra_op.allow_spinning", "0")  # idle threads yield the core
        sess = ort.InferenceSession(buf.getvalue(), opts, providers=["CPUExecutionProvider"])
        got = sess.run(None, {"images": x.numpy()})[0]
        with torch.inference_mode():
            ref = self.model(x).numpy()
        diff = float(np.abs(got - ref).max()) if got.shape == ref.shape else float("inf")
        if diff > self.atol * max(1.0, float(np.abs(ref).max())):
            raise RuntimeError(f"ONNX Runtime output differs from torch by {diff:.3g} for input {shape}")
        return sess

    def __call__(self, x: torch.Tensor) -> torch.Tensor:
        shape = tuple(x.shape)
        with self.lock:
            if shape not in self.sessions:
                self.sessions[shape] = self._session(shape)
        arr = np.ascontiguousarray(x.numpy(), dtype=np.float32)
        return torch.from_numpy(self.sessions[shape].run(None, {"images": arr})[0])
