"""Sub-pixel marker centre (and outline box) at full resolution inside a detected box.

A marker is a red or blue disc inside a dark ring. Inside a window around the detector's box:

1. the image is converted to linear light (8-bit sRGB -> linear), where partial pixel coverage
   at the disc edge mixes linearly;
2. a colour score per pixel: the class channel minus the mean of the other two (red for RedA,
   blue for BlueB); near 0 on the dark ring and on grey/white surfaces, large on the disc;
3. the score is normalised between the ring level (median over a thin annulus just outside the
   box) and the disc level (lower quartile over the inner half of the box) into a soft coverage
   w in [0, 1];
4. w is restricted to the connected component (w > 0.5) holding the box centre, dilated by two
   pixels so that the soft edge pixels count;
5. centre = coverage-weighted centroid; second moments give the ellipse of the disc
   (for a uniform ellipse the half-extent along x is 2 sqrt(var_x), var including the 1/12 of
   the pixel footprint), hence a refined outline box. The moments fall short of the true
   outline by a few hundredths of a px per side (edge blur against the ring level; 0.041 px:
   median over 1441 fully visible markers of every second train frame of configs/detector.toml,
   dataset 2601360c1f4c4e22, 2 spp; 0.024 px on 1-spp renders): ``edge_bias_px`` adds it back.

Quality in [0, 1] combines the contrast between disc and ring (against the spread of the score
over the disc: noise and shading), and how well
the segmented area matches the area of the ellipse that its own moments imply and the area of
the detector's box (occluded or merged markers score low). Below ``min_quality`` the
detector's box is kept and its centre returned.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from dockfactory.core.names import CLASS_CHANNELS

_SRGB_TO_LINEAR = np.where(np.arange(256) / 255.0 <= 0.04045, np.arange(256) / 255.0 / 12.92,
                           ((np.arange(256) / 255.0 + 0.055) / 1.055) ** 2.4).astype(np.float32)
CLASS_CHANNEL = dict(enumerate(CLASS_CHANNELS))  # class id -> RGB channel of its colour


@dataclass(frozen=True)
class Refined:
    """``center: (2,) float64 px`` and ``box: (4,) float64 px`` (OpenCV convention), quality in [0, 1],
    ``refined``: False when the detector's box was kept."""
    center: np.ndarray
    box: np.ndarray
    quality: float
    refined: bool


def colour_score(rgb: np.ndarray, class_id: int) -> np.ndarray:
    """``rgb: (H, W, 3) uint8`` sRGB -> ``(H, W) float32`` linear class channel minus the mean of
    the other two (a washed-out cyan-white blue disc still scores above white)."""
    return score_and_purity(rgb, class_id)[0]


def colour_purity(rgb: np.ndarray, class_id: int) -> np.ndarray:
    """``(H, W) float32``: (class channel - largest other channel) / class channel, linear; 1
    for a pure marker colour, 0 for grey, small for a warm or cold colour that only leans
    toward the class (orange for red)."""
    return score_and_purity(rgb, class_id)[1]


def score_and_purity(rgb: np.ndarray, class_id: int) -> tuple[np.ndarray, np.ndarray]:
    """(:func:`colour_score`, :func:`colour_purity`) from one sRGB-to-linear lookup."""
    if class_id not in CLASS_CHANNEL:
        raise ValueError(f"class_id must be 0 (RedA) or 1 (BlueB), got {class_id!r}")
    lin = _SRGB_TO_LINEAR[rgb]
    c = CLASS_CHANNEL[class_id]
    o1, o2 = (lin[..., k] for k in range(3) if k != c)
    top = lin[..., c]
    return top - 0.5 * (o1 + o2), (top - np.maximum(o1, o2)) / np.maximum(top, 1e-4)


PURITY_SHARE = 0.5  # pixels under this share of the disc's median purity are not the disc
MAX_SCORE_RATIO = 3.0  # pixels scoring this many times the disc's level (above the ring's) are not the disc


EDGE_BIAS_PX = 0.041  # px added to the moment half-extents: median shortfall on train frames of configs/detector.toml


def refine_centre(image: np.ndarray, box, class_id: int, min_quality: float = 0.3,
                  edge_bias_px: float = EDGE_BIAS_PX) -> Refined:
    """Refine one detection. ``image: (H, W, 3) uint8`` RGB at full resolution,
    ``box: (4,) [x0, y0, x1, y1]`` px (OpenCV convention).

    Two passes: the window, the inner and ring masks of the first pass come from the detector's
    box; when that box is a few tenths of the radius too small the ring mask lands on the disc
    and the cut at 1.3 box radii clips it. The second pass repeats the measurement in the window
    of the first refined ellipse (kept if it is refined too)."""
    first = _refine_once(image, box, class_id, min_quality, edge_bias_px)
    if not first.refined:
        return first
    second = _refine_once(image, first.box, class_id, min_quality, edge_bias_px)
    if not second.refined:
        return first
    return Refined(center=second.center, box=second.box, quality=second.quality, refined=True)


def _checked_box(image: np.ndarray, box) -> np.ndarray:
    """``box`` as a ``(4,) float64`` array; ValueError for a bad image or box."""
    if image.ndim != 3 or image.shape[2] != 3 or image.dtype != np.uint8:
        raise ValueError(f"image must be (H, W, 3) uint8, got {image.shape} {image.dtype}")
    box = np.asarray(box, dtype=np.float64).reshape(-1)
    if box.shape != (4,) or not np.isfinite(box).all() or box[2] <= box[0] or box[3] <= box[1]:
        raise ValueError(f"box must be finite [x0, y0, x1, y1] with x1 > x0 and y1 > y0, got {box}")
    return box


def _window(cx: float, cy: float, hw: float, hh: float, w_img: int, h_img: int) -> tuple[int, int, int, int] | None:
    """(x0, y0, x1, y1) pixel slice bounds of the search window around the box, clipped to the
    image; None when it is under 4 px wide or high."""
    m = 1.45  # window half-size in box half-sizes
    x0, x1 = int(np.floor(cx - m * hw - 2)), int(np.ceil(cx + m * hw + 2)) + 1
    y0, y1 = int(np.floor(cy - m * hh - 2)), int(np.ceil(cy + m * hh + 2)) + 1
    x0, y0, x1, y1 = max(x0, 0), max(y0, 0), min(x1, w_img), min(y1, h_img)
    if x1 - x0 < 4 or y1 - y0 < 4:
        return None
    return x0, y0, x1, y1


def _soft_coverage(s: np.ndarray, pur: np.ndarray, rho: np.ndarray):
    """(coverage w (h, w) float32 in [0, 1], disc level, ring level, noise of the score over the
    disc) from the window's score ``s``, purity ``pur`` and normalised radius ``rho``; None when
    the disc does not stand out from the ring."""
    inner, ring = rho <= 0.5, (rho >= 1.08) & (rho <= 1.22)
    if inner.sum() < 3 or ring.sum() < 4:
        return None
    fg, bg = float(np.percentile(s[inner], 25)), float(np.median(s[ring]))
    noise = float(1.4826 * np.median(np.abs(s[inner] - np.median(s[inner])))) + 1e-4
    if fg - bg <= 0:
        return None
    w_raw = (s - bg) / (fg - bg)
    w = np.clip(w_raw, 0.0, 1.0).astype(np.float32)
    w[rho > 1.3] = 0.0
    w[w_raw > MAX_SCORE_RATIO] = 0.0      # far redder (bluer) than the disc: not the disc
    # an occluder that merely leans toward the class colour (orange beside red) scores high
    # too: keep the pixels about as pure as the disc itself
    p_disc = float(np.median(pur[inner]))
    if p_disc > 0:
        w[pur < PURITY_SHARE * p_disc] = 0.0
    return w, fg, bg, noise


def _disc_component(w: np.ndarray, ci: int, cj: int) -> np.ndarray | None:
    """``w`` restricted to the connected component (w > 0.5) at window pixel (row ``ci``, column
    ``cj``) (else the largest one), dilated by two pixels; None without any component."""
    n, lab = cv2.connectedComponents((w > 0.5).astype(np.uint8), connectivity=8)
    if n < 2:
        return None
    k = lab[min(max(ci, 0), lab.shape[0] - 1), min(max(cj, 0), lab.shape[1] - 1)]
    if k == 0:  # centre not on the disc: take the largest component
        k = 1 + int(np.argmax(np.bincount(lab.ravel())[1:]))
    region = cv2.dilate((lab == k).astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
    return np.where(region, w, 0.0)


def _moments(w: np.ndarray, xs: np.ndarray, ys: np.ndarray):
    """(area, mean x, mean y, var x, var y, cov xy) of the coverage ``w`` (variances include the
    1/12 px^2 of the pixel footprint); None below 3 px of area."""
    area = float(w.sum())
    if area < 3:
        return None
    mx, my = float((w * xs).sum() / area), float((w * ys).sum() / area)
    vxx = float((w * (xs - mx) ** 2).sum() / area) + 1 / 12
    vyy = float((w * (ys - my) ** 2).sum() / area) + 1 / 12
    vxy = float((w * (xs - mx) * (ys - my)).sum() / area)
    return area, mx, my, vxx, vyy, vxy


def _quality(area: float, det: float, hw: float, hh: float, contrast: float) -> float:
    """Contrast x ellipse shape x agreement with the detector's box, each in [0, 1]."""
    ellipse_area = 4 * np.pi * np.sqrt(det)
    box_area = np.pi * hw * hh
    shape_ok = min(area / ellipse_area, ellipse_area / area)      # 1 for an ellipse
    box_ok = min(area / box_area, box_area / area)                # 1 when it fills the box's ellipse
    q_contrast = float(np.clip((contrast - 2) / 4, 0, 1))
    q_shape = float(np.clip((shape_ok - 0.85) / 0.13, 0, 1))
    q_box = float(np.clip((box_ok - 0.4) / 0.3, 0, 1))
    return q_contrast * q_shape * q_box


def _refine_once(image: np.ndarray, box, class_id: int, min_quality: float,
                 edge_bias_px: float) -> Refined:
    box = _checked_box(image, box)
    h_img, w_img = image.shape[:2]
    fallback = Refined(center=np.array([(box[0] + box[2]) / 2, (box[1] + box[3]) / 2]), box=box.copy(),
                       quality=0.0, refined=False)
    cx, cy = (box[0] + box[2]) / 2, (box[1] + box[3]) / 2
    hw, hh = max((box[2] - box[0]) / 2, 1.0), max((box[3] - box[1]) / 2, 1.0)
    win = _window(cx, cy, hw, hh, w_img, h_img)
    if win is None:
        return fallback
    x0, y0, x1, y1 = win
    s, pur = score_and_purity(image[y0:y1, x0:x1], class_id)
    ys, xs = np.mgrid[y0:y1, x0:x1].astype(np.float64)
    rho = np.sqrt(((xs - cx) / hw) ** 2 + ((ys - cy) / hh) ** 2)  # 1 on the box's inscribed ellipse
    coverage = _soft_coverage(s, pur, rho)
    if coverage is None:
        return fallback
    w, fg, bg, noise = coverage
    w = _disc_component(w, int(round(cy)) - y0, int(round(cx)) - x0)
    moments = None if w is None else _moments(w, xs, ys)
    if moments is None:
        return fallback
    area, mx, my, vxx, vyy, vxy = moments
    det = vxx * vyy - vxy ** 2
    if det <= 0:
        return fallback
    quality = _quality(area, det, hw, hh, (fg - bg) / noise)
    if quality < min_quality:
        return Refined(center=fallback.center, box=fallback.box, quality=quality, refined=False)
    ex, ey = 2 * np.sqrt(vxx) + edge_bias_px, 2 * np.sqrt(vyy) + edge_bias_px
    rbox = np.array([mx - ex, my - ey, mx + ex, my + ey])
    rbox = np.clip(rbox, -0.5, np.array([w_img, h_img, w_img, h_img]) - 0.5)
    return Refined(center=np.array([mx, my]), box=rbox, quality=quality, refined=True)
