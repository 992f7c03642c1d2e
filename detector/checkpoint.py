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
from pathlib import Path

import torch

from dockfactory.core.errors import DockfactoryError

CHECKPOINT_FORMAT = "dockfactory.detector.checkpoint/1"
WEIGHTS_FORMAT = "dockfactory.detector.weights/1"


class CheckpointError(DockfactoryError):
    """A checkpoint or weights file that cannot be used; the message names the file."""


def save_atomic(obj: dict, path) -> Path:
    """torch.save to a temporary name beside ``path``, then rename."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
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
        obj = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # truncated zip, bad pickle, foreign classes ...
        raise CheckpointError(f"{path}: not a readable checkpoint (truncated or corrupted file?): "
                              f"{type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}") from None
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


def weights_from_checkpoint(ckpt: dict, half: bool = True) -> dict:
    """A weights-only dict (EMA weights) from a training checkpoint dict."""
    sd = {k: (v.half() if half and v.is_floating_point() else v) for k, v in ckpt["ema"].items()}
    cfg = ckpt["config"]
    return {"format": WEIGHTS_FORMAT, "state_dict": sd, "model_config": cfg["model"],
            "data_config": cfg["data"], "dataset_version": ckpt["dataset_version"],
            "provenance": {"epochs": int(ckpt["epoch"]), "updates": int(ckpt["updates"]),
                           "seed": int(cfg["seed"]), "dataset": str(ckpt.get("dataset_path", "")),
                           "half": bool(half)}}


def load_model(path, fuse: bool = True):
    """(model in eval mode (float32), weights dict) from a checkpoint (its EMA) or a weights file."""
    from dockfactory.detector.data import DataConfig
    from dockfactory.detector.model import ModelConfig, build_model
    obj = load_file(path)
    if obj["format"] == CHECKPOINT_FORMAT:
        obj = weights_from_checkpoint(obj, half=False)
    try:
        mcfg = ModelConfig.from_dict(obj["model_config"])
        DataConfig.from_dict(obj["data_config"])
    except (TypeError, ValueError) as exc:
        raise CheckpointError(f"{path}: bad config in checkpoint: {exc}") from None
    model = build_model(mcfg)
    try:
        model.load_state_dict({k: v.float() if v.is_floating_point() else v for k, v in obj["state_dict"].items()})
    except RuntimeError as exc:
        raise CheckpointError(f"{path}: weights do not fit the model: {str(exc).splitlines()[0]}") from None
    model.eval()
    if fuse:
        model.fuse()
    return model, obj
