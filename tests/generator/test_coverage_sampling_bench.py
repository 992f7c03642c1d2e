"""bench/render/coverage_sampling.py's figures on made-up coverage (no render)."""
import numpy as np
import pytest

from bench.render.coverage_sampling import compare, parse_setting


def _got(cov, crop, seconds=(1.0, 3.0, 2.0)):
    return {"cov": [[cov]], "crop": [[crop]], "seconds": list(seconds)}


def test_the_figures_are_taken_on_the_truth_s_edge_pixels_only():
    """RMS and bias over the pixels the truth puts strictly inside (0.001, 0.999): an error on a
    pixel the truth calls inside or outside does not count; the median seconds are reported."""
    truth = np.zeros((4, 4, 2))
    truth[1, 1, 0], truth[2, 2, 1], truth[3, 3, 0] = 0.5, 0.02, 1.0
    cov = truth.copy()
    cov[1, 1, 0] += 0.1          # an edge pixel off by 0.1
    cov[3, 3, 0] -= 0.5          # a full pixel off: not an edge of the truth
    crop = truth.copy()
    crop[2, 2, 1] += 0.2
    row = compare(_got(cov, crop), {"cov": [[truth]]})
    assert row["edge_px"] == 2
    assert row["rms"] == pytest.approx(np.sqrt(0.1 ** 2 / 2))
    assert row["sampled_rms"] == pytest.approx(np.sqrt(0.2 ** 2 / 2))
    assert row["coverage_s"] == 2.0
    mid = [b for b in row["bias_bins"] if b["truth"][0] == 0.3][0]
    assert mid["n"] == 1 and mid["mean"] == pytest.approx(0.1)


@pytest.mark.parametrize("text", ["a:128", "a:x:0.1", "a:1:2:3"])
def test_a_setting_it_cannot_read_is_refused_naming_it(text):
    with pytest.raises(ValueError):
        parse_setting(text)
    assert parse_setting("fast:64:0.01") == ("fast", 64, 0.01)
