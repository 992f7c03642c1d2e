"""bench/detector/half_weights.py: the fp16 copy of a weights file loads to (nearly) the same network."""
import os

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import pytest

torch = pytest.importorskip("torch")
from bench.detector.half_weights import half_weights, largest_centre_change  # noqa: E402


def test_half_copy_is_smaller_and_gives_the_same_outputs(tmp_path, repo_root):
    from dockfactory.detector.checkpoint import load_file, load_model
    src = repo_root / "models" / "yolov5n_se_markers.pt"
    dst = half_weights(src, tmp_path / "half.pt")
    obj = load_file(dst)
    assert all(v.dtype == torch.float16 for v in obj["state_dict"].values() if v.is_floating_point())
    assert obj["provenance"]["half"] is True
    assert dst.stat().st_size < 0.6 * src.stat().st_size
    torch.manual_seed(0)
    x = torch.rand(1, 3, 96, 128)
    with torch.no_grad():
        a = load_model(src)[0](x)[0]
        b = load_model(dst)[0](x)[0]
    # fp16 weights (about 3 significant digits): raw outputs agree to a small fraction of their range
    assert (a - b).abs().max() <= 0.02 * a.abs().max()


def test_largest_centre_change_matches_by_class_and_score():
    a = {"frames": {"f": [{"class_id": 0, "score": 0.9, "center_px": [10.0, 10.0]},
                          {"class_id": 1, "score": 0.1, "center_px": [50.0, 50.0]}]}}
    b = {"frames": {"f": [{"class_id": 0, "score": 0.8, "center_px": [10.003, 9.996]},
                          {"class_id": 1, "score": 0.9, "center_px": [10.0, 10.0]}]}}
    assert largest_centre_change(a, b) == pytest.approx(0.005)
    b["frames"]["f"][0]["class_id"] = 1                  # no same-class partner: infinitely far
    assert largest_centre_change(a, b) == float("inf")
