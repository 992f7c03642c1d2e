"""eval.section_shift: the common offset of a section's centres measured on labelled frames (the
part of each section's mean error that its markers' own scatter does not explain), the noise
card's field and the detections file's check.

Tolerance: over 3,000 groups of 7 markers with 0.1 px of noise the estimate's relative spread is
3.9 % at a shift of 0.03 px and 2.1 % at 0.07 px (40 seeds; mean within 1 % of the truth): tested
within 10 %."""
import json
import math

import numpy as np
import pytest
from pipeline_data import SHIFT_SPLIT_CONFIG, offset_detections, painted_from_text

from dockfactory.core.errors import DockfactoryError
from dockfactory.eval.dataset_access import validate_detections
from dockfactory.eval.section_shift import MIN_SECTION_MARKERS, section_shift_stats


def _groups(rng, n, shift, noise, markers=7):
    return [rng.normal(0.0, shift, 2) * [1, 1] + rng.normal(0.0, noise, (markers, 2)) for _ in range(n)]


@pytest.mark.parametrize("shift", [0.03, 0.07])
def test_shift_is_recovered_beside_the_markers_noise(shift):
    rng = np.random.default_rng(int(shift * 1000))
    stats = section_shift_stats(_groups(rng, 3000, shift, 0.1))
    assert stats["groups"] == 3000
    assert stats["shift_axis_px"] == pytest.approx([shift, shift], rel=0.1)
    # the section means themselves hold the noise too: sqrt(shift^2 + 0.1^2 / 7)
    assert stats["section_mean_rms_px"] == pytest.approx([math.hypot(shift, 0.1 / math.sqrt(7))] * 2, rel=0.05)


def test_noise_alone_gives_about_no_shift_and_small_groups_are_left_out():
    rng = np.random.default_rng(1)
    stats = section_shift_stats(_groups(rng, 3000, 0.0, 0.1))
    assert max(stats["shift_axis_px"]) < 0.012   # 0.1 / sqrt(7) = 0.038 of mean noise taken out
    few = section_shift_stats(_groups(rng, 10, 0.1, 0.1, markers=MIN_SECTION_MARKERS - 1))
    assert few["groups"] == 0 and few["shift_axis_px"] is None


@pytest.mark.parametrize("bad", [[0.1], [0.1, -0.2], [0.1, "x"], "0.1", [0.1, 1e6]])
def test_detections_with_a_bad_section_shift_are_refused_naming_it(tmp_path, bad):
    doc = {"frames": {}, "section_shift_px": bad}
    with pytest.raises(DockfactoryError, match="section_shift_px"):
        validate_detections(json.loads(json.dumps(doc)), tmp_path / "d.json")



@pytest.fixture(scope="module")
def painted(tmp_path_factory):
    return painted_from_text(tmp_path_factory, "shift", SHIFT_SPLIT_CONFIG)


@pytest.mark.slow   # the painted dataset of its fixture: about 9 s, for this one test
def test_a_split_of_the_dataset_measures_its_own_offset_or_says_it_cannot(painted):
    """``split_section_shift`` measures the offset on the val frames' detections (a painted dataset,
    exact centroids plus a 0.1 px offset per frame and section: over its 20-odd sections the
    estimate's spread is about 1 / sqrt(2 n), 16 %: tested within 35 %), and gives None when the detections do not cover the split or it has too few sections."""
    from dockfactory.eval.section_shift import split_section_shift
    from dockfactory.generator.datasets.reader import Dataset
    ds = Dataset.open(painted)
    val = ds.frames(("val",))
    assert len(val) >= 8
    dets = offset_detections(ds, ds.frames(("val", "test")), 0.1, np.random.default_rng(4))
    block = split_section_shift(ds, dets, "val")
    assert block["groups"] >= 2 * len(val) - 2 and block["splits"] == ["val"]
    assert block["shift_axis_px"] == pytest.approx([0.1, 0.1], rel=0.35)
    only_test = {"frames": {f: d for f, d in dets["frames"].items() if f not in val}}
    assert split_section_shift(ds, only_test, "val") is None
    assert split_section_shift(ds, dets, "val", min_groups=10 ** 6) is None

