"""The optional median / Gaussian filter of the linear render (generator.frame_output.median_filtered)."""
import numpy as np
import pytest

from dockfactory.generator.frame_output import median_filtered


def _disc(cx: float, cy: float, r: float = 9.0, n: int = 64, ss: int = 8) -> np.ndarray:
    """A red disc on grey, pixel coverage from an ss x ss supersampling (float32 RGB)."""
    g = (np.arange(n * ss) + 0.5) / ss - 0.5
    inside = ((g[None, :] - cx) ** 2 + (g[:, None] - cy) ** 2 <= r * r).astype(np.float32)
    cov = inside.reshape(n, ss, n, ss).mean(axis=(1, 3))
    img = np.full((n, n, 3), 0.3, np.float32)
    img[..., 0] += 0.6 * cov
    img[..., 1:] -= 0.25 * cov[..., None]
    return img


def _centroid(img: np.ndarray) -> np.ndarray:
    w = img[..., 0] - img[..., 1]   # 0 on the background: a linear weight
    ys, xs = np.mgrid[0:w.shape[0], 0:w.shape[1]]
    return np.array([(w * xs).sum() / w.sum(), (w * ys).sum() / w.sum()])


def test_off_returns_the_render_itself():
    img = _disc(30.3, 31.7)
    assert median_filtered(img, "off") is img


@pytest.mark.parametrize("name, tol", [("gauss05", 0.002), ("gauss07", 0.002), ("gauss10", 0.002),
                                       ("median3", 0.02), ("median5", 0.02)])
def test_filters_keep_a_disc_centroid(name, tol):
    img = _disc(30.37, 31.71)
    out = median_filtered(img, name)
    assert out.shape == img.shape and out.dtype == np.float32
    # a symmetric filter of a centrally symmetric shape: the linear blur keeps the centroid to
    # 0.002 px; the median, not linear, moves a pixel-sampled disc by up to 0.02 px
    assert np.abs(_centroid(out) - _centroid(img)).max() < tol


def test_median_removes_a_lone_bright_sample_and_gauss_spreads_it():
    img = np.full((20, 20, 3), 0.2, np.float32)
    img[10, 10] = 50.0
    assert median_filtered(img, "median3")[10, 10].max() == pytest.approx(0.2)
    g = median_filtered(img, "gauss07")
    assert g[10, 10, 0] < 50.0 * 0.5
    assert g.sum() == pytest.approx(img.sum(), rel=1e-4)   # the blur keeps the energy
