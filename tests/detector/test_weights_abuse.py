"""Weights that are not ours, or ours edited, are refused in one line that names the file and
the problem, and never with advice to load them unsafely (torch's own message suggests
``weights_only=False``, which would run whatever code the file holds)."""
import os
import pickle

import pytest
import torch

from dockfactory.core.resources import shipped_weights
from dockfactory.detector.checkpoint import CheckpointError, load_model
from dockfactory.detector.noise_card import MAX_CARD_NOISE_PX
from dockfactory.cli import main
from dockfactory.solver.checks import MAX_SIGMA_PX


class _Payload:
    def __reduce__(self):
        return (os.system, ("echo this must never run",))


def _edited(tmp_path, name, edit):
    w = torch.load(shipped_weights(), weights_only=True)
    edit(w)
    path = tmp_path / name
    torch.save(w, path)
    return path


def _cases(tmp_path):
    first = None

    def non_tensor(w):
        nonlocal first
        first = next(iter(w["state_dict"]))
        w["state_dict"][first] = "x"
    torch.save({"x": _Payload()}, tmp_path / "payload.pt")
    (tmp_path / "model.onnx").write_bytes(b"\x08\x07\x12\x07pytorch" + bytes(64))
    (tmp_path / "plain.pkl").write_bytes(pickle.dumps({"state_dict": {}}))
    return {
        "payload.pt": "holds Python objects other than tensors",
        "model.onnx": "not a torch weights file",
        "plain.pkl": "not a torch weights file",
        _edited(tmp_path, "nontensor.pt", non_tensor).name: "state_dict: expected names mapped to tensors",
        _edited(tmp_path, "classes.pt", lambda w: w["model_config"].update(num_classes=10 ** 9)).name:
            "num_classes must be an integer in [1, 1000]",
        _edited(tmp_path, "arch.pt", lambda w: w["model_config"].update(attention="eca")).name:
            "1 missing (first attn.conv.weight); 2 unexpected (first attn.fc.0.weight)",
    }


def test_foreign_or_edited_weights_are_one_line_refusals(tmp_path):
    for name, why in _cases(tmp_path).items():
        with pytest.raises(CheckpointError) as exc:
            load_model(tmp_path / name)
        msg = str(exc.value)
        assert why in msg and str(tmp_path / name) in msg and "\n" not in msg, msg
        assert "weights_only" not in msg and "Re-running" not in msg, msg


def test_detect_with_foreign_weights_is_exit_2_without_unsafe_advice(tmp_path, painted_source, capsys):
    _cases(tmp_path)
    for name in ("payload.pt", "model.onnx", "arch.pt"):
        code = main(["detect", str(painted_source), "--weights", str(tmp_path / name), "--out", str(tmp_path / "d.json")])
        err = capsys.readouterr().err.strip().splitlines()
        assert code == 2 and len(err) == 1 and "weights_only" not in err[0] and name in err[0], err
        assert not (tmp_path / "d.json").exists()


def test_a_noise_card_and_the_solver_share_the_largest_centre_noise():
    assert MAX_CARD_NOISE_PX == MAX_SIGMA_PX


def _three_class_weights(tmp_path):
    """A well-formed weights file of a detector with 3 classes (the shipped one's recipe)."""
    from dockfactory.detector.model import ModelConfig, build_model
    w = torch.load(shipped_weights(), weights_only=True)
    w["model_config"] = {**w["model_config"], "num_classes": 3}
    cfg = {k: (tuple(tuple(a) for a in v) if k == "anchors" else tuple(v) if isinstance(v, list) else v)
           for k, v in w["model_config"].items()}
    w["state_dict"] = build_model(ModelConfig(**cfg)).state_dict()
    path = tmp_path / "three.pt"
    torch.save(w, path)
    return path


def test_weights_of_other_classes_are_refused(tmp_path, painted_source, capsys):
    """Weights whose detector has other classes than the markers' load as a network, but every
    consumer (detect, measure) refuses them in one line (before: class 2 had no name and
    crashed, or a 2-class detector of other objects ran)."""
    from dockfactory.detector.infer import MarkerDetector
    path = _three_class_weights(tmp_path)
    load_model(path)                                        # a valid network ...
    with pytest.raises(CheckpointError, match="a detector of 3 classes, not the markers' 2 \\(RedA, BlueB\\)"):
        MarkerDetector(path)                                # ... not a marker detector
    code = main(["detect", str(painted_source), "--weights", str(path), "--out", str(tmp_path / "d.json")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "three.pt" in err[0] and "3 classes" in err[0], err
    assert not (tmp_path / "d.json").exists()
