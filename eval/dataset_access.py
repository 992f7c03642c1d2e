"""Read what evaluation needs from a dataset directory (identity, layout, labels)."""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from dockfactory.core.config import Config, config_from_dict
from dockfactory.core.io import load_labels
from dockfactory.generator.dataset import DatasetError, read_identity


@dataclass
class EvalDataset:
    root: Path
    identity: dict
    config: Config
    labels: dict          # frame_id -> label

    @property
    def version_id(self) -> str:
        return self.identity["version_id"]

    def markers(self):
        return self.config.markers_layout()

    def frames(self, splits) -> list[str]:
        return [fid for fid, lab in self.labels.items() if lab["spec"]["split"] in splits]


def open_dataset(root) -> EvalDataset:
    root = Path(root)
    ident = read_identity(root)
    if ident is None:
        raise DatasetError(f"{root}: not a dockfactory dataset (no dataset.json)")
    if not (root / "manifest.json").exists():
        raise DatasetError(f"{root}: dataset is not complete (no manifest.json); finish rendering first")
    cfg = config_from_dict(ident["config"], str(root / "dataset.json"))
    labels = {lab["frame_id"]: lab for lab in load_labels(root)}
    return EvalDataset(root, ident, cfg, labels)


def read_json_for(path, what: str, dataset: EvalDataset) -> dict:
    """Load a JSON file made for ``dataset``; refuse one made for another dataset version."""
    path = Path(path)
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        raise DatasetError(f"{path}: {what} file not found") from None
    except (OSError, json.JSONDecodeError) as exc:
        raise DatasetError(f"{path}: unreadable {what} ({exc})") from exc
    version = data.get("dataset_version")
    if version != dataset.version_id:
        raise DatasetError(f"{path}: {what} were made for dataset version {version}, but "
                           f"{dataset.root} is version {dataset.version_id}; refusing to mix them")
    return data
