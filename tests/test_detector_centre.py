"""Sub-pixel centre refinement on synthetic discs with exact coverage."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from detector.centre import colour_score, refine_centre
from detector.synthetic import make_frame


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**31))
def test_refined_centre_and_box_are_subpixel(seed):
    rng = np.random.default_rng(seed)
    img, markers = make_frame(rng, 96, 96, 2, r_range=(6.0, 12.0))
    for m in markers:
        box = np.array(m["bbox_px"]) + rng.uniform(-1.5, 1.5, 4)   # a detector's imprecise box
        r = refine_centre(img, box, m["class_id"])
        assert r.refined and 0.3 <= r.quality <= 1.0
        assert np.hypot(*(r.center - m["center_px"])) < 0.08
        assert np.abs(r.box - np.array(m["bbox_px"])).max() < 0.35


def test_occluded_disc_keeps_detector_box():
    rng = np.random.default_rng(1)
    img, markers = make_frame(rng, 96, 96, 1, r_range=(10.0, 10.0))
    m = markers[0]
    x0, y0, x1, y1 = (int(v) for v in m["bbox_px"])
    img[y0 - 3:y1 + 4, (x0 + x1) // 2:x1 + 4] = (150, 150, 150)      # hide the right half
    r = refine_centre(img, m["bbox_px"], m["class_id"])
    assert not r.refined and r.quality < 0.3
    assert np.allclose(r.center, m["center_px"])


def test_wrong_colour_is_not_refined():
    rng = np.random.default_rng(2)
    img, markers = make_frame(rng, 64, 64, 1)
    m = markers[0]
    r = refine_centre(img, m["bbox_px"], 1 - m["class_id"])
    assert not r.refined


def test_bad_input():
    img = np.zeros((32, 32, 3), np.uint8)
    with pytest.raises(ValueError, match="box"):
        refine_centre(img, [5, 5, 4, 9], 0)
    with pytest.raises(ValueError, match="image"):
        refine_centre(img[..., 0], [1, 1, 9, 9], 0)
    with pytest.raises(ValueError, match="class_id"):
        colour_score(img, 3)
