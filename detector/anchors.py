"""Anchors fitted to the dataset's marker boxes: k-means plus YOLOv5's best-possible-recall check.

A target box matches an anchor when both width and height ratios lie within ``1/thr .. thr``
(YOLOv5's ``anchor_t`` = 4). Best possible recall (BPR) is the fraction of boxes that match at
least one anchor; YOLOv5 refits when it is below 0.98, we raise instead (the fit is ours).
"""
from __future__ import annotations

import numpy as np

ANCHOR_T = 4.0


def _check_wh(wh) -> np.ndarray:
    wh = np.asarray(wh, dtype=np.float64)
    if wh.ndim != 2 or wh.shape[1] != 2:
        raise ValueError(f"wh must be (N, 2) box widths and heights, got shape {wh.shape}")
    if not np.isfinite(wh).all() or (wh <= 0).any():
        raise ValueError("wh must be finite and positive")
    return wh


def anchor_fitness(wh, anchors, thr: float = ANCHOR_T) -> tuple[float, float]:
    """(best possible recall, mean best ratio metric) of ``anchors: (K, 2)`` px for ``wh: (N, 2)`` px."""
    wh = _check_wh(wh)
    k = _check_wh(np.asarray(anchors, dtype=np.float64).reshape(-1, 2))
    r = wh[:, None, :] / k[None]
    x = np.minimum(r, 1 / r).min(2)          # (N, K): worst-side ratio
    best = x.max(1)
    return float((best > 1 / thr).mean()), float(best.mean())


def kmeans_anchors(wh, n: int = 9, seed: int = 0, iters: int = 100, thr: float = ANCHOR_T,
                   min_bpr: float = 0.98) -> np.ndarray:
    """k-means (k-means++ start, whitened widths/heights) anchors ``(n, 2)`` px sorted by area.

    ``wh: (N, 2) float, px`` boxes at the network's input scale. Raises ValueError when fewer
    boxes than anchors are given or the best possible recall is below ``min_bpr``.
    """
    wh = _check_wh(wh)
    if len(wh) < n:
        raise ValueError(f"need at least {n} boxes to fit {n} anchors, got {len(wh)}")
    rng = np.random.default_rng(seed)
    s = wh.std(0)
    s[s == 0] = 1.0
    x = wh / s
    centres = [x[rng.integers(len(x))]]
    for _ in range(1, n):
        d2 = np.min(((x[:, None] - np.array(centres)[None]) ** 2).sum(-1), 1)
        if d2.sum() == 0:
            centres.append(x[rng.integers(len(x))])
        else:
            centres.append(x[rng.choice(len(x), p=d2 / d2.sum())])
    c = np.array(centres)
    for _ in range(iters):
        assign = ((x[:, None] - c[None]) ** 2).sum(-1).argmin(1)
        new = np.array([x[assign == j].mean(0) if (assign == j).any() else c[j] for j in range(n)])
        if np.allclose(new, c):
            break
        c = new
    anchors = c * s
    anchors = anchors[np.argsort(anchors.prod(1))]
    bpr, _ = anchor_fitness(wh, anchors, thr)
    if bpr < min_bpr:
        raise ValueError(f"k-means anchors reach a best possible recall of {bpr:.3f} < {min_bpr}")
    return anchors


def anchors_per_level(anchors, levels: int) -> tuple:
    """``(levels * 3, 2)`` anchors sorted by area -> nested tuple (levels, 3, (w, h)), smallest first."""
    a = np.asarray(anchors, dtype=np.float64).reshape(-1, 2)
    if len(a) != 3 * levels:
        raise ValueError(f"need {3 * levels} anchors for {levels} levels, got {len(a)}")
    a = a[np.argsort(a.prod(1))]
    return tuple(tuple((round(float(w), 2), round(float(h), 2)) for w, h in a[3 * i:3 * i + 3])
                 for i in range(levels))
