"""The joint edge fit of a Bayer camera on thin discs (detector.centre_joint): the fit's band ends
where the dark ring may, so the paint beyond a ring thinner than a pixel stays out of it, and the
class's own channel steers the fit when the paint, not the disc, lifts the annulus around it."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from dockfactory.core.camera_chain.cfa import channel_map, mosaic
from dockfactory.core.camera_chain.demosaic import demosaic
from dockfactory.detector import centre_joint
from dockfactory.detector.centre_camera import refine_centre_camera
from tests.detector.test_centre_camera import COLOURS, srgb8


def slanted_disc(cx: float, cy: float, colour, a: float = 11.0, b: float = 3.5, size: int = 48,
                 ss: int = 8) -> np.ndarray:
    """Linear (size, size, 3): a disc seen at a slant (an ellipse of semi-axes ``a``, ``b`` px along
    x, y) in a dark ring reaching 1.25 of its radius (a 20 mm disc's 2.5 mm ring: 0.9 px across it
    here) on bright paint (0.5), integrated over each pixel (ss x ss), then an optical blur of 0.5 px."""
    ys, xs = np.mgrid[0:size * ss, 0:size * ss]
    q = (((xs + 0.5) / ss - 0.5 - cx) / a) ** 2 + (((ys + 0.5) / ss - 0.5 - cy) / b) ** 2
    img = np.full((size * ss, size * ss, 3), 0.5, np.float32)
    img[q < 1.25 ** 2] = 0.02
    img[q < 1] = colour
    img = img.reshape(size, ss, size, ss, 3).mean(axis=(1, 3))
    return cv2.GaussianBlur(img, (0, 0), 0.5)


def thin_disc_rms(class_id: int, n: int = 24) -> float:
    """RMS centre error (px) of the refinement told RGGB over ``n`` thin discs at random sub-pixel
    positions, raw noise 0.004, bilinear demosaic; every one refined or the test fails."""
    rng = np.random.default_rng(11)
    out = []
    for _ in range(n):
        cx, cy = 24 + rng.uniform(-1, 1), 24 + rng.uniform(-1, 1)
        raw = mosaic(slanted_disc(cx, cy, COLOURS[class_id]), "RGGB")
        raw = np.clip(raw + rng.normal(0, 0.004, raw.shape).astype(np.float32), 0, 1)
        image = srgb8(demosaic(raw, "RGGB", "bilinear"))
        r = refine_centre_camera(image, np.array([cx - 11, cy - 3.5, cx + 11, cy + 3.5]), class_id, "RGGB")
        if r.refined:
            out.append(r.center - (cx, cy))
    assert len(out) >= n * 3 // 4
    return float(np.sqrt((np.array(out) ** 2).sum(axis=1).mean()))


@pytest.mark.parametrize("class_id", (0, 1))
def test_the_paint_beyond_a_thin_ring_stays_out_of_the_fit(class_id):
    """RMS <= 0.06 px (measured 0.042 / 0.044 px red / blue; 0.091 / 0.170 px with the band
    reaching past the ring as before)."""
    assert thin_disc_rms(class_id) <= 0.06


def _annulus_window(disc: float, ring: float, paint: float, paint_share: float, size: int = 41):
    """A window whose class channel (0) holds ``disc`` inside rho 1, the annulus (rho 1.08-1.22)
    ``ring`` and ``paint`` (the outer ``paint_share`` of it) and ``paint`` beyond; channel 1
    dark everywhere, channel 2 the paint's level outside the disc (a grey paint)."""
    ys, xs = np.mgrid[0:size, 0:size]
    rho = np.hypot(xs - size // 2, ys - size // 2) / 15.0
    rng = np.random.default_rng(3)
    lin = np.empty((size, size, 3))
    split = 1.08 + (1.0 - paint_share) * 0.14
    lin[..., 0] = np.where(rho < 1.0, disc, np.where(rho < split, ring, paint))
    lin[..., 1] = 0.01
    lin[..., 2] = np.where(rho < 1.0, 0.01, paint)
    lin += rng.normal(0, 0.002, lin.shape)
    return lin, channel_map("RGGB", size, size), rho


def test_a_dim_disc_keeps_its_own_channel_when_paint_lifts_the_annulus():
    """A dim red disc (0.05) in a dark ring (0.01) whose annulus is 60 % paint (0.2): the annulus's
    median is above the disc, yet the red samples steer the fit, the ring level the dark part's
    (before: the blue channel negated, whose edge is the ring's outer one)."""
    lin, cmap, rho = _annulus_window(0.05, 0.01, 0.2, 0.6)
    ch, sign, (disc, ring) = centre_joint.reference_channel(lin, cmap, rho, 0)
    assert (ch, sign) == (0, 1.0)
    assert disc == pytest.approx(0.05, abs=0.005) and ring == pytest.approx(0.01, abs=0.01)


def test_a_white_ring_still_gives_the_edge_to_another_channel():
    """A red disc (0.5) in a white ring (0.7) on grey paint: the annulus's dark part is the ring
    itself, above the disc: not the red channel."""
    lin, cmap, rho = _annulus_window(0.5, 0.7, 0.3, 0.3)
    ch, sign, _ = centre_joint.reference_channel(lin, cmap, rho, 0)
    assert ch != 0


def test_a_band_end_that_leaves_no_fit_falls_back_to_the_whole_band(monkeypatch):
    """With the band's end drawn inside the disc (no edge left in it), the fit is that of the band
    without the end, not refused (before: the refinement fell back to the coverage centroid)."""
    from tests.detector.test_centre_camera import disc
    raw = mosaic(disc(32.3, 31.8, COLOURS[0]), "RGGB")
    image = srgb8(demosaic(raw, "RGGB", "bilinear"))
    box = np.array([32.3 - 12, 31.8 - 12, 32.3 + 12, 31.8 + 12])
    monkeypatch.setattr(centre_joint.centre, "RING_SCALE_LIMIT", 1e9)
    whole = refine_centre_camera(image, box, 0, "RGGB")
    monkeypatch.setattr(centre_joint.centre, "RING_SCALE_LIMIT", 0.5)
    cut = refine_centre_camera(image, box, 0, "RGGB")
    assert whole.refined and whole.quality == 1.0
    assert cut.quality == 1.0 and np.allclose(cut.center, whole.center, atol=1e-9)
