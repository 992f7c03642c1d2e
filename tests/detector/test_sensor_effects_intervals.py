"""bench/sensor/sensor_effects.py's paired bootstrap intervals: the ratio of two RMSEs over the same frames
(an effect over the three-chip reference, or new weights over shipped ones) with the interval the
frames allow."""
from __future__ import annotations

import json

import numpy as np
import pytest

from bench.sensor import sensor_effects as se


def rows(errors: np.ndarray, names=None) -> list[dict]:
    """Bench rows with the same error in X, Y and alpha."""
    names = names or [f"{i:06d}" for i in range(len(errors))]
    return [{"frame": n, "ok": True, "centres": [], **{f"err_{c}": float(e) for c in se.COMPONENTS},
             **{f"z_{c}": float(e) / 0.1 for c in se.COMPONENTS}} for n, e in zip(names, errors)]


def test_scaled_errors_give_an_exact_ratio():
    ref = np.random.default_rng(1).normal(0, 0.1, 48)
    ci = se.ratio_interval(rows(2.0 * ref), rows(ref), "x")
    assert ci == pytest.approx([2.0, 2.0], abs=1e-3)


def test_one_frame_carrying_the_rmse_widens_the_interval():
    """Equal errors but one frame 10x: the ratio is far above 1, the interval reaches down near 1."""
    ref = np.random.default_rng(2).normal(0, 0.1, 48)
    ref[5] = 0.1
    new = ref.copy()
    new[5] = 1.0
    point = np.sqrt(np.sum(new ** 2) / np.sum(ref ** 2))
    lo, hi = se.ratio_interval(rows(new), rows(ref), "y")
    assert point > 1.5
    assert lo < 1.2 and lo <= point <= hi


def test_only_frames_solved_in_both_pair_up():
    ref, new = rows(np.full(10, 0.1)), rows(np.full(10, 0.2))
    new[3]["ok"] = False
    ref[4]["ok"] = False
    ref[7]["err_x"] = 100.0     # unsolved in `new`: must not enter the pair
    new[7]["ok"] = False
    assert se.ratio_interval(new, ref, "x") == pytest.approx([2.0, 2.0], abs=1e-3)
    assert se.ratio_interval(new[:4], ref[:4], "x") is None       # under 5 pairs


def test_add_intervals_keeps_them_for_stripped_files():
    ref = np.random.default_rng(3).normal(0, 0.1, 20)
    effects = {"three-chip": {"rows": rows(ref)}, "bayer-mhc": {"rows": rows(1.5 * ref)}}
    se.add_intervals(effects)
    assert effects["bayer-mhc"]["ratio_interval_alpha"] == pytest.approx([1.5, 1.5], abs=1e-3)
    assert effects["three-chip"]["ratio_interval_x"] == pytest.approx([1.0, 1.0], abs=1e-3)


def test_paired_files_pool_scenes(tmp_path):
    """Two results files: per scene and over both scenes, the second's RMSE over the first's."""
    rng = np.random.default_rng(4)
    a, b = rng.normal(0, 0.1, 12), rng.normal(0, 0.3, 12)
    old = {"datasets": {"A@1": {"bayer-mhc": {"rows": rows(a)}}, "B@2": {"bayer-mhc": {"rows": rows(b)}}}}
    new = {"datasets": {"A@1": {"bayer-mhc": {"rows": rows(2 * a)}}, "B@2": {"bayer-mhc": {"rows": rows(b)}}}}
    p_old, p_new = tmp_path / "old.json", tmp_path / "new.json"
    p_old.write_text(json.dumps(old))
    p_new.write_text(json.dumps(new))
    text = se.paired([str(p_old), str(p_new)])
    lines = {tuple(c.strip() for c in ln.split("|")[1:3]): ln for ln in text.splitlines()[2:]}
    assert lines[("bayer-mhc", "A@1")].count("2.00 [2.00-2.00]") == 3
    assert lines[("bayer-mhc", "B@2")].count("1.00 [1.00-1.00]") == 3
    pooled = np.sqrt((4 * np.sum(a ** 2) + np.sum(b ** 2)) / (np.sum(a ** 2) + np.sum(b ** 2)))
    assert f"{pooled:.2f} [" in lines[("bayer-mhc", "all")]


def test_rms_z_interval_spans_the_sampling_noise_of_48_frames():
    """Gaussian z over 48 frames: the interval holds the sample's RMS and spans about 0.8-1.2."""
    z = np.random.default_rng(5).normal(0, 1, 48)
    lo, hi = se.rms_z_bootstrap_interval(z)
    rms = float(np.sqrt(np.mean(z ** 2)))
    assert lo < rms < hi
    assert 0.25 < hi - lo < 0.6
    assert se.rms_z_bootstrap_interval(z[:4]) is None


@pytest.mark.parametrize("flags", [[], ["--tell-cfa", "--tell-jpeg"]])
def test_a_results_file_is_not_resumed_with_other_flags(tmp_path, monkeypatch, capsys, flags):
    """Rows measured with (or without) the refinement told the CFA and the JPEG are never relabelled:
    resuming their file with the other flags exits 2 naming the file and the flag, before any work."""
    out = tmp_path / "res.json"
    told = not flags
    out.write_text(json.dumps({"datasets": {}, "tell_cfa": told, "tell_jpeg": told}))
    monkeypatch.setattr("sys.argv", ["sensor_effects", str(tmp_path / "no_dataset"), "--out", str(out), *flags])
    with pytest.raises(SystemExit) as exc:
        se.main()
    assert exc.value.code == 2
    assert f"{out}: its rows were measured with tell_cfa = {told}" in capsys.readouterr().err
    assert json.loads(out.read_text())["tell_cfa"] is told
