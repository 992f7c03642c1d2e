"""bench/sensor/centre_bound.py: the Fisher information of a disc's centre, against the closed form of a
blurred circular edge, and what a Bayer sensor's sampling leaves of it."""
from __future__ import annotations

import numpy as np
import pytest

from dockfactory.core.camera_chain.cfa import channel_map

from bench.sensor import centre_bound as cb

R, WIDTH, CONTRAST, VAR = 8.0, 0.6, 0.3, 1e-4


def _information(sites, channels=1, offsets=8) -> np.ndarray:
    """Mean information (2, 2) over sub-pixel positions of a circle of radius R in ``channels``
    channels of equal contrast and noise."""
    rng = np.random.default_rng(3)
    s = np.eye(2) * R ** 2
    c = np.full(channels, CONTRAST)
    v = np.full(channels, VAR)
    return np.mean([cb.centre_information(np.array([40.0, 40.0]) + rng.uniform(0, 2, 2), s, WIDTH, c, v, v, sites)
                    for _ in range(offsets)], axis=0)


def test_a_circle_matches_the_closed_form():
    """J_xx = (contrast^2 / var) pi R / (2 sqrt(pi) width) for a Gaussian edge of std width along a
    circle of radius R (the edge integral of n_x^2 is pi R; of pdf^2, 1 / (2 sqrt(pi) width)): within
    3 %; J_xy ~ 0."""
    info = _information(None)
    closed = CONTRAST ** 2 / VAR * np.pi * R / (2 * np.sqrt(np.pi) * WIDTH)
    assert info[0, 0] == pytest.approx(closed, rel=0.03) and info[1, 1] == pytest.approx(closed, rel=0.03)
    assert abs(info[0, 1]) < 0.02 * closed


@pytest.mark.parametrize("channel, ratio", [(0, 2.0), (1, np.sqrt(2.0)), (2, 2.0)])
def test_a_bayer_sensor_keeps_its_share_of_the_samples(channel, ratio):
    """An edge in one channel, seen at that channel's RGGB sites only (R, B one pixel in four, G two):
    the bound's std is 2 (sqrt 2) times that of every pixel, within 5 %."""
    cmap = channel_map("RGGB", 96, 96)
    only = lambda ch, xs, ys: cmap[ys, xs] == channel      # noqa: E731  the edge's channel's sites
    full, sampled = _information(None), _information(only)
    assert np.sqrt(full[0, 0] / sampled[0, 0]) == pytest.approx(ratio, rel=0.05)
    assert np.sqrt(full[1, 1] / sampled[1, 1]) == pytest.approx(ratio, rel=0.05)


def test_three_channels_add_their_information():
    """Three channels of equal contrast and noise hold three times the information of one."""
    assert _information(None, channels=3)[0, 0] == pytest.approx(3 * _information(None)[0, 0], rel=1e-9)


def test_no_refinement_beats_the_bound():
    """bench/sensor/centre_efficiency.py on 40 noisy synthetic circles: the shipped three-chip fit and the
    RGGB joint fit are at or above their bounds (measured 1.3-1.6x and 1.9-2.5x; asserted >= 0.85x,
    the RMS of 40 trials being within about 11 % of its expectation), and not absurdly far (<= 4x)."""
    from bench.sensor import centre_efficiency as ce
    rng = np.random.default_rng(9)
    errs, where = ce.trial_errors(8.0, 8.0, 40, 0.004, rng)
    bound = ce.bound_std(8.0, 8.0, where, 0.004)
    for cam, ref in (("three-chip", "three-chip-score"), ("rggb", "rggb")):
        eff = np.sqrt((errs[cam] ** 2).mean(axis=0)) / bound[ref]
        assert np.all(eff >= 0.85) and np.all(eff <= 4.0), (cam, eff)
