"""The edge fit's model of a blurred shaded disc (detector.centre.BLURRED_SHADING): the blur of a
disc whose level changes across it moves its apparent edges toward the dark side by about
v g / (f - b); the model carries that term, so the centre does not move with the shading."""
import numpy as np

import dockfactory.detector.centre as centre
from dockfactory.core.cv import cv2

SS = 8


def shaded_disc(cx: float, cy: float, a: float, b: float, shade: float, blur_px: float = 0.5,
                shape=(48, 64)) -> np.ndarray:
    """(h, w, 3) uint8: a red disc (semi-axes ``a`` along x, ``b`` along y px) whose linear level
    rises by ``shade`` (relative) per semi-axis toward +y, in a 3 px dark ring on grey; area
    coverage 8 x 8 per pixel, a Gaussian blur, gamma 2.2."""
    h, w = shape
    off = (np.arange(SS) + 0.5) / SS - 0.5
    ys = np.broadcast_to(np.arange(h)[:, None, None, None] + off[None, None, :, None], (h, w, SS, SS))
    xs = np.broadcast_to(np.arange(w)[None, :, None, None] + off[None, None, None, :], (h, w, SS, SS))
    disc = ((xs - cx) / a) ** 2 + ((ys - cy) / b) ** 2 <= 1
    ring = ((xs - cx) / (a + 3)) ** 2 + ((ys - cy) / (b + 3)) ** 2 <= 1
    lin = lambda c: (np.asarray(c, float) / 255.0) ** 2.2   # noqa: E731
    level = lin((200, 25, 25)) * (1 + shade * (ys - cy) / b)[..., None]
    img = np.where(disc[..., None], level, np.where(ring[..., None], lin((25, 25, 25)), lin((120, 120, 120))))
    img = cv2.GaussianBlur(img.mean(axis=(2, 3)), (0, 0), blur_px)
    return (np.clip(img, 0, 1) ** (1 / 2.2) * 255 + 0.5).astype(np.uint8)


def _mean_dy(monkeypatch, term: float) -> float:
    """Mean refined centre error along the shading (y, px) over 16 seeded placements of a disc
    19 x 7 px shaded by 0.15 per semi-axis."""
    monkeypatch.setattr(centre, "BLURRED_SHADING", term)
    rng, dy = np.random.default_rng(2), []
    for _ in range(16):
        cx, cy = 32 + rng.uniform(-0.5, 0.5), 24 + rng.uniform(-0.5, 0.5)
        r = centre.refine_centre(shaded_disc(cx, cy, 19.0, 7.0, 0.15), [cx - 21, cy - 9, cx + 21, cy + 9], 0)
        assert r.refined
        dy.append(r.center[1] - cy)
    return float(np.mean(dy))


def test_the_blurred_shading_term_takes_the_shift_away(monkeypatch):
    """Without the term the centre moves toward the dark side (-y) by about v g / (f - b): with the
    edge width here (about 0.58 px) and g = 0.15 / 7 per px, some 0.005-0.007 px; with it, under a third."""
    shipped = centre.BLURRED_SHADING
    without = _mean_dy(monkeypatch, 0.0)
    with_term = _mean_dy(monkeypatch, shipped)
    assert without < -0.004
    assert abs(with_term) < abs(without) / 3
