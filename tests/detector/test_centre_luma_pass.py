"""The refinement's luma pass (detector.centre.coverage_passes): a disc in shadow inside a warm-lit
white ring scores in colour about what its ring does, so the colour pass refuses it and the centre
used to be left unrefined at the detector's box (0.2-0.7 px off on the rendered designs); the luma
pass measures its edge against the ring. It serves only where the colour pass fails, and keeps the
detector's class."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from dockfactory.detector import centre
from dockfactory.detector.centre import refine_centre
from dockfactory.detector.centre_camera import refine_centre_camera
from tests.detector.test_centre_camera import COLOURS, disc, srgb8

DIM_RED = (0.18, 0.004, 0.004)         # a red disc in shadow (linear)
WARM_WHITE = (0.47, 0.30, 0.29)        # its white ring under warm light: R - mean(G, B) 0.175, the disc's
DIM_BLUE = (0.004, 0.01, 0.18)
COOL_WHITE = (0.29, 0.30, 0.47)


def shaded_disc(cx: float, cy: float, colour, ring, a: float = 14.0, b: float = 6.5, size: int = 48,
                ss: int = 8) -> np.ndarray:
    """Linear (size, size, 3): a disc seen at a slant (semi-axes ``a``, ``b`` px along x, y) in a
    ring of colour ``ring`` reaching 1.25 of its radius, on dark paint (0.03), integrated over each
    pixel (ss x ss), then an optical blur of 0.5 px."""
    ys, xs = np.mgrid[0:size * ss, 0:size * ss]
    q = (((xs + 0.5) / ss - 0.5 - cx) / a) ** 2 + (((ys + 0.5) / ss - 0.5 - cy) / b) ** 2
    img = np.full((size * ss, size * ss, 3), 0.03, np.float32)
    img[q < 1.25 ** 2] = ring
    img[q < 1] = colour
    img = img.reshape(size, ss, size, ss, 3).mean(axis=(1, 3))
    return cv2.GaussianBlur(img, (0, 0), 0.5)


def _frames(class_id: int, n: int = 24):
    """``n`` shaded discs of ``class_id`` at random sub-pixel positions with pixel noise 0.003:
    (image, box, true centre) each."""
    rng = np.random.default_rng(5 + class_id)
    colour, ring = (DIM_RED, WARM_WHITE) if class_id == 0 else (DIM_BLUE, COOL_WHITE)
    for _ in range(n):
        cx, cy = 24 + rng.uniform(-1, 1), 24 + rng.uniform(-1, 1)
        lin = shaded_disc(cx, cy, colour, ring) + rng.normal(0, 0.003, (48, 48, 3)).astype(np.float32)
        yield srgb8(lin), np.array([cx - 14, cy - 6.5, cx + 14, cy + 6.5]), np.array([cx, cy])


@pytest.mark.parametrize("class_id", (0, 1))
def test_a_shaded_disc_in_a_warm_white_ring_is_refined_on_its_luma(class_id):
    """Of the 24 discs, the colour pass refuses at least 12 (their contrast to the ring under 2.5
    noise sigmas; before, each kept the box's centre, unrefined); the refinement refines at least
    90 % of those on the luma, at an RMS error of at most 0.03 px (measured: 17 and 24 refused, all
    refined, 0.010 / 0.007 px)."""
    errors, refused = [], 0
    for image, box, truth in _frames(class_id):
        colour, _ = centre._refine_once(image, box, class_id, 0.3, centre.EDGE_BIAS_PX)
        if colour.refined:
            continue
        refused += 1
        r = refine_centre(image, box, class_id)
        if r.refined:
            errors.append(r.center - truth)
    assert refused >= 12
    assert len(errors) >= 0.9 * refused
    assert float(np.sqrt((np.array(errors) ** 2).sum(axis=1).mean())) <= 0.03


def test_the_luma_pass_keeps_the_detectors_class():
    """Asked as the other class, the shaded red disc is not refined: the luma pass refuses a disc
    whose purest colour is not the class's."""
    image, box, _ = next(_frames(0))
    assert not refine_centre(image, box, 1).refined


def test_a_disc_the_colour_pass_refines_never_reaches_the_luma_pass(monkeypatch):
    """A lit disc in a dark ring: the same centre with the luma pass unavailable (it would raise)."""
    image = srgb8(disc(31.6, 32.2, COLOURS[0]))
    box = np.array([31.6 - 12, 32.2 - 12, 31.6 + 12, 32.2 + 12])
    before = refine_centre(image, box, 0)

    def no_luma(*_):
        raise AssertionError("the luma pass ran")

    monkeypatch.setattr(centre, "luma_score", no_luma)
    after = refine_centre(image, box, 0)
    assert before.refined and np.array_equal(before.center, after.center)


def test_a_jpeg_refinement_takes_the_luma_pass_too():
    """The camera path (a JPEG told) starts from the same passes: the shaded disc is refined."""
    image, box, truth = next(_frames(0))
    r = refine_centre_camera(image, box, 0, None, jpeg=True)
    assert r.refined and np.hypot(*(r.center - truth)) <= 0.15
