"""Label-aware sampling's control variate: a marker region's antialiasing noise taken out by its
exact coverage (pure, no bpy).

A pixel on a marker's edge is the filter-weighted mean of its samples; which class each sample
lands on (disc, ring, anything else) is random, and at a few dozen samples that draw, not the
light, is almost all the noise an edge fit sees (docs/rendering.md). Cycles reports it: the
coverage AOV of the region's render (blender_scenes.coverage) is the share of the same samples
that landed on each class (``sampled``), and a render of that AOV alone at many samples is the
share they converge to (``exact``). With the colour of each class near the pixel (``radiance``)
the corrected pixel is ``rgb + sum_k (exact_k - sampled_k) radiance_k``: the colour the pixel
would have had had its samples landed in the exact proportions. ``sampled`` is unbiased for
``exact``, so the correction has mean zero whatever the class colours: a poor colour estimate
leaves noise in, it adds no bias. What it leaves, the light's noise of each pixel's own samples,
can be shared between the marker's pixels (``smoothing_px``; docs/rendering.md, "The light smoothing").
"""
from __future__ import annotations

import numpy as np

from dockfactory.core.cv import cv2

LOCAL_SIGMA_PX = 2.0     # the class colours are fitted over a Gaussian neighbourhood of this sigma
RIDGE = 0.02             # toward the region-wide colours where a class is under ~2 % of the neighbourhood
COVERED = 1e-3           # a pixel a disc or ring covers more of than this is the marker's
MARKER_REACH_PX = 2.0    # with a denoiser, its colour gives way to the denoised one over this many pixels
MISFIT_SIGMAS = 12.0     # a residual beyond this many robust sigmas is a miss of the class colours, not noise
MIN_CLASS_PIXELS = 16    # a class with fewer marker pixels is judged by the marker's pooled sigma


def _classes(coverage: np.ndarray) -> np.ndarray:
    """(h, w, 3) float64: disc, ring and the rest, from (h, w, 2) disc and ring coverage."""
    cov = np.clip(coverage.astype(np.float64), 0.0, 1.0)
    rest = np.clip(1.0 - cov[..., 0] - cov[..., 1], 0.0, 1.0)
    return np.concatenate([cov, rest[..., None]], axis=-1)


def _kernel(sigma: float) -> np.ndarray:
    """The 1-D Gaussian of :func:`_blur` (normalised, 4 sigma each side)."""
    return cv2.getGaussianKernel(2 * int(np.ceil(4 * sigma)) + 1, sigma, cv2.CV_64F)


def _blur(a: np.ndarray, sigma: float) -> np.ndarray:
    """Gaussian blur of each trailing channel of ``a`` (h, w, ...), reflected at the border."""
    flat = a.reshape(a.shape[0], a.shape[1], -1)
    k = _kernel(sigma)
    out = np.stack([cv2.sepFilter2D(flat[..., i], cv2.CV_64F, k, k, borderType=cv2.BORDER_REFLECT)
                    for i in range(flat.shape[-1])], axis=-1)
    return out.reshape(a.shape)


def class_radiance(rgb: np.ndarray, exact: np.ndarray, sigma_px: float = LOCAL_SIGMA_PX,
                   ridge: float = RIDGE) -> np.ndarray:
    """(h, w, 3 classes, 3 channels): each class's colour near each pixel, the local least-squares
    unmixing of ``rgb`` (h, w, 3) by the ``exact`` class shares (h, w, 3) over a Gaussian
    neighbourhood that leaves the pixel itself out (its own coverage draw must not steer its
    correction), pulled toward the region-wide unmixing by ``ridge`` (a class absent nearby)."""
    c = exact
    outer = c[..., :, None] * c[..., None, :]                       # (h, w, 3, 3)
    cross = c[..., :, None] * rgb.astype(np.float64)[..., None, :]  # (h, w, 3 classes, 3 ch)
    eye = np.eye(3)
    global_l = np.linalg.solve(outer.mean(axis=(0, 1)) + 1e-6 * eye, cross.mean(axis=(0, 1)))   # (3, 3)
    k = _kernel(sigma_px)
    own = float(k[len(k) // 2, 0]) ** 2                             # the pixel's own weight in the blur
    a = _blur(outer, sigma_px) - own * outer + ridge * eye
    b = _blur(cross, sigma_px) - own * cross + ridge * global_l
    return np.linalg.solve(a, b)


def _misfit(residual: np.ndarray, on: np.ndarray, exact: np.ndarray) -> np.ndarray:
    """(h, w) bool: pixels whose residual no light noise explains (beyond :data:`MISFIT_SIGMAS`
    robust sigmas in any channel: where the classes' local colours miss, next to an occluder for
    one) and their 8 neighbours. The sigma is each class's own (the pixels ``on`` whose largest
    ``exact`` share is that class's; all of ``on`` for a class of under :data:`MIN_CLASS_PIXELS`):
    a bright disc's light noise is several times a dark ring's, and one sigma pooled over both
    takes the bright class's ordinary noise for misses (bench/results/marker_sampling/README.md)."""
    group = np.argmax(_classes(exact), axis=-1)
    bad = np.zeros(on.shape, dtype=bool)
    for k in range(3):
        part = on & (group == k)
        if not part.any():
            continue
        vals = residual[part] if part.sum() >= MIN_CLASS_PIXELS else residual[on]
        med = np.median(vals, axis=0)
        sigma = 1.4826 * np.median(np.abs(vals - med), axis=0) + 1e-12
        bad |= part & (np.abs(residual - med) > MISFIT_SIGMAS * sigma).any(axis=-1)
    return cv2.dilate(bad.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0


def smoothed_on_marker(residual: np.ndarray, exact: np.ndarray, sigma_px: float) -> np.ndarray:
    """``residual`` (h, w, 3) with every marker pixel (:func:`marker_weight` 1) replaced by the
    Gaussian (``sigma_px``) mean of the marker pixels around it; the rest as it is. Only marker
    pixels are averaged, so the paint's noise beyond the marker never enters its edge; a pixel the
    light's noise cannot explain (:func:`_misfit`) is neither averaged nor spread: the classes'
    colours miss there, and sharing that miss would move the edges around it."""
    on = marker_weight(exact) >= 1.0
    if not on.any():
        return residual
    on = (on & ~_misfit(residual, on, exact)).astype(np.float64)
    weight = _blur(on, sigma_px)
    mean = _blur(residual * on[..., None], sigma_px) / np.maximum(weight, 1e-12)[..., None]
    return np.where(on[..., None] > 0, mean, residual)


def coverage_corrected(rgb: np.ndarray, sampled: np.ndarray, exact: np.ndarray,
                       smoothing_px: float = 0.0) -> np.ndarray:
    """The region's colour ``rgb`` (h, w, 3, float linear) with its antialiasing noise taken out:
    ``sampled`` and ``exact`` are the (h, w, 2) disc and ring coverage of its samples and of the
    converged coverage render; with ``smoothing_px`` > 0 the light noise left on the marker
    smoothed over that sigma (px; :func:`smoothed_on_marker`); a new float32 array, never below 0.
    ValueError when the shapes differ (a coverage render of another region must not pass
    silently)."""
    if rgb.shape[:2] != sampled.shape[:2] or rgb.shape[:2] != exact.shape[:2]:
        raise ValueError(f"coverage of shape {sampled.shape[:2]} / {exact.shape[:2]} for a region of {rgb.shape[:2]}")
    c, s = _classes(exact), _classes(sampled)
    radiance = class_radiance(rgb[..., :3], c)
    if smoothing_px <= 0:
        delta = np.einsum("hwk,hwkc->hwc", c - s, radiance)
        return np.maximum(rgb[..., :3] + delta, 0.0).astype(np.float32)
    residual = rgb[..., :3].astype(np.float64) - np.einsum("hwk,hwkc->hwc", s, radiance)
    out = np.einsum("hwk,hwkc->hwc", c, radiance) + smoothed_on_marker(residual, exact, smoothing_px)
    return np.maximum(out, 0.0).astype(np.float32)


def marker_weight(exact: np.ndarray, reach_px: float = MARKER_REACH_PX) -> np.ndarray:
    """(h, w) float32 in [0, 1]: 1 on every pixel a disc or ring covers at all and within 1 px of
    one, falling to 0 over the next ``reach_px``: where the corrected colour replaces the
    denoised one."""
    touched = (exact[..., 0] + exact[..., 1]) > COVERED
    if not touched.any():
        return np.zeros(exact.shape[:2], np.float32)
    dist = cv2.distanceTransform((~touched).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    return np.clip(1.0 - (dist - 1.0) / reach_px, 0.0, 1.0).astype(np.float32)


def corrected_region(rgb: np.ndarray, noisy: np.ndarray | None, sampled: np.ndarray,
                     exact: np.ndarray, smoothing_px: float = 0.0) -> np.ndarray:
    """A marker region's colour with the coverage correction: without a denoiser (``noisy`` None)
    :func:`coverage_corrected` of ``rgb``; with one, the correction of the colour before the
    denoiser (``noisy``) on the markers (:func:`marker_weight`), the denoised ``rgb`` on the paint
    beyond them (the denoiser follows each sample's albedo, so it keeps the coverage draw at the
    edges; the paint's light noise is what it takes); ``smoothing_px``: :func:`coverage_corrected`'s.
    (h, w, 3) float32."""
    if noisy is None:
        return coverage_corrected(rgb, sampled, exact, smoothing_px)
    w = marker_weight(exact)[..., None]
    corrected = coverage_corrected(noisy, sampled, exact, smoothing_px)
    return (w * corrected + (1.0 - w) * rgb[..., :3]).astype(np.float32)
