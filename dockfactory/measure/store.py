"""measure's results on disk, written as each image finishes, so a batch is never lost.

OUT/measure_run.json says what the results were made with (every image's bytes, the layout,
the weights, the options that change a result; its sha256 is the run's ``key``). Each measured
image's entry is OUT/records/NNNNN_<stem>.json (written atomically, carrying the key); its
overlay is OUT/overlays/NNNNN_<stem>.png. A rerun with the same key takes the entries it finds
and measures the rest; with another key (other images, bytes or options), or after a run of an
older measure, everything an earlier run wrote (entries, overlays, measurements.json/.csv) is
removed first, so stale results never mix into new ones.

An entry is ``{"key", "index", "image", "record", "detections", "used_points", "principal_point"}``:
the per-image stage of measure (before a docking run's joint solve). Entries written by earlier
versions may also carry ``used_edge_px`` (the edge widths of the used centres, which no solve takes
any more): it is ignored.
"""
from __future__ import annotations

import contextlib
import hashlib
import json
import re
from pathlib import Path

import numpy as np

from dockfactory.core.io import remove_stale_temps, sha256_file, write_json_atomic
from dockfactory.measure.image_header import path_kind

RUN_NAME = "measure_run.json"
RUN_FORMAT = "dockfactory.measure_run/1"
RESULT_NAMES = ("measurements.json", "measurements.csv")
OWN_FILE = re.compile(r"^\d{5}_.*\.(png|json)$")
WRITE_ERROR = "write error"    # an output of the image could not be written (a full disk)
RETRIED = ("worker died", WRITE_ERROR)   # categories measured again by a rerun (the cause may have passed)


def image_identity(path: Path) -> dict:
    """What an image is for the run's key: its bytes' sha256 (a regular file) or what it is."""
    kind = path_kind(path)
    if kind is not None:
        return {"image": str(path), "kind": kind}
    try:
        return {"image": str(path), "bytes": path.stat().st_size, "sha256": sha256_file(path)}
    except OSError as exc:
        return {"image": str(path), "kind": f"not readable ({exc.strerror})"}


def run_key(made_with: dict) -> str:
    return hashlib.sha256(json.dumps(made_with, sort_keys=True).encode("utf-8")).hexdigest()


def plain(obj):
    """``obj`` with numpy scalars and arrays and tuples turned into JSON types."""
    if isinstance(obj, dict):
        return {str(k): plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [plain(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return plain(obj.tolist())
    if isinstance(obj, np.generic):
        return obj.item()
    return obj


class MeasureStore:
    """The per-image entries of one run in ``out`` (a folder whose writer lock the caller holds)."""

    def __init__(self, out: Path, made_with: dict):
        self.out = Path(out)
        self.made_with = made_with
        self.key = run_key(made_with)
        self.discarded = False

    def entry_path(self, index: int, path: Path) -> Path:
        return self.out / "records" / f"{index:05d}_{Path(path).stem}.json"

    def open(self, paths) -> dict[int, dict]:
        """Start or resume the run: the entries already done, by image index (none when the
        folder held another run, whose outputs are removed first; ``discarded`` says so)."""
        for sub in ("records", "overlays"):
            if (self.out / sub).is_dir():
                remove_stale_temps(self.out / sub, 0.0, own=True)   # left by a killed writer
        if self._run_key() != self.key:
            self.discarded = self._clear()
            write_json_atomic(self.out / RUN_NAME, {"format": RUN_FORMAT, "key": self.key, "made_with": self.made_with})
            return {}
        done = {}
        for i, p in enumerate(paths):
            entry = self._load(i, p)
            if entry is not None:
                done[i] = entry
        return done

    def save(self, index: int, path: Path, entry: dict) -> None:
        write_json_atomic(self.entry_path(index, path),
                          plain({"key": self.key, "index": index, "image": str(path), **entry}), indent=None)

    def _run_key(self) -> str | None:
        try:
            doc = json.loads((self.out / RUN_NAME).read_text(encoding="utf-8"))
            return doc["key"] if doc.get("format") == RUN_FORMAT else None
        except (OSError, ValueError, KeyError, TypeError, AttributeError):
            return None

    def _clear(self) -> bool:
        """Remove what an earlier run wrote (the run file first: a kill half-way still restarts)."""
        removed = False
        for p in [self.out / RUN_NAME, *(self.out / n for n in RESULT_NAMES)]:
            with contextlib.suppress(FileNotFoundError):
                p.unlink()
                removed = True
        for sub in ("records", "overlays"):
            folder = self.out / sub
            for p in sorted(folder.iterdir()) if folder.is_dir() and not folder.is_symlink() else []:
                if OWN_FILE.match(p.name) and p.is_file():
                    p.unlink()
                    removed = True
        return removed

    def _load(self, index: int, path: Path) -> dict | None:
        try:
            entry = json.loads(self.entry_path(index, path).read_text(encoding="utf-8"))
            ok = (entry["key"] == self.key and entry["index"] == index and entry["image"] == str(path)
                  and isinstance(entry["record"], dict) and entry["record"].get("category") not in RETRIED)
        except (OSError, ValueError, KeyError, TypeError):
            return None
        return entry if ok else None
