"""Training: a small overfit run, exact resume, checkpoint errors, data determinism, anchors."""
import os

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")


import numpy as np
import pytest
import torch

from dockfactory.core.errors import DockfactoryError
from dockfactory.detector.anchors import (
    anchor_fitness,
    anchors_per_level,
    kmeans_anchors,
)
from dockfactory.detector.checkpoint import CheckpointError, load_file, load_model
from dockfactory.detector.data import CropDataset, DataConfig, load_frames
from dockfactory.detector.infer import MarkerDetector
from dockfactory.detector.model import ModelConfig
from dockfactory.detector.synthetic import SyntheticDataset, write_synthetic_dataset
from dockfactory.detector.train import TrainConfig, train
from dockfactory.eval.detection_metrics import match_frame


@pytest.fixture(scope="module")
def overfit_run(tmp_path_factory):
    """4 synthetic 128 x 128 frames with 4 markers each; n + SE trained for 200 steps on them."""
    torch.set_num_threads(min(2, os.cpu_count() or 1))
    data = write_synthetic_dataset(tmp_path_factory.mktemp("syn") / "data", frames=4, seed=0)
    cfg = TrainConfig(model=ModelConfig(scale="n", attention="se"),
                      data=DataConfig(input_scale=1.0, crop=128, crops_per_frame=1, background_fraction=0.0,
                                      augment=False),
                      epochs=200, batch_size=4, nbs=4, lr0=0.06, seed=0)
    run = tmp_path_factory.mktemp("run")
    summary = train(data, run, cfg, progress=False, log=lambda *a: None)
    return data, run, summary


@pytest.mark.slow   # the overfit run trains for 200 steps: about a minute on 2 cores
def test_overfit_loss_falls_and_markers_found(overfit_run):
    data, run, summary = overfit_run
    total = [h["box"] + h["obj"] + h["cls"] for h in summary["history"]]
    assert np.mean(total[-10:]) < 0.35 * np.mean(total[:5])
    det = MarkerDetector(run / "weights.pt", conf_threshold=0.1)
    from dockfactory.detector.data import read_rgb
    found = errors = 0
    for f in load_frames(data, "train"):
        d = det.detect(read_rgb(f.image_path))
        m = match_frame(f.boxes, f.classes, [x["bbox_px"] for x in d], [x["score"] for x in d],
                        [x["class_id"] for x in d])
        for i, k in enumerate(m):
            if k >= 0 and d[k]["score"] >= 0.25:
                found += 1
                errors += float(np.hypot(*(np.array(d[k]["center_px"]) - f.centers[i]))) < 1.0
    assert found == 16            # every marker of the 4 training images
    assert errors >= 14           # and (nearly) all refined centres within 1 px


@pytest.mark.slow   # needs the overfit run
def test_weights_file_is_weights_only(overfit_run):
    _, run, _ = overfit_run
    obj = torch.load(run / "weights.pt", weights_only=True)
    assert obj["format"].startswith("dockfactory.detector.weights") and obj["dataset_version"]
    ckpt = torch.load(run / "last.pt", weights_only=True)
    assert {"model", "ema", "optimizer", "config", "dataset_version", "epoch"} <= set(ckpt)
    assert ckpt["epoch"] == 200


def _tiny(tmp_path, epochs, out, resume=False, version=None):
    data = write_synthetic_dataset(tmp_path / "data", frames=2, width=64, height=64, markers=2, seed=1)
    if version is not None:   # the same frames under another dataset version
        data = SyntheticDataset(data.root, version)
    cfg = TrainConfig(model=ModelConfig(scale="n", attention="eca"),
                      data=DataConfig(input_scale=1.0, crop=64, crops_per_frame=1), epochs=epochs,
                      batch_size=2, nbs=2, warmup_epochs=1, seed=4, fit_anchors=False)
    return train(data, tmp_path / out, cfg, resume=resume, progress=False, log=lambda *a: None)


@pytest.mark.slow   # three short trainings: several seconds
def test_resume_equals_not_stopping(tmp_path):
    torch.set_num_threads(1)
    _tiny(tmp_path, 2, "straight")                    # 2 epochs of one optimiser step each
    _tiny(tmp_path, 1, "stopped")                     # stop after the first step ...
    _tiny(tmp_path, 2, "stopped", resume=True)        # ... and resume for one more
    a = torch.load(tmp_path / "straight" / "last.pt", weights_only=True)
    b = torch.load(tmp_path / "stopped" / "last.pt", weights_only=True)
    for key in ("model", "ema"):
        assert a[key].keys() == b[key].keys()
        for k in a[key]:
            assert torch.equal(a[key][k], b[key][k]), (key, k)
    for sa, sb in zip(a["optimizer"]["state"].values(), b["optimizer"]["state"].values()):
        assert torch.equal(sa["momentum_buffer"], sb["momentum_buffer"])
    assert a["history"][-1]["box"] == b["history"][-1]["box"] and b["epoch"] == 2


def test_an_out_that_is_a_file_is_refused_before_any_work(tmp_path):
    """An --out naming an existing file (a typo, a script's variable) was a FileExistsError traceback
    when the first checkpoint was written, an epoch of work later."""
    out = tmp_path / "taken"
    out.write_text("mine")
    with pytest.raises(DockfactoryError, match="is a file, not a folder") as err:
        train(None, out, TrainConfig(epochs=1))   # refused before the dataset is read
    assert str(out) in str(err.value) and "\n" not in str(err.value)
    assert out.read_text() == "mine"


def test_corrupted_and_foreign_checkpoints_fail_cleanly(tmp_path):
    torch.set_num_threads(1)
    _tiny(tmp_path, 1, "run")
    last = tmp_path / "run" / "last.pt"
    data = last.read_bytes()
    last.write_bytes(data[: len(data) // 2])
    with pytest.raises(CheckpointError, match="truncated or corrupted"):
        load_file(last)
    with pytest.raises(CheckpointError, match="last.pt"):
        _tiny(tmp_path, 2, "run", resume=True)
    with pytest.raises(CheckpointError, match="truncated or corrupted"):
        MarkerDetector(last)
    foreign = tmp_path / "foreign.pt"
    torch.save({"state_dict": {"w": torch.zeros(2)}}, foreign)
    with pytest.raises(CheckpointError, match="not a dockfactory detector file"):
        load_model(foreign)
    text = tmp_path / "notes.pt"
    text.write_text("hello")
    with pytest.raises(CheckpointError, match="notes.pt"):
        load_file(text)
    with pytest.raises(CheckpointError, match="no such"):
        load_file(tmp_path / "missing.pt")
    wrong = tmp_path / "wrong.pt"
    ok = torch.load(tmp_path / "run" / "weights.pt", weights_only=True)
    ok["state_dict"] = {k: v for k, v in list(ok["state_dict"].items())[:-3]}
    torch.save(ok, wrong)
    with pytest.raises(CheckpointError, match="do not fit"):
        load_model(wrong)


def test_resume_refuses_other_dataset(tmp_path):
    torch.set_num_threads(1)
    _tiny(tmp_path, 1, "run")
    with pytest.raises(CheckpointError, match="dataset version"):
        _tiny(tmp_path, 2, "run", resume=True, version="something-else")


def test_batches_are_deterministic_and_boxes_inside(tmp_path):
    data = write_synthetic_dataset(tmp_path / "d", frames=3, width=160, height=128, markers=4, seed=2)
    frames = load_frames(data, "train")
    ds = CropDataset(frames, DataConfig(input_scale=1.0, crop=96, crops_per_frame=2), seed=7)
    x1, t1 = ds.batch(0, 0, 4)
    x2, t2 = CropDataset(frames, DataConfig(input_scale=1.0, crop=96, crops_per_frame=2), seed=7).batch(0, 0, 4)
    assert torch.equal(x1, x2) and torch.equal(t1, t2)
    x3, _ = ds.batch(1, 0, 4)
    assert not torch.equal(x1, x3)
    assert x1.shape == (4, 3, 96, 96) and x1.min() >= 0 and x1.max() <= 1
    assert t1.shape[1] == 6 and ((t1[:, 2:4] >= 0) & (t1[:, 2:4] <= 96)).all() and (t1[:, 4:] > 0).all()


def test_crop_boxes_follow_markers_without_augmentation(tmp_path):
    data = write_synthetic_dataset(tmp_path / "d", frames=1, width=128, height=128, markers=3, seed=3)
    f = load_frames(data, "train")[0]
    ds = CropDataset([f], DataConfig(input_scale=1.0, crop=128, crops_per_frame=1, background_fraction=0.0,
                                     augment=False), seed=0)
    _, t = ds.batch(0, 0, 1)
    want = np.concatenate(((f.boxes[:, :2] + f.boxes[:, 2:]) / 2 + 0.5, f.boxes[:, 2:] - f.boxes[:, :2]), 1)
    got = t[:, 2:].double().numpy()
    assert np.allclose(np.sort(got, 0), np.sort(want, 0), atol=1e-4)


def test_kmeans_anchors_and_bpr():
    g = np.random.default_rng(0)
    wh = np.concatenate((g.uniform(6, 10, (200, 2)), g.uniform(18, 25, (200, 2))))
    a = kmeans_anchors(wh, 9, seed=0)
    assert a.shape == (9, 2) and np.all(np.diff(a.prod(1)) >= 0)
    assert anchor_fitness(wh, a)[0] == 1.0
    assert len(anchors_per_level(a, 3)) == 3
    with pytest.raises(ValueError, match="best possible recall"):
        # four shapes far apart (ratios > 4) and only three anchors: one shape stays unmatched
        kmeans_anchors(np.array([[5.0, 5.0], [100.0, 100.0], [5.0, 100.0], [100.0, 5.0]] * 20), 3, seed=0)
    with pytest.raises(ValueError, match="at least 9"):
        kmeans_anchors(wh[:5], 9)


def test_p2_model_trains_and_detects(tmp_path):
    torch.set_num_threads(1)
    data = write_synthetic_dataset(tmp_path / "d", frames=4, width=96, height=96, markers=4, seed=6)
    cfg = TrainConfig(model=ModelConfig(scale="n", attention="cbam", p2=True,
                                        anchors=tuple(((4.0, 4.0),) * 3 for _ in range(4))),
                      data=DataConfig(input_scale=1.0, crop=96, crops_per_frame=1), epochs=1, batch_size=4, seed=0)
    summary = train(data, tmp_path / "run", cfg, progress=False, log=lambda *a: None)
    assert len(summary["config"]["model"]["anchors"]) == 4          # k-means refit for 4 levels
    det = MarkerDetector(tmp_path / "run" / "weights.pt", conf_threshold=0.0)
    from dockfactory.detector.data import read_rgb
    assert isinstance(det.detect(read_rgb(load_frames(data, "train")[0].image_path)), list)


def test_resume_removes_a_killed_runs_temp_checkpoint(tmp_path):
    """A run killed while writing ``last.pt`` leaves ``.last.pt.tmp-<host>-<pid>``; the next run in
    the folder (``--resume``) removes it when its writer is gone, and leaves one whose writer is
    alive (before: it stayed for good, 3-25 MB each)."""
    import subprocess
    import sys

    from dockfactory.core.io import HOST, TMP_MARK
    torch.set_num_threads(1)
    _tiny(tmp_path, 1, "run")
    gone = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True,
                          text=True, check=True).stdout.strip()
    dead = tmp_path / "run" / f".last.pt{TMP_MARK}{HOST}-{gone}"
    live = tmp_path / "run" / f".last.pt{TMP_MARK}{HOST}-{os.getppid()}"
    dead.write_bytes(b"half a checkpoint")
    live.write_bytes(b"another writer's")
    _tiny(tmp_path, 2, "run", resume=True)
    assert not dead.exists() and live.exists()
