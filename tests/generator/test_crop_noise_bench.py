"""bench/render/crop_noise.py: the per-class noise of a marker, and the reference's share removed."""
import numpy as np
import pytest

from bench.render.crop_noise import exponents, marker_noise, remove_reference_noise

H, W, CX, CY, R = 80, 100, 50.3, 40.7, 12.0


def _disc(level=1.0):
    """A red disc of radius R on a dark ground, antialiased by 8 x 8 supersampling."""
    ys, xs = np.mgrid[0:H * 8, 0:W * 8]
    inside = ((xs + 0.5) / 8 - CX) ** 2 + ((ys + 0.5) / 8 - CY) ** 2 < R ** 2
    img = np.zeros((H, W, 3))
    img[..., 0] = 0.05 + level * inside.reshape(H, 8, W, 8).mean(axis=(1, 3))
    return img


MARKER = {"in_frame": True, "visible_fraction": 1.0, "section": "A",
          "bbox_px": [CX - R, CY - R, CX + R, CY + R]}


def test_noise_on_the_edge_only_lands_in_the_edge_class():
    """Noise of std 0.05 (of the contrast) added where the disc's coverage is partial only: the edge
    class (by the gradient, which also takes the pixels next to them) reads 40-100 % of its variance,
    the flat class under 5 %; the edge class takes over 90 % of the gradient-weighted noise."""
    ref = _disc()
    rng = np.random.default_rng(1)
    partial = (ref[..., 0] > 0.06) & (ref[..., 0] < 1.04)
    cand = ref.copy()
    cand[..., 0] += np.where(partial, rng.normal(0, 0.05, partial.shape), 0.0)
    got = marker_noise(ref, [cand], MARKER)
    assert 0.4 * 0.05 ** 2 < got[(0, "edge")][0] <= 0.05 ** 2
    assert got[(0, "flat")][0] < 0.05 * 0.05 ** 2
    assert got[(0, "edge")][1] > 0.9


def test_flat_noise_is_the_same_in_every_class():
    """White noise over the whole marker reads the same variance in every class (within 25 %)."""
    ref = _disc()
    cand = ref + np.random.default_rng(2).normal(0, 0.02, ref.shape)
    got = marker_noise(ref, [cand], MARKER)
    for cls in ("edge", "slope", "flat"):
        assert got[(0, cls)][0] == pytest.approx(0.02 ** 2, rel=0.25)


def test_a_hidden_marker_is_left_out():
    assert marker_noise(_disc(), [_disc()], {**MARKER, "visible_fraction": 0.9}) is None


def test_reference_share_removed_and_exponent_of_independent_samples_is_one():
    """Candidates at 16 and 64 samples whose own noise goes as c / N, measured with a 256-sample
    reference's c / 256 added: the removal returns c / N and the exponent 1."""
    c = 0.04
    summary = {f"n{n}": {"marker_samples": n, "classes": {k: {"noise": c / n + c / 256} for k in
                                                        ("edge", "slope", "flat")}} for n in (16, 64)}
    remove_reference_noise(summary, 256)
    assert summary["n16"]["classes"]["edge"]["own_per_sample"] == pytest.approx(c)
    assert exponents(summary)["16->64"]["flat"] == pytest.approx(1.0)
