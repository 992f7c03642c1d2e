"""The edge fit's band ends at the ring (detector.centre.RING_SCALE_LIMIT): across a disc seen
obliquely the ring is under a pixel wide and the paint beyond it, whose colour score is not the
ring's level, must not pull the edge on that side (bench/results/centre_pattern/README.md)."""
import numpy as np
import pytest

import dockfactory.detector.centre as centre
from dockfactory.core.cv import cv2

SS = 8


def _linear(rgb) -> np.ndarray:
    return (np.asarray(rgb, float) / 255.0) ** 2.2


def oblique_marker(cx: float, cy: float, a: float, b: float, ring_minor_px: float, paint_below,
                   shape=(48, 64), blur_px: float = 0.35) -> np.ndarray:
    """(h, w, 3) uint8: a red disc, semi-axes ``a`` (x) and ``b`` (y) px, in a dark ring whose outer
    ellipse is ``ring_minor_px`` wider across the minor axis (proportionally across the major),
    on grey paint above the disc and ``paint_below`` below it (blended across the disc's height);
    area coverage 8 x 8 per pixel, a Gaussian blur, sRGB-like gamma."""
    h, w = shape
    off = (np.arange(SS) + 0.5) / SS - 0.5
    ys = np.broadcast_to(np.arange(h)[:, None, None, None] + off[None, None, :, None], (h, w, SS, SS))
    xs = np.broadcast_to(np.arange(w)[None, :, None, None] + off[None, None, None, :], (h, w, SS, SS))
    disc = ((xs - cx) / a) ** 2 + ((ys - cy) / b) ** 2 <= 1
    ring = ((xs - cx) / (a * (1 + ring_minor_px / b))) ** 2 + ((ys - cy) / (b + ring_minor_px)) ** 2 <= 1
    t = np.clip((ys - cy) / (2 * b) + 0.5, 0, 1)[..., None]
    paint = _linear((60, 60, 60)) * (1 - t) + _linear(paint_below) * t
    lin = np.where(disc[..., None], _linear((200, 25, 25)), np.where(ring[..., None], _linear((25, 25, 25)), paint))
    img = cv2.GaussianBlur(lin.mean(axis=(2, 3)), (0, 0), blur_px)
    return (np.clip(img, 0, 1) ** (1 / 2.2) * 255 + 0.5).astype(np.uint8)


def _mean_error(monkeypatch, limit: float, a: float, b: float, ring_minor_px: float) -> np.ndarray:
    """Mean refined centre error (x, y) px over 12 seeded sub-pixel placements."""
    monkeypatch.setattr(centre, "RING_SCALE_LIMIT", limit)
    rng, errors = np.random.default_rng(1), []
    for _ in range(12):
        cx, cy = 32 + rng.uniform(-0.5, 0.5), 24 + rng.uniform(-0.5, 0.5)
        image = oblique_marker(cx, cy, a, b, ring_minor_px, (60, 150, 200))
        r = centre.refine_centre(image, [cx - a - 2, cy - b - 2, cx + a + 2, cy + b + 2], 0)
        assert r.refined
        errors.append(r.center - [cx, cy])
    return np.mean(errors, axis=0)


def test_paint_beyond_a_thin_ring_pulls_the_centre_less(monkeypatch):
    """A disc 18 x 6 px with its ring 0.8 px wide across the minor axis and blue-grey paint below:
    without the band's end the centre is pulled 0.03 px across the minor axis; with it, under half
    of that and within 0.02 px."""
    free = _mean_error(monkeypatch, 1e9, 18.0, 6.0, 0.8)
    ended = _mean_error(monkeypatch, 1.1, 18.0, 6.0, 0.8)
    assert abs(free[1]) > 0.02
    assert abs(ended[1]) < 0.5 * abs(free[1])
    assert abs(ended[1]) < 0.02


@pytest.mark.parametrize("limit", [1.1, 1.3])
def test_a_ring_wider_than_the_band_changes_nothing(monkeypatch, limit):
    """A disc seen face-on (10 px radius, ring 3 px): the band (1 px outside the edge) ends inside
    the ring anyway, so the end moves the centre by no more than the fit's own stopping step
    (0.002 px)."""
    monkeypatch.setattr(centre, "RING_SCALE_LIMIT", 1e9)
    image = oblique_marker(32.2, 23.7, 10.0, 10.0, 3.0, (60, 150, 200))
    box = [20.2, 11.7, 44.2, 35.7]
    free = centre.refine_centre(image, box, 0)
    monkeypatch.setattr(centre, "RING_SCALE_LIMIT", limit)
    ended = centre.refine_centre(image, box, 0)
    assert free.refined and ended.refined
    assert np.abs(free.center - ended.center).max() < 0.002
