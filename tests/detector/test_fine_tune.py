"""Fine-tuning (``train(init=...)``, ``dockfactory train --init``): the run starts from the given
weights, keeps their network, anchors and input scale, records their sha256, and refuses a file
that is not weights or a resume from other weights."""
import os

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import pytest
import torch

from dockfactory.core.io import sha256_file
from dockfactory.detector.checkpoint import CheckpointError
from dockfactory.detector.data import DataConfig
from dockfactory.detector.model import ModelConfig
from dockfactory.detector.synthetic import write_synthetic_dataset
from dockfactory.detector.train import TrainConfig, train


def _data(tmp_path):
    return write_synthetic_dataset(tmp_path / "data", frames=2, width=64, height=64, markers=2, seed=1)


def _cfg(epochs, attention="eca", input_scale=1.0, lr0=0.01, fit_anchors=False, seed=4):
    return TrainConfig(model=ModelConfig(scale="n", attention=attention),
                       data=DataConfig(input_scale=input_scale, crop=64, crops_per_frame=1), epochs=epochs,
                       batch_size=2, nbs=2, warmup_epochs=1, lr0=lr0, seed=seed, fit_anchors=fit_anchors)


def _quiet(*_):
    return None


@pytest.fixture(scope="module")
def base_run(tmp_path_factory):
    """A 2-epoch tiny run from scratch (ECA, input scale 1.0, initial weights of seed 7, where the
    fine-tunes use seed 4): the weights to fine-tune from."""
    torch.set_num_threads(1)
    tmp = tmp_path_factory.mktemp("base")
    data = _data(tmp)
    train(data, tmp / "run", _cfg(2, seed=7), progress=False, log=_quiet)
    return data, tmp / "run" / "weights.pt"


def _conv_weights(state: dict) -> dict:
    return {k: v.float() for k, v in state.items() if k.endswith(".weight") and v.dim() == 4}


@pytest.mark.slow   # three tiny trainings: a few seconds
def test_fine_tune_starts_from_the_weights_and_keeps_their_network(base_run, tmp_path):
    data, weights = base_run
    # ask for another network, scale and anchors: the init file's win
    summary = train(data, tmp_path / "ft", _cfg(1, attention="se", input_scale=0.5, lr0=1e-6, fit_anchors=True),
                    progress=False, log=_quiet, init=weights)
    base = torch.load(weights, weights_only=True)
    cfg = summary["config"]
    assert cfg["model"] == base["model_config"] and cfg["data"]["input_scale"] == 1.0
    assert cfg["init_sha256"] == sha256_file(weights) and cfg["warmup_bias_lr"] == 1e-6
    tuned = torch.load(tmp_path / "ft" / "weights.pt", weights_only=True)
    assert tuned["provenance"]["init_sha256"] == sha256_file(weights)
    a, b = _conv_weights(base["state_dict"]), _conv_weights(tuned["state_dict"])
    assert a.keys() == b.keys()
    # one step at lr 1e-6 barely moves a weight; a run from the seed's random init would be far off
    assert max(float((a[k] - b[k]).abs().max()) for k in a) < 1e-3
    scratch = train(data, tmp_path / "scratch", _cfg(1, lr0=1e-6), progress=False, log=_quiet)
    c = _conv_weights(torch.load(scratch["weights"], weights_only=True)["state_dict"])
    assert max(float((a[k] - c[k]).abs().max()) for k in a) > 1e-2


@pytest.mark.slow   # three tiny trainings
def test_fine_tune_resumes_only_from_the_same_weights(base_run, tmp_path):
    data, weights = base_run
    train(data, tmp_path / "ft", _cfg(1), progress=False, log=_quiet, init=weights)
    train(data, tmp_path / "ft", _cfg(2), resume=True, progress=False, log=_quiet, init=weights)
    assert torch.load(tmp_path / "ft" / "last.pt", weights_only=True)["epoch"] == 2
    other = tmp_path / "other.pt"
    train(data, tmp_path / "other_run", _cfg(1), progress=False, log=_quiet)
    other.write_bytes((tmp_path / "other_run" / "weights.pt").read_bytes())
    with pytest.raises(CheckpointError, match="not fine-tuned from these weights"):
        train(data, tmp_path / "ft", _cfg(3), resume=True, progress=False, log=_quiet, init=other)


def test_fine_tune_refuses_what_is_not_weights(tmp_path):
    data = _data(tmp_path)
    foreign = tmp_path / "foreign.pt"
    torch.save({"state_dict": {"w": torch.zeros(2)}}, foreign)
    with pytest.raises(CheckpointError, match="foreign.pt.*not a dockfactory detector file"):
        train(data, tmp_path / "run", _cfg(1), progress=False, log=_quiet, init=foreign)
    with pytest.raises(CheckpointError, match="no such"):
        train(data, tmp_path / "run", _cfg(1), progress=False, log=_quiet, init=tmp_path / "missing.pt")
    assert not (tmp_path / "run" / "last.pt").exists()


@pytest.mark.parametrize("value", ["0", "-0.01", "2", "nan", "fast"])
def test_train_lr0_out_of_range_exit_2(painted_source, tmp_path, capsys, value):
    from dockfactory.cli import main
    with pytest.raises(SystemExit) as exc:
        main(["train", str(painted_source), "--out", str(tmp_path / "run"), "--lr0", value, "--quiet"])
    assert exc.value.code == 2 and "--lr0" in capsys.readouterr().err
    assert not (tmp_path / "run").exists()


def test_train_init_that_is_not_weights_exit_2(painted_source, tmp_path, capsys):
    from dockfactory.cli import main
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"PK\x03\x04 truncated")
    assert main(["train", str(painted_source), "--out", str(tmp_path / "run"), "--init", str(bad), "--quiet",
                 "--threads", "1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "bad.pt" in err[0]
    assert not (tmp_path / "run" / "last.pt").exists()
