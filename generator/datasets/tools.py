"""``dockfactory dataset verify | info | diff | export``: check, describe, compare and export dataset
directories (the content diff lives in ``generator.datasets.diff``)."""
from __future__ import annotations

import json
from pathlib import Path

from dockfactory.core.config import config_from_identity
from dockfactory.core.io import output_lock, remove_stale_temps, write_json_atomic
from dockfactory.generator.datasets.folder import (
    DatasetError,
    dataset_lock,
    load_identity,
    read_identity,
)
from dockfactory.generator.datasets.check import (  # noqa: F401  (verify: the CLI's and tests' entry)
    VerifyReport,
    content_files,
    load_manifest,
    verify,
)
from dockfactory.generator.datasets.diff import diff, diff_text  # noqa: F401  (the CLI's and tests' entry)
from dockfactory.generator.datasets.reader import Dataset
from dockfactory.generator.datasets.dvc_links import outside_exports
from dockfactory.generator.exports import WRITERS
from dockfactory.generator.exports.files import folder_built_aside
from dockfactory.generator.sampler import frame_plan

EXPORT_WRITERS = WRITERS   # the export registry's writers by name (generator.exports.FORMATS: each format module's own)

EXPORT_MARK = ".dockfactory-export.json"   # written last into an export: a folder without it is not one
STALE_EXPORT_S = 6 * 3600.0                 # a temporary export of another host counts as stale after this


def info(root) -> dict:
    """Describe the dataset at ``root`` from its identity and manifest (``dockfactory dataset info``; no file hashed).

    Parameters
    ----------
    root : path
        The dataset folder, complete or not.

    Returns
    -------
    dict
        ``root``, ``name``, ``version_id``, ``seed``, ``generator_version``, ``blender_version``, ``image_size``
        ([width, height] px), ``frames`` ({planned, done}: frames of the plan whose label exists) and ``complete``
        (a manifest exists); when complete also ``counts`` (the manifest's) and ``bytes`` (its files' total size).

    Raises
    ------
    DatasetError
        ``root`` holds no ``dataset.json`` or not a dataset identity, or an unreadable manifest (no ``files`` list
        of {path, bytes, sha256}, no ``counts`` with ``by_split_condition``).
    ConfigError
        The identity's config is not a config this version reads.
    """
    root = Path(root)
    ident = load_identity(root)
    cfg = config_from_identity(ident["config"], str(root / "dataset.json"))
    out = {"root": str(root), "name": ident["name"], "version_id": ident["version_id"], "seed": ident["seed"],
           "generator_version": ident["generator_version"], "blender_version": ident["blender_version"],
           "image_size": [cfg.image.width, cfg.image.height]}
    plan = frame_plan(cfg)
    done = sum(1 for s in plan if (root / "labels" / f"{s.frame_id}.json").is_file())
    out["frames"] = {"planned": len(plan), "done": done}
    manifest_path = root / "manifest.json"
    if manifest_path.exists():
        m = load_manifest(root)
        if not isinstance(m.get("counts"), dict) or not isinstance(m["counts"].get("by_split_condition"), dict):
            raise DatasetError(f"{manifest_path}: unreadable manifest (no 'counts' with 'by_split_condition')")
        out["complete"] = True
        out["counts"] = m["counts"]
        out["bytes"] = sum(f["bytes"] for f in m["files"])
    else:
        out["complete"] = False
    return out


def info_text(d: dict) -> str:
    lines = [f"{d['root']}: dataset {d['name']!r} version {d['version_id']} (seed {d['seed']})",
             f"  generator {d['generator_version']}, Blender {d['blender_version']}, images {d['image_size'][0]}x{d['image_size'][1]}",
             f"  frames: {d['frames']['done']} of {d['frames']['planned']} done; "
             + ("complete" if d["complete"] else "incomplete (no manifest yet)")]
    if d["complete"]:
        lines.append(f"  size: {d['bytes'] / 1e6:.1f} MB")
        for key, n in d["counts"]["by_split_condition"].items():
            lines.append(f"  {key:22s} {n}")
    return "\n".join(lines)


def export_complete(root, fmt: str) -> bool:
    """True when DIR/exports/<fmt>/ is a finished export of this dataset version (its completion
    mark, written last, names the format and the version): a partial folder is not done."""
    root = Path(root)
    mark = root / "exports" / fmt / EXPORT_MARK
    try:
        rec = json.loads(mark.read_text())
        ident = read_identity(root) or {}
        return (not (root / "exports" / fmt).is_symlink() and isinstance(rec, dict) and rec.get("format") == fmt
                and rec.get("version_id") == ident.get("version_id"))
    except (OSError, ValueError, DatasetError):
        return False


def write_export(root, fmt: str, ds: Dataset | None = None, dest=None) -> Path:
    """:func:`export` for a caller that already holds the lock of the folder written (``render``:
    the dataset's); ``ds``: the dataset already opened (one check for several formats), else it
    is opened here; ``dest``: the folder that receives ``<fmt>/`` (default the dataset's
    ``exports/``)."""
    root = Path(root)
    if fmt not in EXPORT_WRITERS:
        raise DatasetError(f"unknown export format {fmt!r} (known: {', '.join(EXPORT_WRITERS)})")
    if not (root / "manifest.json").exists():
        raise DatasetError(f"{root}: dataset is not complete (no manifest.json); finish rendering first")
    exports = root / "exports" if dest is None else Path(dest)
    if exports.is_symlink() or (exports / fmt).is_symlink():
        raise DatasetError(f"{exports}: is (or holds) a symlink; exports are written into real folders only")
    exports.mkdir(parents=True, exist_ok=True)
    # built aside by a killed export (of this host, or old): never part of any export
    remove_stale_temps(exports, max_age_s=STALE_EXPORT_S, own=True)
    final = exports / fmt
    with folder_built_aside(final) as tmp:   # old or new, never partial
        ds = ds if ds is not None else Dataset.open(root)
        EXPORT_WRITERS[fmt](ds, tmp)
        n_files = sum(1 for p in tmp.rglob("*") if p.is_file())
        write_json_atomic(tmp / EXPORT_MARK, {"format": fmt, "version_id": ds.version_id, "files": n_files})
    return final


def export(root, fmt: str, ds: Dataset | None = None, dest=None) -> Path:
    """Write one export of a complete dataset as DIR/exports/<fmt>/ (or ``dest``/<fmt>/).

    Built aside, then swapped in by rename (an interrupted export leaves the old one, the new one or none, never a
    partial one), under the lock of the folder written (the dataset's, or ``dest``'s). For a dataset tracked by DVC
    whose project does not ignore ``exports/``, ``dest`` defaults to a folder beside the tracked one
    (``dvc_links.outside_exports``): ``dvc status`` stays clean.

    Parameters
    ----------
    root : path
        The complete dataset folder.
    fmt : str
        A name of ``EXPORT_WRITERS``, the export registry (``dockfactory dataset export --help`` lists them).
    ds : Dataset, optional
        The dataset already opened (one check for several formats); None: opened (and checked) here.
    dest : path, optional
        The folder that receives ``<fmt>/``, outside the dataset; None: the dataset's ``exports/``.

    Returns
    -------
    Path
        The export folder ``<dest>/<fmt>``, holding its completion mark (format, version id, file count).

    Raises
    ------
    DatasetError
        An unknown ``fmt``; ``root`` not a dataset, incomplete (no manifest) or damaged; ``dest`` inside it; the
        export folder a symlink; a dataset the format cannot export (a video without docking runs).
    DockfactoryError
        Another render or export holds the folder's lock (core.io.FolderBusy), or ``dest`` cannot be made.
    """
    root = Path(root)
    if fmt not in EXPORT_WRITERS:
        raise DatasetError(f"unknown export format {fmt!r} (known: {', '.join(EXPORT_WRITERS)})")
    load_identity(root)   # a dataset (one-line error naming dataset.json otherwise)
    dest = dest if dest is not None else outside_exports(root)
    if dest is not None:
        if Path(dest).resolve().is_relative_to(root.resolve()):
            raise DatasetError(f"--out {dest}: inside the dataset {root}; give a folder outside it "
                               f"(inside, exports go to {root / 'exports'} without --out)")
        with output_lock(dest, f"export {fmt}"):
            return write_export(root, fmt, ds, dest)
    with dataset_lock(root, f"export {fmt}"):
        return write_export(root, fmt, ds)
