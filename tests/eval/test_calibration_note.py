"""The report's note on the reported covariance is a finding only when its frames can tell: an RMS z
outside the [0.85, 1.2] band whose chi-square interval still holds 1 is 'too few frames to tell',
not 'std too small'. Tested on both sides of each threshold."""
from __future__ import annotations

import math

import pytest

from dockfactory.eval.confidence import chi2_quantile
from dockfactory.eval.report.calibration import calibration_note, rms_z_interval


def cal(rms_z: float, n: int, within: float = 0.95) -> dict:
    s = {"n": n, "rms_z": rms_z, "within_2sigma": within}
    ok = {"n": n, "rms_z": 1.0, "within_2sigma": 0.95}
    return {"overall": {"x": s, "y": ok, "alpha": ok}}


def test_interval_holds_one_exactly_over_the_calibrated_range():
    n = 9
    edge_hi = math.sqrt(chi2_quantile(0.975, n) / n)     # the largest RMS z a calibrated covariance gives (95 %)
    assert rms_z_interval(edge_hi * 0.999, n)[0] < 1 < rms_z_interval(edge_hi * 1.001, n)[0]
    lo, hi = rms_z_interval(1.0, 48)
    assert 0.80 < lo < 0.86 and 1.2 < hi < 1.3
    assert rms_z_interval(None, 0) is None


@pytest.mark.parametrize("rms_z, n, expect", [
    (1.24, 9, "too few frames to tell"),      # the demo's 9 frames: outside the band, not a finding
    (1.24, 200, "std too small"),            # the same RMS over 200 frames is one
    (0.70, 9, "too few frames to tell"),
    (0.70, 200, "std too large"),
    (1.10, 200, ""),                         # inside the band: no note
])
def test_note_on_both_sides(rms_z, n, expect):
    note = calibration_note(cal(rms_z, n))
    if expect:
        assert expect in note and f"over {n} frames" in note
    else:
        assert note == ""


def test_flip_at_the_interval_edge():
    """Just past the edge where the interval stops holding 1, the note turns into a finding."""
    n = 30
    edge = math.sqrt(chi2_quantile(0.975, n) / n)
    assert "too few frames" in calibration_note(cal(edge * 0.995, n))
    assert "std too small" in calibration_note(cal(edge * 1.005, n))
