"""Edge fit of one disc to every channel of a Bayer camera, each at the sensor's own samples of it.

Pixel convention: OpenCV (the centre of the top-left pixel is (0, 0)); values are linear (8-bit
sRGB through ``centre._SRGB_TO_LINEAR``).

Why and how: docs/detector.md, "The joint edge fit of a Bayer camera".
"""
from __future__ import annotations

from dataclasses import dataclass, replace

from dockfactory.core.cv import cv2
import numpy as np

from dockfactory.core.camera_chain.cfa import channel_map
import dockfactory.detector.centre as centre
from dockfactory.detector.centre import CLASS_CHANNEL

MIN_CHANNEL_CNR = 2.0   # another channel joins the fit when |disc - ring| is at least this many noise sigmas
RING_FLOOR_PERCENTILE = 10.0   # the ring's level within an annulus that may hold paint (ring_floor)
RING_FLOOR_MIN_SAMPLES = 5      # fewer annulus samples than this: no floor (a percentile of a handful is one sample)
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


def site_samples(lin: np.ndarray, cmap: np.ndarray, win, ref, band: np.ndarray) -> SiteSamples | None:
    """Samples of every channel with contrast at its own sites inside ``band`` (h, w) bool, the
    reference channel first with the sign and levels of ``ref`` (:func:`reference_channel`).
    ``lin`` (h, w, 3) linear window of the image, ``cmap`` (h, w) its channel map, ``win`` the
    pass's ``centre._Window``. Another channel whose disc is darker than its ring enters negated
    (values and levels), so that every slot's disc lies above its ring (the fit's acceptance reads
    slot 0's). None when the reference channel has no contrast."""
    own, own_sign, own_levels = ref
    dx, dy = win.xs - win.centre[0], win.ys - win.centre[1]
    parts, levels = [], []
    for ch in (own, *(c for c in range(3) if c != own)):
        lv = channel_levels(lin[..., ch], cmap == ch, win.rho)
        if ch == own and (lv is None or own_levels[0] == own_levels[1]):
            return None
        if lv is None or (ch != own and abs(lv[0] - lv[1]) < MIN_CHANNEL_CNR * lv[2]):
            continue
        sign = own_sign if ch == own else (1.0 if lv[0] > lv[1] else -1.0)
        sel = band & (cmap == ch)
        n = int(sel.sum())
        parts.append((dx[sel], dy[sel], sign * lin[..., ch][sel], np.full(n, len(levels)), np.full(n, 1.0 / lv[2])))
        levels.append(tuple(own_levels) if ch == own else (sign * lv[0], sign * lv[1]))
    x, y, s, k, wt = (np.concatenate(v) for v in zip(*parts))
    return SiteSamples(x=x, y=y, s=s.astype(np.float64), k=k, wt=wt, levels=np.array(levels))


def ring_floor(level: np.ndarray, sites: np.ndarray, rho: np.ndarray) -> float | None:
    """The ``RING_FLOOR_PERCENTILE`` percentile of one channel's ``level`` at ``sites`` over the
    ring annulus (``rho`` 1.08-1.22) when the annulus brightens outward (a dark ring, paint beyond
    it); None when it does not (a white ring, or no paint in it) or under
    ``RING_FLOOR_MIN_SAMPLES`` samples. Why: around a thin or small disc the annulus holds the dark
    ring and the paint beyond it, and the paint can lift the annulus's median above a dim disc; the
    ring is the annulus's dark, inner part."""
    sel = (rho >= 1.08) & (rho <= 1.22) & sites
    ring, r = level[sel], rho[sel]
    if ring.size < RING_FLOOR_MIN_SAMPLES or not np.ptp(ring) > 0 or not np.ptp(r) > 0:
        return None
    if not np.corrcoef(r, ring)[0, 1] > 0:
        return None
    return float(np.percentile(ring, RING_FLOOR_PERCENTILE))


def disc_noise(level: np.ndarray, sites: np.ndarray, rho: np.ndarray) -> float:
    """Robust spread (1.4826 MAD) + 1e-4 of one channel's ``level`` at ``sites`` over the inner half
    of the pass's box (``rho`` <= 0.5): the disc's own noise, free of what the annulus holds."""
    inner = level[(rho <= 0.5) & sites]
    return float(1.4826 * np.median(np.abs(inner - np.median(inner)))) + 1e-4


def reference_channel(lin: np.ndarray, cmap: np.ndarray, rho: np.ndarray, class_channel: int):
    """(channel, sign, (disc level, ring level) of ``sign`` times the channel) whose samples steer
    the fit's band: the class's own channel when its disc is above its ring (a disc on a dark ring:
    above the annulus's median, or ``MIN_CHANNEL_CNR`` of its own noise sigmas above the annulus's
    dark part, :func:`ring_floor`, the ring level then that part), else the channel of the largest
    contrast to noise ``|disc - ring| / noise`` at its own sites (on a white ring, a red disc's edge
    is in the green and blue samples, dark against the ring), sign -1 when its disc is the darker.
    None when no channel has a disc and a ring level."""
    best = None
    for ch in range(3):
        lv = channel_levels(lin[..., ch], cmap == ch, rho)
        if lv is None:
            continue
        if ch == class_channel:
            if lv[0] > lv[1]:
                return ch, 1.0, lv[:2]
            floor = ring_floor(lin[..., ch], cmap == ch, rho)
            if floor is not None and lv[0] > floor + MIN_CHANNEL_CNR * disc_noise(lin[..., ch], cmap == ch, rho):
                return ch, 1.0, (lv[0], floor)
        cnr = abs(lv[0] - lv[1]) / lv[2]
        if cnr > 0 and (best is None or cnr > best[0]):
            sign = 1.0 if lv[0] > lv[1] else -1.0
            best = (cnr, ch, sign, (sign * lv[0], sign * lv[1]))
    return None if best is None else best[1:]


def fit_disc_joint(image: np.ndarray, win, class_id: int, cfa: str, reweight: bool = True) -> np.ndarray | None:
    """Centre (2,) float64 px of the disc in ``win`` (a ``centre._Window`` of ``image`` (H, W, 3) uint8
    sRGB) fitted to every channel at its own sites of pattern ``cfa``; with ``reweight`` (the
    refinement's choice) a second fit weighted by each channel's residual RMS in the first. None
    when there is nothing to fit or ``centre._fit_accepted`` refuses it (geometry and the reference
    channel's levels)."""
    fitted = joint_fit(image, win, class_id, cfa, reweight)
    return None if fitted is None else win.centre + fitted[0][:2]


def joint_fit(image: np.ndarray, win, class_id: int, cfa: str, reweight: bool = True):
    """(parameters, the fit's ``SiteSamples`` with the weights of its last fit) of
    :func:`fit_disc_joint`, the centre at parameters[:2] px from ``win.centre``; None as there.
    The band ends at ``centre.RING_SCALE_LIMIT`` of the first ellipse (across a thin disc the ring
    is under a pixel and the paint beyond it, bright in every raw channel, would enter its outer
    pixel); where that leaves no accepted fit (too few samples of a small disc, a first ellipse
    smaller than the disc) the band as it was without that end is fitted instead."""
    m0 = centre._inverse_2x2(4 * win.cov)
    ex, ey = win.xs - win.centre[0], win.ys - win.centre[1]
    d0, _ = centre._sampson(ex, ey, m0[0, 0], m0[0, 1], m0[1, 1])
    q0 = m0[0, 0] * ex * ex + 2 * m0[0, 1] * ex * ey + m0[1, 1] * ey * ey
    y0, x0 = int(win.ys[0, 0]), int(win.xs[0, 0])
    h, w = win.s.shape
    lin = centre._SRGB_TO_LINEAR[image[y0:y0 + h, x0:x0 + w]]
    cmap = channel_map(cfa, *image.shape[:2])[y0:y0 + h, x0:x0 + w]
    ref = reference_channel(lin, cmap, win.rho, CLASS_CHANNEL[class_id])
    if ref is None:
        return None
    c, sign, lv = ref
    band = ((d0 > -centre.FIT_BAND_IN_PX) & (d0 < centre.FIT_BAND_OUT_PX)
            & centre._usable(sign * lin[..., c], win.pur, win.rho, lv[0], lv[1]))
    fitted = _fit_band(site_samples(lin, cmap, win, ref, band & (q0 < centre.RING_SCALE_LIMIT ** 2)), m0, win, reweight)
    return fitted if fitted is not None else _fit_band(site_samples(lin, cmap, win, ref, band), m0, win, reweight)


def _fit_band(data: SiteSamples | None, m0: np.ndarray, win, reweight: bool):
    """(parameters, ``data`` with the weights of the last fit) of the disc fitted to ``data`` from
    the first ellipse ``m0`` (then, with ``reweight``, again with each channel weighted by its
    residual RMS); None under 20 samples or when ``centre._fit_accepted`` refuses it."""
    if data is None or data.x.size < 20:
        return None
    p = _levenberg_marquardt(np.concatenate([[0.0, 0.0, m0[0, 0], m0[0, 1], m0[1, 1], np.log(0.2)],
                                             *([f, 0.0, 0.0, b] for f, b in data.levels)]), data)
    if p is not None and reweight:
        r = _residual(p, data)[0] / data.wt
        count = np.maximum(np.bincount(data.k, minlength=len(data.levels)), 1)
        rms = np.sqrt(np.bincount(data.k, r * r, minlength=len(data.levels)) / count)
        data = replace(data, wt=1.0 / (rms[data.k] + 1e-4))
        p = _levenberg_marquardt(p, data)
    if p is None or not centre._fit_accepted(p[:_GEOMETRY + _LEVELS], m0, win):
        return None
    return p, data


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
