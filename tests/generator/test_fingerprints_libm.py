"""Fingerprint v3 (generator.datasets.fingerprints_libm): a published dataset whose labels' trigonometry
another CPU path rounded otherwise verifies on the cores a libm re-render gives, and nothing else.

The published dataset is the painted smoke dataset (tests/pipeline_data.py); a re-render whose
numpy rounded sin and cos otherwise is a copy of three frames with a geometric field moved in its
last bits, as the AVX-512 and libm paths differ.
"""
import json
import math

import pytest

from dockfactory.generator.datasets import published
from dockfactory.generator.datasets.folder import DatasetError
from dockfactory.generator.datasets.fingerprints import FINGERPRINTS_V3_NAME, read_fingerprints_v2
from dockfactory.generator.datasets.fingerprints_libm import derive


def _edit(sub, fid, edit):
    path = sub / "labels" / f"{fid}.json"
    label = json.loads(path.read_text())
    edit(label)
    path.write_text(json.dumps(label, indent=1) + "\n")


def _last_bits(label):      # one ulp up on every marker's centre: what libm against SVML leaves
    for m in label["markers"]:
        m["center_px"] = [math.nextafter(v, math.inf) for v in m["center_px"]]


def test_a_rerender_with_other_last_bits_fails_on_v2_and_passes_on_its_derived_v3(release):
    pub, sub, ids = release
    _edit(sub, ids[0], _last_bits)
    rep = published.verify_against(sub, pub / "manifest.json")
    assert f"labels/{ids[0]}.json: differs from the manifest beyond its image and index-pass measurements" \
        in rep.problems
    der = derive(sub, pub / "manifest.json")
    assert (der.frames, der.same_as_v2, der.kept, der.problems) == (3, 2, 0, []), der.text()
    assert set(read_fingerprints_v2(pub / FINGERPRINTS_V3_NAME)) == set(ids)
    rep = published.verify_against(sub, pub / "manifest.json")
    assert rep.ok and (rep.labels_identical, rep.labels_libm) == (2, 1), rep.text()
    assert "1 labels match the published geometry as libm's sin and cos give it" in rep.text()


def test_v3_lets_through_only_the_derived_bits(release):
    pub, sub, ids = release
    _edit(sub, ids[0], _last_bits)
    derive(sub, pub / "manifest.json")
    _edit(sub, ids[0], lambda lab: lab["markers"][0]["center_px"].__setitem__(0, lab["markers"][0]["center_px"][0]
                                                                             + 1e-3))
    rep = published.verify_against(sub, pub / "manifest.json")
    assert f"labels/{ids[0]}.json: differs from the manifest beyond its image and index-pass measurements" \
        in rep.problems and rep.labels_libm == 0


def test_derive_merges_frames_and_refuses_a_frame_with_another_core_writing_nothing(release):
    pub, sub, ids = release
    _edit(sub, ids[0], _last_bits)
    derive(sub, pub / "manifest.json")
    v3 = pub / FINGERPRINTS_V3_NAME
    before = v3.read_bytes()
    for fid in ids[1:]:
        (sub / "labels" / f"{fid}.json").unlink()
    _edit(sub, ids[0], _last_bits)                           # another core for a frame v3 holds
    der = derive(sub, pub / "manifest.json")
    assert der.problems == [f"labels/{ids[0]}.json: the v3 file holds another core for frame {ids[0]}"]
    assert v3.read_bytes() == before


def test_derive_refuses_index_numbers_beyond_v2s_tolerance_and_a_release_without_v2(release):
    pub, sub, ids = release
    def pixels(label):
        s = label["sections"][1]
        s["pixels_visible"] += 3
        s["visible_fraction"] = min(1.0, s["pixels_visible"] / s["pixels_all"])
    _edit(sub, ids[1], pixels)
    der = derive(sub, pub / "manifest.json")
    assert der.problems == [f"labels/{ids[1]}.json: index-pass numbers differ from v2's beyond 2 px"]
    assert not (pub / FINGERPRINTS_V3_NAME).exists()
    (pub / published.FINGERPRINTS_V2_NAME).unlink()
    with pytest.raises(DatasetError, match="no fingerprint v2 beside it"):
        derive(sub, pub / "manifest.json")
