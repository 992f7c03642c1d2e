"""Sub-pixel marker centre (and outline box) at full resolution inside a detected box.

A marker is a red or blue disc inside a dark ring. Two coverage passes in a window around the
detector's box (linear light, a colour score normalised between ring and disc into a soft
coverage of the disc's connected component, its moments; on the luma where the colour score
cannot tell the disc from its ring: :func:`coverage_passes`) give a first ellipse, the window, the
quality and the fallback; :func:`edge_fit` then fits the projected disc to the score in a band
around that ellipse's edge (an ellipse, a blurred edge, a shaded disc level, a ring level) and
gives the centre and the edge width; :func:`finish_refined` judges it (quality in [0, 1]: contrast,
shape, agreement with the box, point symmetry; below ``min_quality`` not refined; a refused edge
fit never kept at full quality). The module's sha256 names the refinement of the weights' noise
cards (``detector.noise_card``). Why and how: docs/detector.md, "The centre refinement".
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import cv2
import numpy as np

from dockfactory.core.names import CLASS_CHANNELS

_SRGB_TO_LINEAR = np.where(np.arange(256) / 255.0 <= 0.04045, np.arange(256) / 255.0 / 12.92,
                           ((np.arange(256) / 255.0 + 0.055) / 1.055) ** 2.4).astype(np.float32)
CLASS_CHANNEL = dict(enumerate(CLASS_CHANNELS))  # class id -> RGB channel of its colour
LUMA_WEIGHTS = np.array([0.299, 0.587, 0.114], dtype=np.float32)   # JPEG's Y' (BT.601, on sRGB values)


@dataclass(frozen=True)
class Refined:
    """``center: (2,) float64 px`` and ``box: (4,) float64 px`` (OpenCV convention), quality in [0, 1],
    ``refined``: False when the centre is no trusted sub-pixel measurement (the detector's box
    kept, or the quality below the gate); ``edge_px`` the edge fit's edge width
    (Gaussian std, px; :class:`EdgeFit`), NaN when no edge fit gave the centre."""
    center: np.ndarray
    box: np.ndarray
    quality: float
    refined: bool
    edge_px: float = float("nan")


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


# The quality's shape term is 0 where the coverage's area is this share of its moments' ellipse (or
# the ellipse this share of it), 1 at 0.13 above: a disc thin for its blur (or a demosaic) widens its
# moments, so a higher floor refuses exactly the discs the thin-disc refit and noise are for
# (checked on two scenes: results/README.md, "Measurements behind the code's constants").
SHAPE_OK_MIN = 0.75
EDGE_BIAS_PX = 0.041  # px added to the moment half-extents of the box (it moves no centre): median shortfall on train frames of configs/detector.toml


@dataclass(frozen=True)
class _Window:
    """What one coverage pass measured in its window: the score ``s``, its purity ``pur``, the
    pixel coordinates ``xs``, ``ys`` and the normalised radius ``rho`` of the pass's box (all
    (h, w)), the first ellipse (centre (2,) px and covariance (2, 2) px^2 of the coverage), the
    disc and ring levels of the score, the soft coverage ``w`` (h, w) of the disc's component;
    ``luma``: the pass scored the luma (:func:`luma_score`), not the colour."""
    s: np.ndarray
    pur: np.ndarray
    xs: np.ndarray
    ys: np.ndarray
    rho: np.ndarray
    centre: np.ndarray
    cov: np.ndarray
    fg: float
    bg: float
    w: np.ndarray | None = None
    luma: bool = False


def refine_centre(image: np.ndarray, box, class_id: int, min_quality: float = 0.3,
                  edge_bias_px: float = EDGE_BIAS_PX) -> Refined:
    """Refine one detection: its sub-pixel centre, outline box and quality.

    Parameters
    ----------
    image : (H, W, 3) uint8
        RGB at full resolution (a three-chip camera's; other cameras: ``centre_camera``).
    box : (4,) array_like
        The detector's box [x0, y0, x1, y1], px, OpenCV convention (pixel centres at integers).
    class_id : int
        0 (RedA) or 1 (BlueB): the disc colour scored.
    min_quality : float
        The gate: below it the centre is returned not refined.
    edge_bias_px : float
        px added to the moment half-extents of the refined box (it moves no centre).

    Returns
    -------
    Refined
        The kept coverage pass (:func:`coverage_passes`), then :func:`edge_fit` in its window
        gives the centre and :func:`finish_refined` judges it; the box is the moment box around
        the centre.

    Raises
    ------
    ValueError
        An image that is not (H, W, 3) uint8, a box that is not finite with x1 > x0 and y1 > y0,
        or a class_id other than 0 or 1.
    """
    first, win = coverage_passes(image, box, class_id, min_quality, edge_bias_px)
    if win is None:
        return first
    fit = edge_fit(win)
    return finish_refined(image, first, win, None if fit is None else (fit.centre, fit.edge_px),
                          min_quality, edge_bias_px)


def coverage_passes(image: np.ndarray, box, class_id: int, min_quality: float,
                    edge_bias_px: float) -> tuple[Refined, "_Window | None"]:
    """(the kept coverage pass, its window; None when none was refined) of the detection ``box``:
    two passes on the colour score (the second in the window of the first refined ellipse, kept
    when refined too); when the colour score's first pass is refused, the same two passes on the
    linear luma (:func:`luma_score`). Why the luma: a disc in shadow inside a warm-lit white ring
    scores in colour about what the ring does (R - mean(G, B) of a bright warm white equals a dim
    red's), and a JPEG's half-resolution chroma smears a thin disc's colour into its ring, while the
    disc's edge against its ring stays sharp in luma. Only where the colour pass is refused: a
    luma pass replacing colour passes of low quality made the centres of thin discs worse (docs/detector.md,
    "The luma pass")."""
    first, win = _refine_once(image, box, class_id, min_quality, edge_bias_px)
    luma = not first.refined
    if luma:
        by_luma = _refine_once(image, box, class_id, min_quality, edge_bias_px, True)
        if not by_luma[0].refined:
            return first, None
        first, win = by_luma
    second, win2 = _refine_once(image, first.box, class_id, min_quality, edge_bias_px, luma)
    return (second, win2) if second.refined else (first, win)


def luma_score(rgb: np.ndarray, rho: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(score, purity) of the window ``rgb`` (h, w, 3) uint8 sRGB for the luma pass: the linear
    luma (BT.601 weights on sRGB, then linearised), negated when the disc (``rho`` <= 0.5, the
    normalised radius of the detector's box) is darker than the annulus beyond it (rho 1.08-1.22:
    a white ring), so that the disc stands above its ring as in the colour score; purity all ones
    (luma has no colour to be pure in)."""
    luma = np.rint(rgb.astype(np.float32) @ LUMA_WEIGHTS).astype(np.uint8)
    level = _SRGB_TO_LINEAR[luma].astype(np.float32)
    inner, ring = rho <= 0.5, (rho >= 1.08) & (rho <= 1.22)
    if inner.any() and ring.any() and np.median(level[inner]) < np.median(level[ring]):
        level = -level
    return level, np.ones(level.shape, np.float32)


# A refused edge fit leaves the coverage centroid at this share of the coverage pass's quality; the
# symmetry term is 1 up to ASYM_OK_PX of asymmetry and 0 from ASYM_BAD_PX, the coverage binarised and
# smoothed by SYMMETRY_BLUR_PX first so that neither shading nor pixel noise counts. One set for every
# camera class, checked on two scenes through three-chip, Bayer and JPEG cameras and on a video
# stream: bench/results/centre_quality/README.md.
REFUSED_FIT_QUALITY = 0.5
SYMMETRY_BLUR_PX = 1.0
ASYM_OK_PX = 0.30
ASYM_BAD_PX = 0.45


def finish_refined(image: np.ndarray, first: Refined, win: _Window, fitted, min_quality: float,
                   edge_bias_px: float) -> Refined:
    """The detection from the kept coverage pass (``first``, ``win``) and the edge fit's
    ``fitted`` (centre (2,) px, edge width px; None when the fit was refused: the coverage
    centroid, at ``REFUSED_FIT_QUALITY`` of the quality, not refined after a luma pass). The quality takes the disc's point
    symmetry about the centre (:func:`symmetry_quality`): a part hidden by an occluder or eaten
    by glare moves the centre toward what is left. Below ``min_quality`` the centre is returned
    not refined."""
    if fitted is None:   # a luma pass's coverage is no centre of its own (its colour pass was refused)
        share = 0.0 if win.luma else REFUSED_FIT_QUALITY
        centre, edge_px, quality = first.center, float("nan"), first.quality * share
    else:
        (centre, edge_px), quality = fitted, first.quality
    quality *= symmetry_quality(asymmetry_px(win, centre))
    out = refined_at(image, centre, win, quality, edge_bias_px, edge_px)
    return out if quality >= min_quality else replace(out, refined=False)


def asymmetry_px(win: _Window, centre: np.ndarray) -> float:
    """Mean distance (px) between the disc's edge and the edge of its copy turned 180 degrees about
    ``centre`` (2,) px: the summed absolute difference of the smoothed binarised coverage and its
    turned copy over the perimeter of a disc of the coverage's area, halved (0 for an ellipse
    centred there; a centre e px off an ellipse gives about 0.64 e)."""
    w = cv2.GaussianBlur((win.w > 0.5).astype(np.float32), (0, 0), SYMMETRY_BLUR_PX)
    cx, cy = centre[0] - win.xs[0, 0], centre[1] - win.ys[0, 0]
    turn = np.float32([[-1, 0, 2 * cx], [0, -1, 2 * cy]])
    turned = cv2.warpAffine(w, turn, (w.shape[1], w.shape[0]), flags=cv2.INTER_LINEAR, borderValue=0)
    area = max(float(win.w.sum()), 1.0)
    return float(np.abs(w - turned).sum()) / (4.0 * math.sqrt(math.pi * area))


def symmetry_quality(asymmetry: float) -> float:
    """The quality's symmetry term in [0, 1] of an ``asymmetry`` (px, :func:`asymmetry_px`)."""
    return float(np.clip((ASYM_BAD_PX - asymmetry) / (ASYM_BAD_PX - ASYM_OK_PX), 0.0, 1.0))


def refined_at(image: np.ndarray, centre: np.ndarray, win: _Window, quality: float, edge_bias_px: float,
               edge_px: float) -> Refined:
    """The refined detection at the fitted ``centre`` (2,) px: the box of the moment half-extents
    of ``win`` (plus ``edge_bias_px``) around it, clipped to the ``image``."""
    h_img, w_img = image.shape[:2]
    half = np.array([win.cov[0, 0], win.cov[1, 1]]) ** 0.5 * 2 + edge_bias_px
    rbox = np.clip(np.concatenate([centre - half, centre + half]), -0.5,
                   np.array([w_img, h_img, w_img, h_img]) - 0.5)
    return Refined(center=centre, box=rbox, quality=quality, refined=True, edge_px=float(edge_px))


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
    q_shape = float(np.clip((shape_ok - SHAPE_OK_MIN) / 0.13, 0, 1))
    q_box = float(np.clip((box_ok - 0.4) / 0.3, 0, 1))
    return q_contrast * q_shape * q_box


def _refine_once(image: np.ndarray, box, class_id: int, min_quality: float,
                 edge_bias_px: float, luma: bool = False) -> tuple[Refined, _Window | None]:
    """One coverage pass in the window of ``box`` on the colour score (``luma``: on
    :func:`luma_score`, refused unless the class's colour is the purest at the disc's centre: the
    detector's class is kept as the colour pass keeps it): (result, the window's measurements for
    the edge fit; None unless refined)."""
    box = _checked_box(image, box)
    h_img, w_img = image.shape[:2]
    fallback = Refined(center=np.array([(box[0] + box[2]) / 2, (box[1] + box[3]) / 2]), box=box.copy(),
                       quality=0.0, refined=False)
    cx, cy = (box[0] + box[2]) / 2, (box[1] + box[3]) / 2
    hw, hh = max((box[2] - box[0]) / 2, 1.0), max((box[3] - box[1]) / 2, 1.0)
    win = _window(cx, cy, hw, hh, w_img, h_img)
    if win is None:
        return fallback, None
    x0, y0, x1, y1 = win
    ys, xs = np.mgrid[y0:y1, x0:x1].astype(np.float64)
    rho = np.sqrt(((xs - cx) / hw) ** 2 + ((ys - cy) / hh) ** 2)  # 1 on the box's inscribed ellipse
    s, pur = score_and_purity(image[y0:y1, x0:x1], class_id)
    if luma:
        if not np.median(pur[rho <= 0.5]) > 0:   # the disc is not the class's colour: no luma pass
            return fallback, None
        s, pur = luma_score(image[y0:y1, x0:x1], rho)
    coverage = _soft_coverage(s, pur, rho)
    if coverage is None:
        return fallback, None
    w, fg, bg, noise = coverage
    w = _disc_component(w, int(round(cy)) - y0, int(round(cx)) - x0)
    moments = None if w is None else _moments(w, xs, ys)
    if moments is None:
        return fallback, None
    area, mx, my, vxx, vyy, vxy = moments
    det = vxx * vyy - vxy ** 2
    if det <= 0:
        return fallback, None
    quality = _quality(area, det, hw, hh, (fg - bg) / noise)
    if quality < min_quality:
        return Refined(center=fallback.center, box=fallback.box, quality=quality, refined=False), None
    ex, ey = 2 * np.sqrt(vxx) + edge_bias_px, 2 * np.sqrt(vyy) + edge_bias_px
    rbox = np.array([mx - ex, my - ey, mx + ex, my + ey])
    rbox = np.clip(rbox, -0.5, np.array([w_img, h_img, w_img, h_img]) - 0.5)
    window = _Window(s=s, pur=pur, xs=xs, ys=ys, rho=rho, centre=np.array([mx, my]),
                     cov=np.array([[vxx, vxy], [vxy, vyy]]), fg=fg, bg=bg, w=w, luma=luma)
    return Refined(center=np.array([mx, my]), box=rbox, quality=quality, refined=True), window


def _usable(s: np.ndarray, pur: np.ndarray, rho: np.ndarray, fg: float, bg: float) -> np.ndarray:
    """(h, w) bool: pixels that are disc, edge or ring, not an occluder: within 1.3 box radii, not
    far redder (bluer) than the disc (``MAX_SCORE_RATIO``), not scoring like the disc while far
    less pure than it (an orange occluder beside red)."""
    w_raw = (s - bg) / (fg - bg)
    inner = rho <= 0.5
    p_disc = float(np.median(pur[inner])) if inner.any() else 0.0
    impure = (pur < PURITY_SHARE * p_disc) & (w_raw > 0.5) if p_disc > 0 else np.zeros_like(inner)
    return (rho <= 1.3) & (w_raw <= MAX_SCORE_RATIO) & ~impure


# --- the edge fit -------------------------------------------------------------------------------

# The band and the guard were checked on two scenes that differ in geometry (bench/centre_bias.py;
# the figures: results/README.md, "Measurements behind the code's constants"). The band inside takes
# in the whole edge band the renders' denoiser reshapes; a narrower band trades BlueB's offset for RedA's.
FIT_BAND_IN_PX = 2.5   # the fit uses the pixels from this far inside the first ellipse's edge ...
FIT_BAND_OUT_PX = 1.0  # ... to this far outside it (the ring is 2.5 mm wide: 2.5-3 px here, < 1 px across flat discs)
# ... and not beyond this scale of the first ellipse: a 2.5 mm ring around a disc up to 50 mm wide
# reaches at least 1.1 of its radius, so the band's pixels are disc, edge or ring, never the paint
RING_SCALE_LIMIT = 1.1
FIT_MAX_SHIFT_PX = 0.5  # a fitted centre farther than this from the coverage centroid is refused
FIT_ITERATIONS = 8     # Levenberg-Marquardt steps at most (it stops earlier below 0.002 px)


LOGISTIC_TO_GAUSSIAN = 1.702   # the logistic edge of scale s is close to a Gaussian step of std 1.702 s
# x s^2 (s the logistic's scale): a blurred shaded disc's edge profile carries -v (grad f . n) K(d),
# v K(d) the blur's tail moment, v = 4 ln 2 s^2 where it matters (at the edge, for a logistic kernel)
BLURRED_SHADING = 4 * math.log(2)
# A disc whose fitted minor semi-axis is under this many edge widths (Gaussian std) is refitted with
# its disc level's gradient along the major axis only: across a thin blurred disc that gradient and
# a shift of the centre along the minor axis change the score nearly alike (checked on two scenes:
# results/README.md, "Measurements behind the code's constants").
THIN_DISC_EDGE_WIDTHS = 6.0


@dataclass(frozen=True)
class EdgeFit:
    """The edge fit of one disc: ``centre`` (2,) float64 px, ``edge_px`` the std (px) of the
    Gaussian step its logistic edge approximates (the optics', the pixel filter's and the
    camera's blur together), ``minor_px`` its minor semi-axis (px)."""
    centre: np.ndarray
    edge_px: float
    minor_px: float


def fit_disc_edge(win: _Window | None) -> np.ndarray | None:
    """Centre ``(2,) float64 px`` of :func:`edge_fit` on ``win``; None where it gives none."""
    fit = edge_fit(win)
    return None if fit is None else fit.centre


def edge_fit(win: _Window | None) -> EdgeFit | None:
    """The disc in the window ``win``, by least squares (:class:`EdgeFit`); None when there is
    nothing to fit or the fit is refused.

    Model of the score at pixel x (px): ``b + (f(x) - b) L(d) - v (grad f . n) K(d)`` with L the
    logistic step ``1 / (1 + exp(d / sigma))`` and K = -dL/dd, d(x) the signed distance (px, > 0
    outside) to the ellipse {x: (x - c)^T M (x - c) = 1} to first order (Sampson: ``(q - 1) /
    (2 |M (x - c)|)``) and n its outward normal, sigma the edge width (blur of the optics and the
    pixel filter), f(x) = f0 + f1 x + f2 y the disc level (shading across the disc) and b the ring
    level. The last term is what the blur does to a shaded disc (the product of the level and the
    step blurred, to first order; v = ``BLURRED_SHADING`` sigma^2): without it a shading g per px
    moved the edges, and so the centre, by about -v g / (f - b) toward the dark side. Parameters:
    c (2), M (3), log sigma, f0, f1, f2, b; Levenberg-Marquardt from the coverage ellipse, over the
    usable pixels in a band around its edge that ends at ``RING_SCALE_LIMIT`` of that ellipse
    (where that leaves no accepted fit, the band without that end). Why the end: across a disc seen
    obliquely the ring is under a pixel wide, and the paint beyond it, whose score is not the ring's
    level, entered the band's outer pixels on the thin sides and pulled the edge there: a centre
    offset fixed per marker that biased the pose (bench/results/centre_pattern/README.md). A disc
    thinner than ``THIN_DISC_EDGE_WIDTHS`` edge widths is refitted with the shading along its major
    axis only (:func:`_refit_shading_along_major`)."""
    if win is None:
        return None
    m0 = _inverse_2x2(4 * win.cov)             # uniform ellipse: covariance = M^-1 / 4
    dx, dy = win.xs - win.centre[0], win.ys - win.centre[1]
    d0, _ = _sampson(dx, dy, m0[0, 0], m0[0, 1], m0[1, 1])
    q0 = m0[0, 0] * dx * dx + 2 * m0[0, 1] * dx * dy + m0[1, 1] * dy * dy
    band = (d0 > -FIT_BAND_IN_PX) & (d0 < FIT_BAND_OUT_PX) & _usable(win.s, win.pur, win.rho, win.fg, win.bg)
    p0 = np.array([0.0, 0.0, m0[0, 0], m0[0, 1], m0[1, 1], np.log(0.2), win.fg, 0.0, 0.0, win.bg])
    p = _fit_in_band(win, m0, dx, dy, band & (q0 < RING_SCALE_LIMIT ** 2), p0)
    if p is None:
        p = _fit_in_band(win, m0, dx, dy, band, p0)
    if p is None:
        return None
    return EdgeFit(centre=win.centre + p[:2], edge_px=_edge_px(p), minor_px=_minor_px(p))


def _fit_in_band(win: _Window, m0: np.ndarray, dx: np.ndarray, dy: np.ndarray, band: np.ndarray,
                 start: np.ndarray) -> np.ndarray | None:
    """Parameters of :func:`edge_fit`'s model fitted from ``start`` to the window's pixels in
    ``band`` (h, w) bool (``dx``, ``dy``: px from the coverage centroid; ``m0`` the coverage
    ellipse), a thin disc refitted with its shading along the major axis; None under 20 pixels or
    when refused."""
    if band.sum() < 20:
        return None
    x, y, s = dx[band], dy[band], win.s[band].astype(np.float64)
    p = _levenberg_marquardt(start, x, y, s)
    if p is None or not _fit_accepted(p, m0, win):
        return None
    if _minor_px(p) < THIN_DISC_EDGE_WIDTHS * _edge_px(p):
        q = _refit_shading_along_major(p, x, y, s)
        p = q if q is not None and _fit_accepted(q, m0, win) else p
    return p


def _edge_px(p: np.ndarray) -> float:
    """Gaussian-equivalent std (px) of the fitted logistic edge of parameters ``p``."""
    return LOGISTIC_TO_GAUSSIAN * float(np.exp(np.clip(p[5], -3.0, 2.0)))


def _minor_px(p: np.ndarray) -> float:
    """Minor semi-axis (px) of the fitted ellipse of parameters ``p`` (1 / sqrt of M's largest
    eigenvalue)."""
    return float(_eigenvalues_2x2(np.array([[p[2], p[3]], [p[3], p[4]]]))[1]) ** -0.5


def _refit_shading_along_major(p: np.ndarray, x: np.ndarray, y: np.ndarray, s: np.ndarray) -> np.ndarray | None:
    """Parameters ``p`` refitted with the disc level's gradient held along the ellipse's major
    axis (its component along the minor axis fixed at 0), in the original frame; None when not
    finite. The fit runs in coordinates rotated onto the axes of ``p``'s ellipse."""
    m = np.array([[p[2], p[3]], [p[3], p[4]]])
    t = 0.5 * np.arctan2(2 * p[3], p[2] - p[4])     # direction of M's largest eigenvalue: the minor axis
    c, sn = np.cos(t), np.sin(t)
    rot = np.array([[-sn, c], [-c, -sn]])            # rows: major, minor axis (a rotation, no LAPACK)
    mr = rot @ m @ rot.T
    grad = rot @ p[7:9]
    q0 = np.array([*(rot @ p[:2]), mr[0, 0], mr[0, 1], mr[1, 1], p[5], p[6], grad[0], 0.0, p[9]])
    xr, yr = rot @ np.stack([x, y])
    free = np.ones(10, bool)
    free[8] = False
    q = _levenberg_marquardt(q0, xr, yr, s, free)
    if q is None:
        return None
    mq = rot.T @ np.array([[q[2], q[3]], [q[3], q[4]]]) @ rot
    return np.array([*(rot.T @ q[:2]), mq[0, 0], mq[0, 1], mq[1, 1], q[5], q[6], *(rot.T @ q[7:9]), q[9]])


def _inverse_2x2(m: np.ndarray) -> np.ndarray:
    """Inverse of a symmetric 2 x 2 matrix (no LAPACK: its threads cost milliseconds per call on
    a busy machine)."""
    det = m[0, 0] * m[1, 1] - m[0, 1] * m[1, 0]
    return np.array([[m[1, 1], -m[0, 1]], [-m[1, 0], m[0, 0]]]) / det


def _eigenvalues_2x2(m: np.ndarray) -> np.ndarray:
    """Ascending eigenvalues of a symmetric 2 x 2 matrix."""
    half_trace, diff = (m[0, 0] + m[1, 1]) / 2, (m[0, 0] - m[1, 1]) / 2
    root = np.hypot(diff, m[0, 1])
    return np.array([half_trace - root, half_trace + root])


def _sampson(ex, ey, m11, m12, m22):
    """(d, (gx, gy, gn)): first-order signed distance (px) of points (ex, ey) (px from the
    centre) to the ellipse q = e^T M e = 1, and g = M e, |g|."""
    gx, gy = m11 * ex + m12 * ey, m12 * ex + m22 * ey
    gn = np.sqrt(gx * gx + gy * gy) + 1e-12
    return (ex * gx + ey * gy - 1) / (2 * gn), (gx, gy, gn)


def _edge_residual(p: np.ndarray, x: np.ndarray, y: np.ndarray, s: np.ndarray):
    """(residual s - model (n,), the intermediate values the Jacobian needs) of parameters ``p``
    at pixels (x, y) (px from the coverage centroid)."""
    ex, ey = x - p[0], y - p[1]
    d, (gx, gy, gn) = _sampson(ex, ey, p[2], p[3], p[4])
    sigma = np.exp(np.clip(p[5], -3.0, 2.0))       # 0.05-7.4 px
    phi = 1.0 / (1.0 + np.exp(np.clip(d / sigma, -60.0, 60.0)))    # 1 inside, 0 outside
    level = p[6] + p[7] * x + p[8] * y - p[9]
    blur = -BLURRED_SHADING * sigma * phi * (1 - phi) / gn     # x the level's gradient along g
    return (s - (p[9] + level * phi + blur * (p[7] * gx + p[8] * gy)),
            (ex, ey, d, gx, gy, gn, sigma, phi, level, blur))


def _edge_jacobian(p: np.ndarray, x: np.ndarray, y: np.ndarray, aux) -> np.ndarray:
    """(10, n) derivatives of the model (exact, the Sampson distance's normaliser included)."""
    ex, ey, d, gx, gy, gn, sigma, phi, level, blur = aux
    k = -level * phi * (1 - phi) / (sigma * gn)     # (d model / d d) / |g|
    dh = d / gn
    hx = (p[2] * gx + p[3] * gy) * dh               # d (M g)_x / |g|, d (M g)_y / |g|
    hy = (p[3] * gx + p[4] * gy) * dh
    j = np.empty((10, len(x)))
    j[0] = k * (hx - gx)                            # e = x - c: d d / d c = -(g - d M g / |g|) / |g|
    j[1] = k * (hy - gy)
    j[2] = k * ex * (0.5 * ex - d * gx)             # d d / d m = (d q / d m) / (2 |g|) - d (d |g| / d m) / |g|
    j[3] = k * (ex * ey - d * (gx * ey + gy * ex))
    j[4] = k * ey * (0.5 * ey - d * gy)
    j[5] = -k * gn * d if -3.0 < p[5] < 2.0 else 0.0  # d / d log sigma (0 where clipped)
    j[6], j[7], j[8] = phi, phi * x + blur * gx, phi * y + blur * gy
    j[9] = 1 - phi
    return j


def _levenberg_marquardt(p: np.ndarray, x: np.ndarray, y: np.ndarray, s: np.ndarray,
                        free: np.ndarray | None = None) -> np.ndarray | None:
    """Least-squares parameters from ``p``, those not ``free`` ((10,) bool; None: all free) held
    at their value; None when not finite."""
    free = np.ones(p.size, bool) if free is None else free
    r, aux = _edge_residual(p, x, y, s)
    cost, lam = float(r @ r), 1e-3
    for _ in range(FIT_ITERATIONS):
        j = _edge_jacobian(p, x, y, aux)[free]
        h, g = j @ j.T, j @ r
        damp = np.diag(np.diag(h) + 1e-12)
        for _ in range(8):
            solved, sub = cv2.solve(h + lam * damp, g, flags=cv2.DECOMP_CHOLESKY)  # no LAPACK threads
            step = np.zeros(p.size)
            step[free] = sub.ravel()
            if solved:
                r_new, aux_new = _edge_residual(p + step, x, y, s)
                cost_new = float(r_new @ r_new)
                if cost_new < cost:
                    break
            lam *= 10.0
        else:
            break                                   # no step lowers the cost: converged
        p, r, aux, cost, lam = p + step, r_new, aux_new, cost_new, max(lam / 10.0, 1e-7)
        if abs(step[0]) + abs(step[1]) < 2e-3:          # px: far below the noise of a centre
            break
    return p if np.isfinite(p).all() else None


def _fit_accepted(p: np.ndarray, m0: np.ndarray, win: _Window | None = None) -> bool:
    """The fit is the disc: its axes within 0.8-1.25 times the coverage ellipse's, an edge width
    under 3 px (a sharper edge than the model's floor of 0.05 px is fine: 2-spp renders have
    near-binary edge pixels), a disc above the ring, and its centre within ``FIT_MAX_SHIFT_PX`` of
    the coverage centroid or, given the window ``win``, of one of its :func:`coverage_anchors`
    (computed only for a fit beyond the centroid's reach)."""
    m = np.array([[p[2], p[3]], [p[3], p[4]]])
    eig, eig0 = _eigenvalues_2x2(m), _eigenvalues_2x2(m0)
    if eig[0] <= 0:
        return False
    axes_ok = bool(np.all((eig / eig0 > 0.64) & (eig / eig0 < 1.5625)))   # axis ratio 0.8-1.25
    if not (axes_ok and float(np.exp(p[5])) < 3.0 and p[6] > p[9]):
        return False
    if float(np.hypot(p[0], p[1])) < FIT_MAX_SHIFT_PX:
        return True
    if win is None:
        return False
    anchors = coverage_anchors(win)
    return float(np.min(np.hypot(anchors[:, 0] - p[0], anchors[:, 1] - p[1]))) < FIT_MAX_SHIFT_PX


def coverage_anchors(win: _Window) -> np.ndarray:
    """(k, 2) px from the coverage centroid: the centroids of the coverage binarised at half the
    disc level and of the coverage normalised by a disc level that is a plane fitted to the disc's
    pixels (refitted twice on the pixels that normalisation puts in the disc). A shading across
    the disc (a shadow's edge, a light's fall-off) pulls the soft coverage's centroid toward the
    bright side by up to a pixel on a slanted disc; these hardly move: an edge fit within reach of
    one of them is the disc's (its own model takes the shading)."""
    if win.w is None or (win.w > 0.5).sum() < 6:
        return np.zeros((1, 2))
    x, y = win.xs - win.centre[0], win.ys - win.centre[1]
    core, support = win.w > 0.5, win.w > 0
    out = [(float(x[core].mean()), float(y[core].mean()))]
    cov = None
    for _ in range(3):
        level = _plane_through(x, y, win.s, core)
        if level is None:
            break
        cov = np.clip((win.s - win.bg) / np.maximum(level - win.bg, 1e-6), 0.0, 1.0) * support
        if (cov > 0.5).sum() < 6:
            cov = None
            break
        core = cov > 0.5
    if cov is not None:
        out.append((float((cov * x).sum() / cov.sum()), float((cov * y).sum() / cov.sum())))
    return np.array(out)


def _plane_through(x: np.ndarray, y: np.ndarray, s: np.ndarray, mask: np.ndarray) -> np.ndarray | None:
    """(h, w) least-squares plane s ~ c0 + c1 x + c2 y over the pixels of ``mask``, evaluated
    everywhere (the 3 x 3 normal equations by Cramer's rule: no LAPACK); None when degenerate."""
    xm, ym, sm = (v[mask].astype(np.float64) for v in (x, y, s))
    a = np.array([[xm.size, xm.sum(), ym.sum()], [xm.sum(), (xm * xm).sum(), (xm * ym).sum()],
                  [ym.sum(), (xm * ym).sum(), (ym * ym).sum()]])
    rhs = np.array([sm.sum(), (xm * sm).sum(), (ym * sm).sum()])
    det = float(np.dot(a[0], np.cross(a[1], a[2])))
    if not np.isfinite(det) or abs(det) < 1e-9 * float(np.abs(a).max()) ** 3:
        return None
    c = []
    for k in range(3):
        m = a.copy()
        m[:, k] = rhs
        c.append(float(np.dot(m[0], np.cross(m[1], m[2]))) / det)
    return c[0] + c[1] * x + c[2] * y
