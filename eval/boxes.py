"""Box geometry shared by the detection metrics (numpy; the detector's torch version is in
detector/infer.py)."""
from __future__ import annotations

import numpy as np


def iou_matrix(a, b) -> np.ndarray:
    """``a: (N, 4)``, ``b: (M, 4)`` [x0, y0, x1, y1] -> ``(N, M)`` IoU."""
    a = np.asarray(a, dtype=np.float64).reshape(-1, 4)
    b = np.asarray(b, dtype=np.float64).reshape(-1, 4)
    lt = np.maximum(a[:, None, :2], b[None, :, :2])
    rb = np.minimum(a[:, None, 2:], b[None, :, 2:])
    inter = np.clip(rb - lt, 0, None).prod(2)
    area_a = np.prod(np.clip(a[:, 2:] - a[:, :2], 0, None), 1)
    area_b = np.prod(np.clip(b[:, 2:] - b[:, :2], 0, None), 1)
    return inter / np.maximum(area_a[:, None] + area_b[None] - inter, 1e-12)
