"""Dataset directories: identity (version id), frame completeness, manifest.

Layout of a dataset directory:
  dataset.json       identity: version id, resolved config, software versions (written first)
  config.toml        the config file as given
  layout.json        the marker layout (ids, section, centre and normal in the section frame)
  images/ labels/ meta/ [exr/]   per-frame files (see generator.frame_output)
  logs/              worker logs and per-frame timings (not part of the dataset's content), and
                     the dataset's lock file (logs/.dockfactory.lock: render and export hold it)
  manifest.json      written once every planned frame is complete: counts and every file's
                     size and sha256
"""
from __future__ import annotations

import contextlib
import json
import re
from collections import Counter
from pathlib import Path

from dockfactory.core.config import Config
from dockfactory.core.errors import DockfactoryError
from dockfactory.core.io import LOCK_NAME, folder_lock, output_lock, sha256_file, write_bytes_atomic, write_json_atomic
from dockfactory.core.layout import CLASS_NAMES
from dockfactory.core.names import SPLITS
from dockfactory.generator.datasets.dvc_links import cache_link, dvc_caches
from dockfactory.generator.random_draws import static_scene
from dockfactory.generator.frame_output import frame_paths
from dockfactory.generator.sampler import frame_plan
from dockfactory.generator.version import (
    blender_version,
    dataset_version_id,
    generator_version,
    package_version,
)

DATASET_FORMAT = "dockfactory.dataset/1"
CONVENTIONS = {
    "units": {"length": "mm", "angle": "deg", "image": "px", "focal": "px"},
    "frames": "D = section A's frame: origin at the centre of A's docking face, +X along A's axis "
              "toward B, +Y up, +Z toward the camera side; d_from_b is B in D; "
              "R = Rz(alpha) @ Ry(beta) @ Rx(gamma); camera frame is OpenCV (x right, y down, z forward)",
    "pixels": "OpenCV: (0, 0) is the centre of the top-left pixel; the image spans "
              "[-0.5, W - 0.5] x [-0.5, H - 0.5]; principal point of an unshifted camera "
              "((W - 1) / 2, (H - 1) / 2)",
    "boxes": "[x0, y0, x1, y1] in the pixel frame above",
    "classes": list(CLASS_NAMES),
}


class DatasetError(DockfactoryError):
    """A dataset directory that cannot be used as asked; the message says why."""


# ----------------------------------------------------------------------------- names and locks

FRAME_ID_RE = re.compile(r"^\d{6}$|^rep\d{3}_\d{2}$")
LOCK_FILE = Path("logs") / LOCK_NAME    # inside the dataset, outside its content
ROOT_FILES = ("dataset.json", "config.toml", "layout.json")   # written by prepare, listed in the manifest


def check_frame_id(frame_id, where) -> str:
    """``frame_id`` when it is a frame id (000123, rep001_02), else DatasetError naming ``where``:
    a name that goes into a path is checked before the path is built."""
    if not isinstance(frame_id, str) or not FRAME_ID_RE.match(frame_id) or frame_id.endswith("\n"):
        raise DatasetError(f"{where}: frame id {frame_id!r} is not a frame id (expected 000123 or rep001_02)")
    return frame_id


def check_split(split, where) -> str:
    if not isinstance(split, str) or split not in SPLITS:
        raise DatasetError(f"{where}: split {split!r} is not one of {', '.join(SPLITS)}")
    return split


@contextlib.contextmanager
def dataset_lock(root, what: str):
    """The dataset's exclusive lock (render, export); readers need none. A second writer fails at
    once with a DatasetError naming the holder. A lock file that is a symlink (``dvc add`` with
    DVC's symlink cache links ``logs/`` too) is never written through (``core.io.folder_lock``)."""
    with folder_lock(root, what, Path(root) / LOCK_FILE):
        yield


@contextlib.contextmanager
def writer_lock(folder, what: str, option: str = "--out"):
    """Create the output folder ``folder`` and hold, for the block, the lock a renderer takes on
    it: the dataset's (:func:`dataset_lock`) when ``folder`` is a dataset, else its folder lock
    (core.io.output_lock). Yields the folder; bad folders and busy ones are one-line errors."""
    path = Path(folder)
    dataset = str(folder).strip() and path.is_dir() and ((path / LOCK_FILE).exists() or (path / "dataset.json").exists())
    with output_lock(folder, what, option, path / LOCK_FILE if dataset else None) as made:
        yield made


def _only_lock(root: Path) -> bool:
    """True when ``root`` holds nothing but (an empty logs/ or) the dataset lock file."""
    entries = list(root.iterdir())
    if not entries:
        return True
    if [e.name for e in entries] != ["logs"] or not entries[0].is_dir() or entries[0].is_symlink():
        return False
    return all(e.name == LOCK_NAME for e in entries[0].iterdir())


def check_target(root) -> None:
    """Refuse (DatasetError, nothing written) a directory that is neither empty nor a dataset."""
    root = Path(root)
    if root.exists() and not root.is_dir():
        raise DatasetError(f"{root}: not a directory; refusing to write a dataset there")
    if read_identity(root) is None and root.exists() and not _only_lock(root):
        what = "a dataset.json that is not a dataset identity" if (root / "dataset.json").exists() else "no dataset.json"
        raise DatasetError(f"{root}: directory is not empty and holds {what}; "
                           f"refusing to write a dataset into it")


def identity(cfg: Config) -> dict:
    blender = blender_version()
    generator = generator_version()
    return {
        "format": DATASET_FORMAT,
        "version_id": dataset_version_id(cfg.canonical_json(), blender, generator),
        "name": cfg.dataset.name,
        "seed": cfg.dataset.seed,
        "generator_version": generator,
        "blender_version": blender,
        "config": cfg.to_dict(),
    }


def layout_record(cfg: Config) -> dict:
    return {"markers": [{"id": m.id, "section": m.section, "class_id": m.class_id,
                         "class_name": CLASS_NAMES[m.class_id], "index": m.index,
                         "center_mm": list(m.center_mm), "normal": list(m.normal),
                         "diameter_mm": m.diameter_mm, "pass_index": m.pass_index}
                        for m in static_scene(cfg).markers],
            "frame": "each marker's section frame (A: D; B: B's frame)"}


def read_identity(root) -> dict | None:
    path = Path(root) / "dataset.json"
    if not path.exists():
        return None
    try:
        return json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise DatasetError(f"{path}: unreadable dataset identity ({exc})") from exc


IDENTITY_KEYS = ("name", "version_id", "seed", "generator_version", "blender_version", "config")


def load_identity(root, required: tuple[str, ...] = IDENTITY_KEYS) -> dict:
    """dataset.json of ``root`` with the ``required`` keys (exports need only ``config``), its shape
    checked; DatasetError naming the file otherwise."""
    root = Path(root)
    path = root / "dataset.json"
    ident = read_identity(root)
    if ident is None and not path.exists():
        raise DatasetError(f"{root}: not a dockfactory dataset (no dataset.json)")
    if not isinstance(ident, dict):   # also JSON null, which read_identity returns as None
        raise DatasetError(f"{path}: not a dataset identity (expected a JSON object)")
    missing = [k for k in required if k not in ident]
    if missing:
        raise DatasetError(f"{path}: not a dataset identity (no {missing[0]!r})")
    if not isinstance(ident.get("config"), dict) or not isinstance(ident.get("version_id", ""), str):
        raise DatasetError(f"{path}: not a dataset identity ('config' must be an object, 'version_id' text)")
    return ident


def prepare(root, cfg: Config, config_text: str) -> dict:
    """Create the dataset directory or check that it holds this very config.

    Refuses (DatasetError, nothing written) a directory that holds another dataset version or
    files that are not a dockfactory dataset.
    """
    root = Path(root)
    ident = identity(cfg)
    existing = read_identity(root)
    if existing is None:
        check_target(root)
    elif existing.get("version_id") != ident["version_id"]:
        diffs = config_differences(existing.get("config", {}), ident["config"])
        what = "; ".join(diffs[:5]) or (
            f"software versions differ (generator {existing.get('generator_version')} vs "
            f"{ident['generator_version']}, Blender {existing.get('blender_version')} vs "
            f"{ident['blender_version']})")
        raise DatasetError(f"{root}: holds dataset version {existing.get('version_id')}, this config "
                           f"is version {ident['version_id']} ({what}); versions never mix: "
                           f"render into a new directory")
    else:
        return existing
    # every payload is built (and JSON-encoded) before the first write: a failure leaves nothing
    payloads = {"config.toml": config_text.encode("utf-8"),
                "layout.json": _json_bytes(layout_record(cfg)),
                "dataset.json": _json_bytes(ident)}   # last: the directory is now this dataset
    root.mkdir(parents=True, exist_ok=True)
    for name, data in payloads.items():
        write_bytes_atomic(root / name, data)
    return ident


def _json_bytes(obj) -> bytes:
    return (json.dumps(obj, indent=1, allow_nan=False) + "\n").encode("utf-8")


def config_differences(a, b, prefix: str = "") -> list[str]:
    """Readable differences between two resolved config dicts."""
    out = []
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b)):
            key = f"{prefix}.{k}" if prefix else k
            if k not in a:
                out.append(f"{key}: added ({b[k]!r})")
            elif k not in b:
                out.append(f"{key}: removed (was {a[k]!r})")
            else:
                out += config_differences(a[k], b[k], key)
    elif a != b:
        out.append(f"{prefix}: {a!r} -> {b!r}")
    return out


def frame_files(frame_id: str, keep_exr: bool, keep_raw: bool = False) -> dict[str, str]:
    """The files a frame's meta record vouches for: kind -> path relative to the dataset."""
    out = {"image": f"images/{frame_id}.png", "label": f"labels/{frame_id}.json"}
    if keep_exr:
        out["exr"] = f"exr/{frame_id}.exr"
    if keep_raw:
        out["raw"] = f"raw/{frame_id}.png"
    return out


def frame_done(root, frame_id: str, keep_exr: bool, keep_raw: bool = False) -> bool:
    """True when the frame's label (the commit point) and the files it vouches for exist. The meta
    record must name exactly the frame's own files (a record pointing elsewhere is not done); a
    symlink is a file only when it is a DVC cache link (``generator.datasets.dvc_links``)."""
    p = frame_paths(root, frame_id)
    if not (p["label"].is_file() and p["image"].is_file() and p["meta"].is_file()):
        return False
    if (keep_exr and not p["exr"].is_file()) or (keep_raw and not p["raw"].is_file()):
        return False
    try:
        meta = json.loads(p["meta"].read_text())
        expected = frame_files(frame_id, keep_exr, keep_raw)
        if {k: r["path"] for k, r in meta["files"].items() if k in expected} != expected:
            return False
        for rec in meta["files"].values():
            if rec["path"] not in expected.values():
                return False
            path = Path(root) / rec["path"]
            if (path.is_symlink() and cache_link(path, dvc_caches(root)) is None) or path.stat().st_size != rec["bytes"]:
                return False
        label = json.loads(p["label"].read_text())
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return False
    return label.get("frame_id") == frame_id


def write_manifest(root, cfg: Config) -> dict:
    """Write manifest.json for a complete dataset (every planned frame done)."""
    root = Path(root)
    ident = read_identity(root)
    plan = frame_plan(cfg)
    files, frames = [], []
    for spec in plan:
        meta = json.loads(frame_paths(root, spec.frame_id)["meta"].read_text())
        frames.append({"frame_id": spec.frame_id, "split": spec.split, "condition": spec.condition})
        own = set(frame_files(spec.frame_id, cfg.render.keep_exr, cfg.sensor.raw_output).values())
        stray = [r["path"] for r in meta["files"].values() if r["path"] not in own]
        if stray:
            raise DatasetError(f"{frame_paths(root, spec.frame_id)['meta']}: lists {stray[0]!r}, "
                               f"not a file of frame {spec.frame_id}")
        files += [{"path": r["path"], "bytes": r["bytes"], "sha256": r["sha256"]}
                  for r in meta["files"].values()]
        meta_path = frame_paths(root, spec.frame_id)["meta"]
        files.append({"path": f"meta/{meta_path.name}", "bytes": meta_path.stat().st_size,
                      "sha256": sha256_file(meta_path)})
    for name in ROOT_FILES:
        files.append({"path": name, "bytes": (root / name).stat().st_size, "sha256": sha256_file(root / name)})
    counts = Counter((s.split, s.condition) for s in plan)
    manifest = {
        "format": DATASET_FORMAT,
        "version_id": ident["version_id"],
        "name": ident["name"],
        "seed": ident["seed"],
        "software": {"generator": ident["generator_version"], "blender": ident["blender_version"],
                     "numpy": package_version("numpy"), "opencv": package_version("opencv-python-headless"),
                     "openexr": package_version("OpenEXR")},
        "conventions": CONVENTIONS,
        "image_size": [cfg.image.width, cfg.image.height],
        "config": ident["config"],
        "counts": {
            "frames": len(plan),
            "by_split": dict(Counter(s.split for s in plan)),
            "by_condition": dict(Counter(s.condition for s in plan)),
            "by_split_condition": {f"{sp}/{c}": n for (sp, c), n in sorted(counts.items())},
        },
        "frames": frames,
        "files": sorted(files, key=lambda f: f["path"]),
    }
    path = root / "manifest.json"
    if not path.exists() or json.loads(path.read_text()) != manifest:   # a finished dataset stays untouched
        write_json_atomic(path, manifest)
    return manifest
