"""Checkpoints and shipped weights: plain dicts of tensors and primitives.

Both load with ``torch.load(weights_only=True)`` (no pickled classes). A file that is truncated,
corrupted or not ours raises :class:`CheckpointError` (a ValueError) with the path and the reason.

- training checkpoint (``format`` = CHECKPOINT_FORMAT): model, EMA and optimiser state, the epoch
  reached, the number of optimiser updates, the train config, dataset version id, history;
- weights file (``format`` = WEIGHTS_FORMAT): the EMA weights only (optionally fp16), the model
  and data configs, dataset version id and a short provenance record.
"""
from __future__ import annotations

import os
import warnings
from pathlib import Path

import torch

from dockfactory.core.errors import DockfactoryError
from dockfactory.core.io import temp_name

CHECKPOINT_FORMAT = "dockfactory.detector.checkpoint/1"
WEIGHTS_FORMAT = "dockfactory.detector.weights/1"


class CheckpointError(DockfactoryError):
    """A checkpoint or weights file that cannot be used; the message names the file."""


def save_atomic(obj: dict, path) -> Path:
    """torch.save to a temporary name beside ``path``, then rename."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(temp_name(path.name))
    try:
        torch.save(obj, tmp)
        with open(tmp, "rb") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
    return path


def load_file(path, expect: tuple[str, ...] = (CHECKPOINT_FORMAT, WEIGHTS_FORMAT)) -> dict:
    """Load a checkpoint/weights dict and check its format tag and required keys."""
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"{path}: no such checkpoint file")
    try:
        with warnings.catch_warnings():   # torch's advice on pickle protocols is not the user's business
            warnings.simplefilter("ignore")
            obj = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # truncated zip, bad pickle, foreign classes ...
        raise CheckpointError(f"{path}: {_unreadable_reason(path, exc)}") from None
    if not isinstance(obj, dict) or obj.get("format") not in expect:
        found = obj.get("format") if isinstance(obj, dict) else type(obj).__name__
        raise CheckpointError(f"{path}: not a dockfactory detector file (format {found!r}; "
                              f"expected one of {', '.join(expect)})")
    need = {CHECKPOINT_FORMAT: ("model", "ema", "optimizer", "epoch", "updates", "config", "dataset_version"),
            WEIGHTS_FORMAT: ("state_dict", "model_config", "data_config", "dataset_version")}[obj["format"]]
    missing = [k for k in need if k not in obj]
    if missing:
        raise CheckpointError(f"{path}: checkpoint lacks {', '.join(missing)}")
    return obj


def _unreadable_reason(path: Path, exc: Exception) -> str:
    """Why torch could not load ``path`` with weights only, in our words (torch's own message
    suggests loading with weights_only=False, which would run whatever code the file holds:
    never do that with a file you did not make)."""
    with open(path, "rb") as fh:
        head = fh.read(4)
    if head[:2] != b"PK":
        return ("not a torch weights file (a torch file is a zip archive; this one starts with "
                f"{head!r}: an ONNX model, a pickle or another format?)")
    if "weights_only" in str(exc) or "Unsupported global" in str(exc):
        return ("holds Python objects other than tensors and plain values; dockfactory loads weights as "
                "tensors only and refuses it (loading such objects can run code)")
    return f"not a readable checkpoint (truncated or corrupted?): {type(exc).__name__}"


def state_dict_problem(state: dict, model) -> str | None:
    """Why ``state`` does not fit ``model``, in one line; None when it fits."""
    if not isinstance(state, dict) or not all(isinstance(k, str) and isinstance(v, torch.Tensor)
                                              for k, v in state.items()):
        return "state_dict: expected names mapped to tensors"
    want = model.state_dict()
    missing, unexpected = sorted(set(want) - set(state)), sorted(set(state) - set(want))
    shapes = [k for k in want if k in state and tuple(state[k].shape) != tuple(want[k].shape)]
    if not (missing or unexpected or shapes):
        return None
    parts = [f"{len(missing)} missing (first {missing[0]})" if missing else "",
             f"{len(unexpected)} unexpected (first {unexpected[0]})" if unexpected else "",
             f"{len(shapes)} of another shape (first {shapes[0]}: {tuple(state[shapes[0]].shape)} in the file, "
             f"{tuple(want[shapes[0]].shape)} in the model)" if shapes else ""]
    return "weights do not fit the model its config describes: " + "; ".join(p for p in parts if p)


def weights_from_checkpoint(ckpt: dict, half: bool = True) -> dict:
    """A weights-only dict (EMA weights) from a training checkpoint dict."""
    sd = {k: (v.half() if half and v.is_floating_point() else v) for k, v in ckpt["ema"].items()}
    cfg = ckpt["config"]
    return {"format": WEIGHTS_FORMAT, "state_dict": sd, "model_config": cfg["model"],
            "data_config": cfg["data"], "dataset_version": ckpt["dataset_version"],
            "provenance": {"epochs": int(ckpt["epoch"]), "updates": int(ckpt["updates"]),
                           "seed": int(cfg["seed"]), "dataset": str(ckpt.get("dataset_path", "")),
                           "half": bool(half), "init_sha256": str(cfg.get("init_sha256", ""))}}


def read_weights(path):
    """(weights dict with float32 state, ModelConfig, DataConfig) of a checkpoint (its EMA) or a
    weights file, the state checked against the model its config describes.

    Raises CheckpointError (one line naming the file) for a missing, foreign or inconsistent file."""
    from dockfactory.detector.data import DataConfig
    from dockfactory.detector.model import ModelConfig, build_model
    obj = load_file(path)
    if obj["format"] == CHECKPOINT_FORMAT:
        obj = weights_from_checkpoint(obj, half=False)
    try:
        mcfg = ModelConfig.from_dict(obj["model_config"])
        dcfg = DataConfig.from_dict(obj["data_config"])
    except (TypeError, ValueError) as exc:
        raise CheckpointError(f"{path}: bad config in checkpoint: {exc}") from None
    problem = state_dict_problem(obj["state_dict"], build_model(mcfg))
    if problem:
        raise CheckpointError(f"{path}: {problem}")
    state = {k: v.float() if v.is_floating_point() else v for k, v in obj["state_dict"].items()}
    return {**obj, "state_dict": state}, mcfg, dcfg


def load_model(path, fuse: bool = True):
    """Load a detector from a checkpoint (its EMA weights) or a weights file.

    Parameters
    ----------
    path : str or Path
        The file (read with ``torch.load(weights_only=True)``).
    fuse : bool
        Fold each BatchNorm into its convolution (inference only).

    Returns
    -------
    tuple
        (the model in eval mode, float32; the weights dict: state, model and data configs, the
        dataset version, provenance).

    Raises
    ------
    CheckpointError
        A missing, foreign or inconsistent file (one line naming it).
    """
    from dockfactory.detector.model import build_model
    obj, mcfg, _ = read_weights(path)
    model = build_model(mcfg)
    model.load_state_dict(obj["state_dict"])
    model.eval()
    if fuse:
        model.fuse()
    return model, obj
