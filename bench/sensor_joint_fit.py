"""Tried for Bayer cameras and not shipped: a joint edge fit of every channel at its own sites, and
coverage passes that take the demosaic's widening off the disc's moments. Figures and the reasons
they were dropped: bench/results/sensor_effects/README.md ("Tried").

    python bench/sensor_joint_fit.py --variant NAME DATASET [DATASET ...] --out RESULTS.json
                                     [any option of bench/sensor_effects.py]
    python bench/sensor_joint_fit.py --centres N DATASET [DATASET ...]

The variant replaces the refinement the detector runs when it is told a Bayer pattern (and no JPEG:
``detector.centre_camera.refine_centre_camera``); everything else is ``bench/sensor_effects.py``.
Variants (:data:`VARIANTS`):

- ``joint``: the shipped coverage passes, then :func:`fit_disc_joint`: one disc geometry (centre,
  ellipse, edge width) fitted to every channel at its own sites (R at R, G at both G sites, B at B),
  each channel with its own disc level (a plane) and ring level, each sample weighted by the inverse
  of its channel's noise (robust spread over the disc and the ring at its sites), so that a channel
  adds edge evidence in proportion to its contrast-to-noise squared; a channel whose contrast is
  under ``MIN_CHANNEL_CNR`` noise sigmas is left out. Band, usable mask and acceptance are those of
  ``centre.fit_disc_edge`` on the class's own channel. A refused fit returns the coverage centroid.
- ``joint-reweighted``: ``joint``, then a second fit from the first with each channel weighted by
  the inverse RMS of its residual in the first (noise plus what the model misses of it).
- ``joint-quality``: ``joint`` after coverage passes whose moments are less ``DEMOSAIC_BLUR_PX2``
  per axis (:func:`coverage_pass`): the quality's shape term, the fit's first ellipse and the box.
- ``joint-quality-strict``: ``joint-quality``, and a refused fit returns the marker unrefined.

``--centres N``: the centre errors alone on the first N test frames, every refinement on the same
detector boxes (the shipped detector without its refinement), against the labels' outline
centroids: per scene, effect and refinement, the markers left unrefined and the median and RMS
error (px), as a markdown table (:func:`centre_table`).

Pixel convention: OpenCV (the centre of the top-left pixel is (0, 0)); values linear (8-bit sRGB
through ``centre._SRGB_TO_LINEAR``).
"""
from __future__ import annotations

import sys
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np

from dockfactory.core.cfa import channel_map
from dockfactory.detector import centre, centre_camera
from dockfactory.detector.centre import CLASS_CHANNEL, EDGE_BIAS_PX, Refined

MIN_CHANNEL_CNR = 2.0   # another channel joins the fit when |disc - ring| is at least this many noise sigmas
# px^2 a bilinear demosaic adds per axis to the coverage's second moments: 3 pixels in 4 of a channel
# are interpolated from neighbours 1 px away (0 at own sites; 1 px^2 along the axis of two
# neighbours, on both axes for four diagonal ones): 0.5 on average over the 2x2 block.
DEMOSAIC_BLUR_PX2 = 0.5
_GEOMETRY, _LEVELS = 6, 4   # centre (2), ellipse (3), log edge width; per channel f0, f1, f2, ring


@dataclass(frozen=True)
class SiteSamples:
    """The fit's data: per sample position ``x``, ``y`` (px from the coverage centroid), linear value
    ``s``, channel slot ``k`` and weight ``wt``, all (n,); ``levels`` (m, 2) start disc and ring
    level per slot, slot 0 the class's own channel."""
    x: np.ndarray
    y: np.ndarray
    s: np.ndarray
    k: np.ndarray
    wt: np.ndarray
    levels: np.ndarray


def channel_levels(level: np.ndarray, sites: np.ndarray, rho: np.ndarray) -> tuple[float, float, float] | None:
    """(disc level, ring level, noise) of one channel's ``level`` (h, w) at ``sites`` (h, w) bool:
    medians over the inner half of the pass's box (``rho`` <= 0.5) and its ring annulus (1.08-1.22),
    noise the mean of their robust spreads (1.4826 MAD) + 1e-4; None under 2 samples in either."""
    inner, ring = level[(rho <= 0.5) & sites], level[(rho >= 1.08) & (rho <= 1.22) & sites]
    if inner.size < 2 or ring.size < 2:
        return None
    fg, bg = float(np.median(inner)), float(np.median(ring))
    mad = np.median(np.abs(inner - fg)) + np.median(np.abs(ring - bg))
    return fg, bg, float(1.4826 * 0.5 * mad) + 1e-4


def site_samples(lin: np.ndarray, cmap: np.ndarray, win, own: int, band: np.ndarray) -> SiteSamples | None:
    """Samples of every channel with contrast at its own sites inside ``band`` (h, w) bool, the class
    channel ``own`` first. ``lin`` (h, w, 3) linear window of the image, ``cmap`` (h, w) its channel
    map, ``win`` the pass's ``centre._Window``. None when the class channel has no disc above its ring."""
    dx, dy = win.xs - win.centre[0], win.ys - win.centre[1]
    parts, levels = [], []
    for ch in (own, *(c for c in range(3) if c != own)):
        lv = channel_levels(lin[..., ch], cmap == ch, win.rho)
        if ch == own and (lv is None or not lv[0] > lv[1]):
            return None
        if lv is None or (ch != own and abs(lv[0] - lv[1]) < MIN_CHANNEL_CNR * lv[2]):
            continue
        sel = band & (cmap == ch)
        n = int(sel.sum())
        parts.append((dx[sel], dy[sel], lin[..., ch][sel], np.full(n, len(levels)), np.full(n, 1.0 / lv[2])))
        levels.append(lv[:2])
    x, y, s, k, wt = (np.concatenate(v) for v in zip(*parts))
    return SiteSamples(x=x, y=y, s=s.astype(np.float64), k=k, wt=wt, levels=np.array(levels))


def fit_disc_joint(image: np.ndarray, win, class_id: int, cfa: str, reweight: bool = False) -> np.ndarray | None:
    """Centre (2,) float64 px of the disc in ``win`` (a ``centre._Window`` of ``image`` (H, W, 3) uint8
    sRGB) fitted to every channel at its own sites of pattern ``cfa``; with ``reweight`` a second fit
    weighted by each channel's residual RMS. None when there is nothing to fit or
    ``centre._fit_accepted`` refuses it (geometry and the class channel's levels)."""
    m0 = centre._inverse_2x2(4 * win.cov)
    d0, _ = centre._sampson(win.xs - win.centre[0], win.ys - win.centre[1], m0[0, 0], m0[0, 1], m0[1, 1])
    y0, x0 = int(win.ys[0, 0]), int(win.xs[0, 0])
    h, w = win.s.shape
    lin = centre._SRGB_TO_LINEAR[image[y0:y0 + h, x0:x0 + w]]
    cmap = channel_map(cfa, *image.shape[:2])[y0:y0 + h, x0:x0 + w]
    c = CLASS_CHANNEL[class_id]
    lv = channel_levels(lin[..., c], cmap == c, win.rho)
    if lv is None or not lv[0] > lv[1]:
        return None
    band = ((d0 > -centre.FIT_BAND_IN_PX) & (d0 < centre.FIT_BAND_OUT_PX)
            & centre._usable(lin[..., c], win.pur, win.rho, lv[0], lv[1]))
    data = site_samples(lin, cmap, win, c, band)
    if data is None or data.x.size < 20:
        return None
    p = _levenberg_marquardt(np.concatenate([[0.0, 0.0, m0[0, 0], m0[0, 1], m0[1, 1], np.log(0.2)],
                                             *([f, 0.0, 0.0, b] for f, b in data.levels)]), data)
    if p is not None and reweight:
        r = _residual(p, data)[0] / data.wt
        count = np.maximum(np.bincount(data.k, minlength=len(data.levels)), 1)
        rms = np.sqrt(np.bincount(data.k, r * r, minlength=len(data.levels)) / count)
        p = _levenberg_marquardt(p, replace(data, wt=1.0 / (rms[data.k] + 1e-4)))
    if p is None or not centre._fit_accepted(p[:_GEOMETRY + _LEVELS], m0):
        return None
    return win.centre + p[:2]


def _residual(p: np.ndarray, d: SiteSamples):
    """(weighted residual (n,), the values the Jacobian needs) of parameters ``p``: c (2, px from
    the centroid), M (3, px^-2), log sigma, then per channel f0, f1, f2, b (``centre.fit_disc_edge``'s
    model, one disc level plane and ring level per channel)."""
    ex, ey = d.x - p[0], d.y - p[1]
    dist, (gx, gy, gn) = centre._sampson(ex, ey, p[2], p[3], p[4])
    sigma = np.exp(np.clip(p[5], -3.0, 2.0))
    phi = 1.0 / (1.0 + np.exp(np.clip(dist / sigma, -60.0, 60.0)))    # 1 inside, 0 outside
    lv = p[_GEOMETRY:].reshape(-1, _LEVELS)[d.k]
    level = lv[:, 0] + lv[:, 1] * d.x + lv[:, 2] * d.y - lv[:, 3]
    return d.wt * (d.s - (lv[:, 3] + level * phi)), (ex, ey, dist, gx, gy, gn, sigma, phi, level)


def _jacobian(p: np.ndarray, d: SiteSamples, aux) -> np.ndarray:
    """(6 + 4 m, n) derivatives of the weighted model: geometry rows as ``centre._edge_jacobian``,
    each channel's level rows non-zero at its own samples only."""
    ex, ey, dist, gx, gy, gn, sigma, phi, level = aux
    k = -level * phi * (1 - phi) / (sigma * gn)
    dh = dist / gn
    hx, hy = (p[2] * gx + p[3] * gy) * dh, (p[3] * gx + p[4] * gy) * dh
    j = np.zeros((p.size, d.x.size))
    j[0], j[1] = k * (hx - gx), k * (hy - gy)
    j[2] = k * ex * (0.5 * ex - dist * gx)
    j[3] = k * (ex * ey - dist * (gx * ey + gy * ex))
    j[4] = k * ey * (0.5 * ey - dist * gy)
    j[5] = -k * gn * dist if -3.0 < p[5] < 2.0 else 0.0
    n, row = np.arange(d.x.size), _GEOMETRY + _LEVELS * d.k
    j[row, n], j[row + 1, n], j[row + 2, n], j[row + 3, n] = phi, phi * d.x, phi * d.y, 1 - phi
    return j * d.wt


def _levenberg_marquardt(p: np.ndarray, d: SiteSamples) -> np.ndarray | None:
    """Weighted least squares from ``p`` (``centre.FIT_ITERATIONS`` steps at most, stopping below a
    0.002 px centre step); None when not finite."""
    r, aux = _residual(p, d)
    cost, lam = float(r @ r), 1e-3
    for _ in range(centre.FIT_ITERATIONS):
        j = _jacobian(p, d, aux)
        h, g = j @ j.T, j @ r
        damp = np.diag(np.diag(h) + 1e-12)
        for _ in range(8):
            solved, step = cv2.solve(h + lam * damp, g, flags=cv2.DECOMP_CHOLESKY)
            step = step.ravel()
            if solved:
                r_new, aux_new = _residual(p + step, d)
                if float(r_new @ r_new) < cost:
                    break
            lam *= 10.0
        else:
            break
        p, r, aux, cost, lam = p + step, r_new, aux_new, float(r_new @ r_new), max(lam / 10.0, 1e-7)
        if abs(step[0]) + abs(step[1]) < 2e-3:
            break
    return p if np.isfinite(p).all() else None


def coverage_pass(image: np.ndarray, box, class_id: int, min_quality: float, blur_px2: float):
    """``centre._refine_once`` ((Refined, ``centre._Window`` or None)) with the coverage's second
    moments less ``blur_px2`` px^2 per axis (floored at 1/12) before the quality, the window's
    ellipse and the box are taken from them. ``box``: (4,) [x0, y0, x1, y1] px."""
    result, win = centre._refine_once(image, box, class_id, 0.0 if blur_px2 else min_quality, EDGE_BIAS_PX)
    if win is None or not blur_px2:
        return result, win
    box = np.asarray(box, dtype=np.float64)
    cx, cy = (box[0] + box[2]) / 2, (box[1] + box[3]) / 2
    hw, hh = max((box[2] - box[0]) / 2, 1.0), max((box[3] - box[1]) / 2, 1.0)
    w, fg, bg, noise = centre._soft_coverage(win.s, win.pur, win.rho)
    w = centre._disc_component(w, int(round(cy)) - int(win.ys[0, 0]), int(round(cx)) - int(win.xs[0, 0]))
    vxx, vyy = max(win.cov[0, 0] - blur_px2, 1 / 12), max(win.cov[1, 1] - blur_px2, 1 / 12)
    cov = np.array([[vxx, win.cov[0, 1]], [win.cov[0, 1], vyy]])
    det = vxx * vyy - cov[0, 1] ** 2
    quality = centre._quality(float(w.sum()), det, hw, hh, (fg - bg) / noise) if det > 0 else 0.0
    if quality < min_quality:
        return Refined(center=np.array([cx, cy]), box=box.copy(), quality=quality, refined=False), None
    return (Refined(center=result.center, box=_moment_box(image, result.center, cov), quality=quality,
                    refined=True), replace(win, cov=cov))


def _moment_box(image: np.ndarray, centre_px: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """(4,) px: half-extents 2 sqrt(variance) + ``EDGE_BIAS_PX`` around ``centre_px``, clipped."""
    h_img, w_img = image.shape[:2]
    half = np.array([cov[0, 0], cov[1, 1]]) ** 0.5 * 2 + EDGE_BIAS_PX
    return np.clip(np.concatenate([centre_px - half, centre_px + half]), -0.5,
                   np.array([w_img, h_img, w_img, h_img]) - 0.5)


# name -> (moments less px^2, reweighted second fit, a refused fit leaves the marker unrefined)
VARIANTS = {"joint": (0.0, False, False), "joint-reweighted": (0.0, True, False),
            "joint-quality": (DEMOSAIC_BLUR_PX2, False, False),
            "joint-quality-strict": (DEMOSAIC_BLUR_PX2, False, True)}


def refine_variant(name: str, image: np.ndarray, box, class_id: int, cfa: str | None = None,
                   jpeg: bool = False, min_quality: float = 0.3) -> Refined:
    """``centre_camera.refine_centre_camera``'s contract, the variant ``name`` with a pattern and no
    JPEG, the shipped refinement otherwise."""
    if cfa is None or jpeg:
        return centre_camera.refine_centre_camera(image, box, class_id, cfa, jpeg, min_quality)
    blur, reweight, strict = VARIANTS[name]
    channel_map(cfa, 2, 2)
    first, win = coverage_pass(image, box, class_id, min_quality, blur)
    if not first.refined:
        return first
    second, win2 = coverage_pass(image, first.box, class_id, min_quality, blur)
    if second.refined:
        first, win = second, win2
    fitted = fit_disc_joint(image, win, class_id, cfa, reweight)
    if fitted is None:
        return replace(first, refined=False) if strict else first
    return Refined(center=fitted, box=_moment_box(image, fitted, win.cov), quality=first.quality, refined=True)


def _refiners() -> dict:
    """Refinement name -> f(image, box, class_id): the shipped one (plain without a pattern, told
    RGGB otherwise) and every variant told RGGB."""
    out = {"shipped": lambda i, b, c, cfa: centre_camera.refine_centre_camera(i, b, c, cfa)}
    for name in VARIANTS:
        out[name] = (lambda n: lambda i, b, c, cfa: refine_variant(n, i, b, c, cfa))(name)
    return out


def centre_table(roots: list[str], frames: int, effects=("three-chip", "bayer-bilinear", "bayer-mhc")) -> str:
    """Markdown: per dataset, effect and refinement (``_refiners``, told RGGB; a three-chip image
    through the plain refinement too), markers left unrefined / detections, median and RMS centre
    error (px) of the fully visible markers (``sensor_effects.centre_errors``, an unrefined one at
    its box centre)."""
    import sensor_effects as se
    from dockfactory.core.resources import shipped_weights
    from dockfactory.detector.infer import MarkerDetector
    from dockfactory.generator.dataset_open import Dataset
    from dockfactory.generator.exr import read_passes
    detector = MarkerDetector(shipped_weights(), refine=False)
    lines = ["| scene | effect | refinement | unrefined | median px | RMS px |",
             "| --- | --- | --- | --- | --- | --- |"]
    for root in roots:
        ds = Dataset.open(root, full=False)
        for effect in effects:
            images = {}
            for fid in ds.frames("test")[:frames]:
                image = se.delivered(read_passes(ds.root / "exr" / f"{fid}.exr").rgb, ds.labels[fid], effect)
                images[fid] = (image, detector.detect(image))
            named = [("plain", None, "shipped")] if effect == "three-chip" else []
            for label, cfa, name in named + [(n, "RGGB", n) for n in _refiners()]:
                refine, errs, unrefined, n = _refiners()[name], [], 0, 0
                for fid, (image, dets) in images.items():
                    rows = []
                    for d in dets:
                        r = refine(image, np.array(d["bbox_detector_px"]), d["class_id"], cfa)
                        rows.append({"class_id": d["class_id"], "center_px": r.center.tolist()})
                        unrefined, n = unrefined + (not r.refined), n + 1
                    errs += [np.hypot(dx, dy) for _, dx, dy in se.centre_errors(rows, ds.labels[fid])]
                e = np.array(errs)
                lines.append(f"| {ds.config.dataset.name} | {effect} | {label} | {unrefined}/{n} | "
                             f"{np.median(e):.3f} | {np.sqrt(np.mean(e ** 2)):.3f} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    if "--centres" in argv:
        i = argv.index("--centres")
        print(centre_table(argv[:i] + argv[i + 2:], int(argv[i + 1])))
        return 0
    if "--variant" not in argv or argv.index("--variant") + 1 >= len(argv):
        print(__doc__.split("\n\n")[1], file=sys.stderr)
        return 2
    i = argv.index("--variant")
    name = argv[i + 1]
    if name not in VARIANTS:
        print(f"--variant must be one of {', '.join(VARIANTS)}, got {name!r}", file=sys.stderr)
        return 2
    import sensor_effects
    from dockfactory.detector import infer
    infer.refine_centre_camera = lambda *a, **k: refine_variant(name, *a, **k)
    return sensor_effects.main(argv[:i] + argv[i + 2:])


if __name__ == "__main__":
    sys.exit(main())
