"""Do a frame's markers show in its image where its label says? (``dataset verify --manifest``.)

Each fully visible, legible marker's pixels of its colour must count within ``COUNT_RATIO`` of its label's
``visible_pixels`` and their centroid lie within ``CENTROID_TOLERANCE_PX`` of its ``outline_centroid_px``.

Why and how: docs/datasets.md, "The marker check".
"""
from __future__ import annotations

import math

from dockfactory.core.cv import cv2
import numpy as np

COUNT_RATIO = (0.5, 3.0)
CENTROID_TOLERANCE_PX = 2.5
FULL_FRACTION = 0.99
MIN_PIXELS = 20
CONTRAST = 0.5         # the marker's chroma over its surroundings' excess, as a share of its chroma
SEARCH_MARGIN = 0.25   # the window: the visible box grown by this share of its size (+1 px)


def colour_excess(rgb: np.ndarray, section: str) -> np.ndarray:
    """Per-pixel marker-colour excess of ``rgb`` (..., 3) uint8 RGB in [-1, 1]: red over the larger
    of green and blue for section A, blue over the larger of red and green for B."""
    px = rgb.astype(np.float32) / 255.0
    r, g, b = px[..., 0], px[..., 1], px[..., 2]
    return r - np.maximum(g, b) if section == "A" else b - np.maximum(r, g)


def _checked(marker: dict) -> bool:
    chroma, n, c = marker.get("chroma"), marker.get("visible_pixels"), marker.get("outline_centroid_px")
    frac = marker.get("visible_fraction")
    return (marker.get("legible") is True and isinstance(c, list) and len(c) == 2
            and isinstance(frac, (int, float)) and frac >= FULL_FRACTION
            and all(isinstance(v, (int, float)) and math.isfinite(v) for v in c) and isinstance(chroma, (int, float)) and math.isfinite(chroma)
            and chroma > 0 and isinstance(n, int) and n >= MIN_PIXELS
            and isinstance(marker.get("bbox_visible_px"), list) and len(marker["bbox_visible_px"]) == 4)


def _threshold(excess: np.ndarray, chroma: float) -> float | None:
    """Half-way between the window's surroundings (the median excess of its outermost pixels)
    and the marker's ``chroma``; None when the surroundings come within half the chroma of it
    (a reddish surface behind a red marker): the marker cannot be told from them."""
    border = np.concatenate([excess[0], excess[-1], excess[1:-1, 0], excess[1:-1, -1]])
    around = float(np.median(border))
    if chroma - around < CONTRAST * chroma:
        return None
    return around + 0.5 * (chroma - around)


def marker_colour(image: np.ndarray, marker: dict) -> tuple[int, tuple[float, float] | None]:
    """(count, centroid (x, y) px or None) of ``marker``'s colour in ``image`` (H, W, 3) uint8 RGB:
    in its window, the pixels whose colour excess reaches half-way from the surroundings' to the
    label's ``chroma`` (count -1: surroundings too close in colour to judge), grouped in
    connected blobs; the blobs whose centroid lies inside the label's visible box are the marker
    (a neighbour's blob reaching into the window is not; a disc moved by less than half its box
    still is, whole). Pixel indices follow OpenCV (the top-left pixel's centre is (0, 0))."""
    h, w = image.shape[:2]
    bx0, by0, bx1, by1 = (float(v) for v in marker["bbox_visible_px"])
    pad = SEARCH_MARGIN * max(bx1 - bx0, by1 - by0) + 1.0
    xa, ya = max(0, int(math.floor(bx0 - pad + 0.5))), max(0, int(math.floor(by0 - pad + 0.5)))
    xb, yb = min(w, int(math.ceil(bx1 + pad + 0.5))), min(h, int(math.ceil(by1 + pad + 0.5)))
    if xb <= xa or yb <= ya:
        return 0, None
    excess = colour_excess(image[ya:yb, xa:xb], marker["section"])
    level = _threshold(excess, marker["chroma"])
    if level is None:
        return -1, None
    coloured = (excess >= level).astype(np.uint8)
    n, _, stats, centroids = cv2.connectedComponentsWithStats(coloured, connectivity=8)
    cx, cy = centroids[1:, 0] + xa, centroids[1:, 1] + ya
    keep = (cx >= bx0) & (cx <= bx1) & (cy >= by0) & (cy <= by1)
    area = stats[1:, cv2.CC_STAT_AREA][keep].astype(np.float64)
    if area.sum() == 0:
        return 0, None
    return int(area.sum()), (float(area @ cx[keep] / area.sum()), float(area @ cy[keep] / area.sum()))


def marker_problems(image: np.ndarray, label: dict, where: str) -> tuple[int, list[str]]:
    """(markers judged, one line per judged marker of ``label`` whose colour in ``image`` (H, W, 3)
    uint8 RGB disagrees with the label) (module docstring); ``where`` names the image."""
    problems, judged = [], 0
    for m in label.get("markers") or []:
        if not isinstance(m, dict) or not _checked(m):
            continue
        count, centroid = marker_colour(image, m)
        if count < 0:
            continue
        judged += 1
        ratio = count / m["visible_pixels"]
        if not COUNT_RATIO[0] <= ratio <= COUNT_RATIO[1]:
            problems.append(f"{where}: marker {m.get('id')}: {count} pixels of its colour where the label has "
                            f"{m['visible_pixels']} (ratio {ratio:.2f}, expected {COUNT_RATIO[0]:g}-{COUNT_RATIO[1]:g}):"
                            " erased, recoloured or moved?")
        elif centroid is not None:
            off = math.hypot(centroid[0] - m["outline_centroid_px"][0], centroid[1] - m["outline_centroid_px"][1])
            if off > CENTROID_TOLERANCE_PX:
                problems.append(f"{where}: marker {m.get('id')}: its colour's centroid is {off:.2f} px from the "
                                f"label's (tolerance {CENTROID_TOLERANCE_PX:g} px): moved?")
    return judged, problems
