"""The centres' measured structure and the bound under it (eval.centre_structure).

- structure_moments recovers a known structure (each marker's own variance, correlations between
  markers) from 3000 synthetic frames: correlations within 0.06 (3000 frames: a correlation's
  standard error is under 0.02), variances within 10 %, little shrinkage; from 40 frames of
  independent errors it shrinks the sampling noise away (intensity at least 0.5) and stays
  positive definite; a moment seen in fewer than MIN_PAIR_FRAMES frames is not kept.
- measure_structure measures on train / val, falls back to the test split cross-fitted in two
  halves (each frame bounded by the other half), and says why when neither has enough frames.
- structured_frame_bound under an identity structure is evaluate's disc-model bound of the frame.
- evaluate and the report carry the structured bound beside the independent one.
Seeded throughout.
"""
from __future__ import annotations

import json

import numpy as np
import pytest

from dockfactory.eval import centre_structure as cs
from dockfactory.eval.acceptance import AcceptanceSpec
from dockfactory.eval.evaluate import evaluate, frame_bound, write_outputs
from dockfactory.eval.report.calibration import markdown_honesty
from dockfactory.eval.solve_frames import solve_dataset, write_poses
from dockfactory.generator.datasets.reader import Dataset

IDS = ["A0", "A1", "A2", "B0", "B1"]


def _samples(cov: np.ndarray, frames: int, seed: int, keep: float = 1.0) -> list[dict]:
    rng = np.random.default_rng(seed)
    chol = np.linalg.cholesky(cov)
    out = []
    for _ in range(frames):
        v = chol @ rng.normal(size=len(cov))
        out.append({k: v[2 * i:2 * i + 2] for i, k in enumerate(IDS) if rng.random() < keep})
    return out


def _known_structure() -> np.ndarray:
    var = np.repeat([0.5, 1.0, 2.0, 1.5, 0.8], 2)
    corr = np.eye(10)
    corr[0, 2] = corr[2, 0] = 0.6        # A0 u with A1 u
    corr[7, 9] = corr[9, 7] = -0.4       # B0 v with B1 v
    return corr * np.sqrt(np.outer(var, var))


def test_a_known_structure_is_recovered():
    cov = _known_structure()
    m, shrink = cs.structure_moments(_samples(cov, 3000, 1, keep=0.9), IDS)
    truth = cov / np.diag(cov).mean()
    d = np.sqrt(np.diag(m))
    assert np.diag(m).mean() == pytest.approx(1.0)
    assert np.diag(m) == pytest.approx(np.diag(truth), rel=0.10)
    corr = m / np.outer(d, d)
    assert np.abs(corr - truth / np.sqrt(np.outer(np.diag(truth), np.diag(truth)))).max() < 0.06
    assert shrink < 0.2


def test_independent_errors_over_few_frames_are_shrunk_to_the_diagonal():
    m, shrink = cs.structure_moments(_samples(np.eye(10), 40, 2), IDS)
    assert shrink >= 0.5
    assert np.linalg.eigvalsh(m).min() > cs.PD_FLOOR
    off = m[~np.eye(10, dtype=bool)]
    assert np.abs(off).max() < 0.2


def test_a_moment_over_too_few_frames_is_not_kept():
    samples = _samples(np.eye(10), 200, 3)
    for f in samples[cs.MIN_PAIR_FRAMES - 1:]:
        f.pop("B1")                        # B1 in MIN_PAIR_FRAMES - 1 frames only
    m, _ = cs.structure_moments(samples, IDS)
    assert np.all(m[8:, :8] == 0.0) and np.all(m[:8, 8:] == 0.0)
    assert m[8, 8] == pytest.approx(np.diag(m)[:8].mean(), rel=1e-9)


def _detections(ds, sigma=0.03, seed=5):
    """Each visible marker's outline centroid plus seeded noise, refined, every frame."""
    rng = np.random.default_rng(seed)
    frames = {}
    for fid in ds.frames():
        frames[fid] = [{"class_id": m["class_id"], "bbox_px": m["bbox_px"], "score": 0.9, "refined": True,
                        "center_px": (np.array(m["outline_centroid_px"]) + rng.normal(0, sigma, 2)).tolist()}
                       for m in ds.labels[fid]["markers"] if m.get("visibility") == 2]
    return {"format": "dockfactory.detections/1", "dataset_version": ds.version_id, "frames": frames}


def test_the_structure_is_measured_where_the_verdict_does_not_look(painted_source, monkeypatch):
    ds = Dataset.open(painted_source)
    dets = _detections(ds)
    n_train = len(cs._frame_samples(ds, dets, cs.STRUCTURE_SPLITS, 0.25))
    test_ids = list(cs._frame_samples(ds, dets, ("test",), 0.25))
    assert n_train == 4 and len(test_ids) == 4          # the smoke dataset: 4 train / val, 4 test frames
    monkeypatch.setattr(cs, "MIN_STRUCTURE_FRAMES", 4)
    st = cs.measure_structure(ds, dets, 0.25)
    assert st["source"] == "train/val" and st["folds"][0]["frames"] == 4 and "use" not in st
    monkeypatch.setattr(cs, "MIN_STRUCTURE_FRAMES", 2)   # a split with no frame cannot give it: the test split's halves do
    st = cs.measure_structure(ds, dets, 0.25, splits=("no such split",))
    assert st["source"] == "test, cross-fitted in two halves" and [f["frames"] for f in st["folds"]] == [2, 2]
    assert st["use"] == {f: 1 - k % 2 for k, f in enumerate(test_ids)}
    monkeypatch.setattr(cs, "MIN_STRUCTURE_FRAMES", 5)
    st = cs.measure_structure(ds, dets, 0.25)
    assert st["source"] == "none" and "fewer than 5" in st["reason"] and "folds" not in st


@pytest.mark.parametrize("aspect", [1.0, 1.08])
def test_an_identity_structure_gives_evaluates_bound(painted_source, aspect):
    """Also for non-square pixels (K's fy = aspect fx): both bound in the square-pixel pinhole at fx."""
    ds = Dataset.open(painted_source)
    for fid in ds.frames(("test",)):
        label = json.loads(json.dumps(ds.labels[fid]))
        f, (cx, cy) = label["camera"]["focal_px"], label["camera"]["principal_point"]
        label["camera"]["K"] = [[f, 0.0, cx], [0.0, aspect * f, cy], [0.0, 0.0, 1.0]]
        ids = [m["id"] for m in label["markers"] if m.get("visibility") == 2]
        fold = {"ids": sorted(ids), "moments": np.eye(2 * len(ids)).tolist()}
        got = cs.structured_frame_bound(label, ids, {"source": "t", "folds": [fold]}, 0.02)
        ref = frame_bound(label, ids, 0.02, disc_scale_px=0.02)
        if ref is None:
            assert got is None
            continue
        for c in ("x", "y", "alpha"):
            assert got["bound"][c] == pytest.approx(ref[c], rel=1e-6)
            assert got["fit"][c] == pytest.approx(ref[c], rel=1e-6)


def test_evaluate_and_the_report_carry_the_structured_bound(painted_source, tmp_path, monkeypatch):
    ds = Dataset.open(painted_source)
    dets = _detections(ds)
    monkeypatch.setattr(cs, "MIN_STRUCTURE_FRAMES", 2)
    (tmp_path / "dets.json").write_text(json.dumps(dets))
    write_poses(tmp_path / "poses.json", solve_dataset(ds, detections=dets))
    metrics, rows = evaluate(ds, tmp_path / "poses.json", AcceptanceSpec(), tmp_path / "dets.json", oracle=False)
    write_outputs(tmp_path / "eval", metrics, rows)
    loc = metrics["localization"]
    assert metrics["centre_noise"]["structure"]["source"] == "train/val"
    solved = [r for r in rows if r["ok"] and r["split"] == "test"]
    assert solved and all(r["crb_structured_x"] > 0 and r["fit_structured_x"] >= 0.999 * r["crb_structured_x"]
                          for r in solved)
    assert set(loc["crb_structured"]) == set(loc["crb"])
    md = markdown_honesty(metrics)
    assert "bound under the measured structure" in md and "measured on train/val" in md
    header = (tmp_path / "eval" / "frames.csv").read_text().splitlines()[0]
    assert "crb_structured_x" in header and "fit_structured_alpha" in header
