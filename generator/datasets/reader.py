"""The dataset contract: every consumer (detect, train, solve, evaluate, export, run) reads a dataset
through ``Dataset.open``.

``Dataset.open`` runs the checks of ``generator.datasets.check`` (``full=False``: images and EXR by size only) and
refuses a damaged, incomplete or foreign dataset with a one-line DatasetError; a label's bytes are checked against
the manifest again when it is read.

Why and how: docs/datasets.md, "The dataset contract".
"""
from __future__ import annotations

import json
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

from dockfactory.core.config import Config
from dockfactory.core.io import sha256_bytes
from dockfactory.generator.datasets.folder import DatasetError
from dockfactory.generator.datasets.check import inspect


class Labels(Mapping):
    """frame id -> label of the dataset's planned frames (in plan order), read and checked lazily."""

    def __init__(self, dataset: Dataset):
        self._ds = dataset
        self._cache: dict[str, dict] = {}

    def __getitem__(self, frame_id: str) -> dict:
        if frame_id not in self._ds.splits:
            raise KeyError(frame_id)
        if frame_id not in self._cache:
            self._cache[frame_id] = self._ds.read_label(frame_id)
        return self._cache[frame_id]

    def __iter__(self):
        return iter(self._ds.splits)

    def __len__(self) -> int:
        return len(self._ds.splits)

    def __contains__(self, frame_id) -> bool:
        return frame_id in self._ds.splits


@dataclass
class Dataset:
    root: Path
    identity: dict
    config: Config
    plan: tuple                 # FrameSpec of every frame, in plan order
    manifest: dict
    full: bool                  # images and EXR hashed on open (else compared by size)
    splits: dict = field(default_factory=dict)   # frame id -> split (plan order)
    labels: Labels = field(init=False)

    def __post_init__(self):
        self.splits = {s.frame_id: s.split for s in self.plan}
        self._sha = {rec["path"]: rec["sha256"] for rec in self.manifest["files"]}
        self.labels = Labels(self)

    @classmethod
    def open(cls, root, full: bool = True) -> Dataset:
        """The complete, intact dataset at ``root``; DatasetError (one line) otherwise."""
        root = Path(root)
        if not root.is_dir():
            raise DatasetError(f"{root}: no such dataset directory")
        report, checked = inspect(root, hash_bulk=full)
        if not report.ok:
            raise DatasetError(report.refusal())
        return cls.of_checked(root, checked, full)

    @classmethod
    def of_checked(cls, root, checked, full: bool) -> Dataset:
        """The dataset a caller has just checked itself (``check.inspect`` with an OK
        report): what it read, without checking again."""
        return cls(Path(root), checked.identity, checked.config, checked.plan, checked.manifest, full)

    @property
    def version_id(self) -> str:
        return self.identity["version_id"]

    def markers(self):
        return self.config.markers_layout()

    def frames(self, splits: Iterable[str] | str | None = None) -> list[str]:
        """Frame ids of ``splits`` (a name, several, or None for all), in plan order."""
        want = {splits} if isinstance(splits, str) else (None if splits is None else set(splits))
        return [fid for fid, sp in self.splits.items() if want is None or sp in want]

    def labels_of(self, split: str | None = None) -> list[dict]:
        """Labels of one split (None: all), in plan order."""
        return [self.labels[fid] for fid in self.frames(split)]

    def image_path(self, frame_id: str) -> Path:
        self._planned(frame_id)
        return self.root / "images" / f"{frame_id}.png"

    def _planned(self, frame_id: str) -> None:
        if frame_id not in self.splits:
            raise DatasetError(f"{self.root}: frame {frame_id!r} is not a frame of this dataset")

    def read_label(self, frame_id: str) -> dict:
        """The label of a planned frame, its bytes checked against the manifest and its frame id and
        split against the plan."""
        self._planned(frame_id)
        rel = f"labels/{frame_id}.json"
        path = self.root / rel
        try:
            data = path.read_bytes()
        except OSError as exc:
            raise DatasetError(f"{path}: cannot read label ({exc.strerror})") from None
        if sha256_bytes(data) != self._sha.get(rel):
            raise DatasetError(f"{path}: changed since the dataset was finished (sha256 differs from the "
                               f"manifest); refusing to use it")
        label = json.loads(data)
        spec = label.get("spec") if isinstance(label, dict) else None
        if not isinstance(spec, dict) or label.get("frame_id") != frame_id or spec.get("split") != self.splits[frame_id]:
            raise DatasetError(f"{path}: not the label of planned frame {frame_id} "
                               f"(split {self.splits[frame_id]})")
        return label
