"""Centre quality that means something: a disc partly hidden by an occluder is not returned as a
refined centre at full quality, while whole discs keep theirs.

Synthetic markers as in test_centre_bias (exact coverage, blur, noise, 8-bit sRGB); an occluder
is a grey half-plane laid over the rendered image, hiding a chord of the disc; the detector's
box is that of the visible part (what a detector sees). Truth: the whole ellipse's centre."""
import numpy as np
import pytest

import dockfactory.detector.centre as centre
from test_centre_bias import ellipse_coverage, render_marker

OCCLUDER = np.array([0.20, 0.20, 0.20])          # a grey tool or cable in linear light


def occluded_marker(rng, hidden: float):
    """(image, class id, true centre (2,), visible box (4,)) of a marker whose part beyond a random
    chord is hidden by a grey occluder: ``hidden`` the share of the disc's width (along the
    chord's normal) hidden from its far side."""
    cls, a = int(rng.integers(0, 2)), rng.uniform(8, 14)
    b, theta = a * rng.uniform(0.6, 1.0), rng.uniform(0, np.pi)
    img, truth, box = render_marker(rng, cls, a, b, theta, 0.0, 0.35, 0.004)
    phi = rng.uniform(0, 2 * np.pi)
    n = np.array([np.cos(phi), np.sin(phi)])
    reach = float(np.abs(n) @ ((box[2:] - box[:2]) / 2))          # about the disc's extent along n
    ys, xs = np.mgrid[0:64, 0:64]
    d = (xs - truth[0]) * n[0] + (ys - truth[1]) * n[1]
    cover = np.clip(d - reach * (1 - 2 * hidden) + 0.5, 0, 1)[..., None]   # 1 beyond the chord
    srgb = img.astype(np.float64) / 255
    lin = np.where(srgb <= 0.04045, srgb / 12.92, ((srgb + 0.055) / 1.055) ** 2.4)
    lin = np.clip(lin * (1 - cover) + OCCLUDER * cover, 0, 1)
    out = np.where(lin <= 0.0031308, 12.92 * lin, 1.055 * lin ** (1 / 2.4) - 0.055)
    img = np.clip(np.rint(out * 255), 0, 255).astype(np.uint8)
    vis_y, vis_x = np.nonzero((ellipse_coverage(64, 64, truth[0], truth[1], a, b, theta) > 0.5) & (cover[..., 0] < 0.5))
    return img, cls, truth, np.array([vis_x.min() - 0.5, vis_y.min() - 0.5, vis_x.max() + 0.5, vis_y.max() + 0.5])


def test_whole_discs_keep_their_quality():
    """60 whole discs (axes 3-16 px, shading up to 30 %, blur 0.35-0.8 px): every refined one is
    within 0.2 px with an asymmetry under ASYM_OK_PX (its symmetry term 1) at the coverage pass's
    quality; the few whose edge fit is refused (a thin, strongly shaded, blurred disc: its coverage
    centroid is up to 0.8 px off) at most at REFUSED_FIT_QUALITY of it."""
    rng = np.random.default_rng(11)
    refused = 0
    for _ in range(60):
        cls, a = int(rng.integers(0, 2)), rng.uniform(8, 16)
        img, truth, box = render_marker(rng, cls, a, a * rng.uniform(0.4, 1.0), rng.uniform(0, np.pi),
                                        rng.uniform(0, 0.3), rng.uniform(0.35, 0.8), 0.004)
        first, win = centre._refine_once(img, box, cls, 0.3, centre.EDGE_BIAS_PX)
        second, win2 = centre._refine_once(img, first.box, cls, 0.3, centre.EDGE_BIAS_PX)
        first, win = (second, win2) if second.refined else (first, win)
        r = centre.refine_centre(img, box, cls)
        if np.isnan(r.edge_px):      # the edge fit refused
            refused += 1
            assert r.quality <= centre.REFUSED_FIT_QUALITY * first.quality + 1e-12
            continue
        assert r.refined and r.quality == pytest.approx(first.quality)
        assert centre.asymmetry_px(win, r.center) < centre.ASYM_OK_PX
        assert np.hypot(*(r.center - truth)) < 0.2
    assert refused <= 2


def _far_refined(monkeypatch=None) -> tuple[int, int]:
    """(refined centres more than 1 px off, discs more than 1 px off) over 90 discs with a chord
    hidden (30, 45 and 60 % of their width from one side)."""
    far, off = 0, 0
    for hidden in (0.3, 0.45, 0.6):
        rng = np.random.default_rng([7, int(hidden * 100)])
        for _ in range(30):
            img, cls, truth, box = occluded_marker(rng, hidden)
            r = centre.refine_centre(img, box, cls)
            err = float(np.hypot(*(r.center - truth)))
            off += err > 1.0
            far += r.refined and err > 1.0
    return far, off


@pytest.mark.slow   # seconds of work: the full suite runs it (make test), the fast lane does not
def test_a_hidden_chord_is_rarely_a_refined_centre_far_off(monkeypatch):
    """Discs with a chord hidden, most of their centres 1-5 px off (85 of 90): without the symmetry
    term 75 of them are returned refined (as the refinement did before it, like the renders' 7.5 px
    at quality 1.0); with it 13 (at most 14 allowed; 11 with the edge fit's band not ended at the
    ring, 10 before either change to the edge fit: the end, which takes the paint's pull off every
    whole oblique disc, lets two more hidden caps through). What is left: a narrow cap (more than
    half the disc hidden) looks like a whole disc seen at a slant, symmetric about its own centre: no
    test on its shape alone tells it apart (the solver's comparison of each box with the pose's
    prediction is what can)."""
    far, off = _far_refined()
    assert off >= 80 and far <= 14
    monkeypatch.setattr(centre, "symmetry_quality", lambda a: 1.0)
    before, _ = _far_refined()
    assert before >= 60


def test_asymmetry_measures_a_displaced_centre():
    """On a clean disc the asymmetry about the true centre is under ASYM_OK_PX / 2 and about a
    centre 1 px off it is 0.45-0.85 px (an ellipse shifted by 2 e against itself: about 0.64 e)."""
    rng = np.random.default_rng(3)
    img, truth, box = render_marker(rng, 0, 12.0, 9.0, 0.4, 0.0, 0.35, 0.002)
    _, win = centre._refine_once(img, box, 0, 0.3, centre.EDGE_BIAS_PX)
    assert centre.asymmetry_px(win, truth) < centre.ASYM_OK_PX / 2
    assert 0.45 < centre.asymmetry_px(win, truth + [0.6, 0.8]) < 0.85
    assert centre.symmetry_quality(0.0) == 1.0 and centre.symmetry_quality(centre.ASYM_BAD_PX) == 0.0
