"""Checking a dataset directory: its identity, its manifest against its plan, its files against its
manifest. ``verify`` reports every problem; ``Dataset.open`` (generator.datasets.reader) runs the same
checks and refuses the dataset naming its first problems. With ``hash_bulk=False`` images and EXR
are compared by size only (the small files, labels included, are always hashed).

Derived files (not content, never in the manifest, regenerable): ``logs/``, ``exports/``, the
dataset card ``README.md`` and its Hugging Face view ``hf/`` (``generator.datasets.card``).

Why and how: docs/datasets.md, "The chain of trust".
"""
from __future__ import annotations

import json
import os
from dataclasses import dataclass, field, replace
from pathlib import Path

from dockfactory.core.config import Config, config_from_identity
from dockfactory.core.errors import DockfactoryError
from dockfactory.core.io import dead_writer, is_temp_name, sha256_file
from dockfactory.generator.datasets.folder import (
    DATASET_FORMAT,
    ROOT_FILES,
    SPLITS,
    DatasetError,
    frame_files,
    load_identity,
)
from dockfactory.generator.datasets.dvc_links import CACHE_ENV, cache_link, dvc_caches
from dockfactory.generator.sampler import frame_plan
from dockfactory.generator.version import dataset_version_id, generator_version

# job logs, derived exports, the dataset card and its Hugging Face view: not part of the hashed content
NOT_CONTENT = ("logs", "exports", "README.md", "hf")
BULK_DIRS = ("images", "exr", "raw")      # the cheap check compares these by size only (sha256 in verify)


@dataclass
class VerifyReport:
    root: str
    missing: list = field(default_factory=list)
    corrupt: list = field(default_factory=list)      # (path, reason)
    unexpected: list = field(default_factory=list)
    unsafe: list = field(default_factory=list)       # (path, reason): outside the dataset, symlinks
    inconsistent: list = field(default_factory=list)  # (what, reason): identity, manifest and plan disagree
    ignored: list = field(default_factory=list)      # temporaries of dead writers (never content)
    incomplete: str = ""

    @property
    def ok(self) -> bool:
        return not (self.missing or self.corrupt or self.unexpected or self.unsafe or self.inconsistent
                    or self.incomplete)

    def problems(self) -> list[str]:
        """Every problem, one line each, the most telling first."""
        out = [f"incomplete: {self.incomplete}"] if self.incomplete else []
        out += [f"inconsistent: {p} ({why})" for p, why in self.inconsistent]
        out += [f"unsafe: {p} ({why})" for p, why in self.unsafe]
        out += [f"missing: {p}" for p in self.missing]
        out += [f"corrupt: {p} ({why})" for p, why in self.corrupt]
        out += [f"unexpected: {p}" for p in self.unexpected]
        return out

    def text(self) -> str:
        lines = [f"{self.root}: {'OK: complete and intact' if self.ok else 'FAILED'}"]
        lines += [f"  {p}" for p in self.problems()]
        lines += [f"  ignored: {p} (temporary file of a writer that died; never part of the dataset)"
                  for p in self.ignored]
        return "\n".join(lines)

    def refusal(self, shown: int = 3) -> str:
        """One line refusing the dataset, naming its first problems."""
        if self.incomplete and not (self.problems()[1:]):
            return self.incomplete
        probs = self.problems()
        more = f"; and {len(probs) - shown} more" if len(probs) > shown else ""
        return (f"{self.root}: damaged dataset, refused ({len(probs)} problem{'s' * (len(probs) != 1)}: "
                f"{'; '.join(probs[:shown])}{more}); `dockfactory dataset verify {self.root}` lists them all")


@dataclass
class Checked:
    """What the checks read on the way: the identity, its config and plan, the manifest."""
    identity: dict
    config: Config
    plan: tuple
    manifest: dict


def content_files(root: Path) -> list[str]:
    """Every file of the dataset's content (relative paths), excluding logs/ and exports/."""
    out = []
    for p in root.rglob("*"):
        rel = p.relative_to(root)
        if p.is_file() and rel.parts[0] not in NOT_CONTENT and rel.as_posix() != "manifest.json":
            out.append(rel.as_posix())
    return sorted(out)


def load_manifest(root: Path) -> dict:
    """manifest.json of ``root``, its shape checked (a ``files`` list of {path, bytes, sha256});
    DatasetError naming the file otherwise."""
    path = root / "manifest.json"
    try:
        manifest = json.loads(path.read_text())
    except FileNotFoundError:
        raise DatasetError(f"{root}: dataset is not complete (no manifest.json): run its render command "
                           f"again to finish it") from None
    except (OSError, ValueError) as exc:
        raise DatasetError(f"{path}: unreadable manifest ({exc})") from exc
    files = manifest.get("files") if isinstance(manifest, dict) else None
    if not isinstance(files, list):
        raise DatasetError(f"{path}: unreadable manifest (expected an object with a 'files' list)")
    for i, rec in enumerate(files):
        if not (isinstance(rec, dict) and isinstance(rec.get("path"), str) and isinstance(rec.get("sha256"), str)
                and isinstance(rec.get("bytes"), int) and not isinstance(rec.get("bytes"), bool)):
            raise DatasetError(f"{path}: unreadable manifest (files[{i}] is not "
                               f"{{path: text, bytes: integer, sha256: text}})")
    return manifest


def outside_reason(rel) -> str:
    """Why manifest path ``rel`` does not name a file inside the dataset ("" when it does): it
    must be a plain relative POSIX path, without ``..``, ``.`` or empty parts."""
    if not isinstance(rel, str) or not rel:
        return "not a path"
    if "\\" in rel or "\x00" in rel:
        return "outside the dataset (not a plain relative path)"
    if rel.startswith("/") or (len(rel) > 1 and rel[1] == ":"):
        return "outside the dataset (absolute path)"
    if any(part in ("", ".", "..") for part in rel.split("/")):
        return "outside the dataset (.. or empty parts)"
    return ""


def symlinks(root: Path, caches: tuple[Path, ...] = ()) -> list[tuple[str, str]]:
    """Every symlink inside the dataset (logs and exports included) but the DVC cache links of
    files (into one of ``caches``): (relative path, reason)."""
    out = []
    real_root = root.resolve()
    for dirpath, dirnames, filenames in os.walk(root):   # never follows symlinked folders
        for name in dirnames + filenames:
            p = Path(dirpath) / name
            if not p.is_symlink() or (name in filenames and cache_link(p, caches) is not None):
                continue
            target = os.readlink(p)
            rel = p.relative_to(root).as_posix()
            if not p.exists():
                out.append((rel, f"dangling symlink to {target}"))
            elif not p.resolve().is_relative_to(real_root):
                out.append((rel, f"symlink to {target}, outside the dataset and not into a DVC cache "
                                 f"(name one in {CACHE_ENV})"))
            else:
                out.append((rel, f"symlink to {target}; a dataset holds files, not links"))
    return sorted(out)


def plan_files(cfg: Config, plan) -> set[str]:
    """Every file a complete dataset of ``cfg`` holds (relative paths): each planned frame's own
    files and meta record, and the identity, config and layout."""
    out = set(ROOT_FILES)
    for spec in plan:
        out.update(frame_files(spec.frame_id, cfg.render.keep_exr, cfg.sensor.raw_output).values())
        out.add(f"meta/{spec.frame_id}.json")
    return out


def _check_identity(root: Path, ident: dict, report: VerifyReport) -> tuple[Config, tuple]:
    """The identity's config and plan. The version id is recomputed from the stored config (as
    stored: a later config schema with more defaulted keys does not change it); one that differs
    (an edited dataset.json) or another format is inconsistent."""
    where = root / "dataset.json"
    if ident.get("format") != DATASET_FORMAT:
        report.inconsistent.append(("dataset.json", f"format {ident.get('format')!r}, expected {DATASET_FORMAT!r} "
                                                    f"(a dataset of another tool or version)"))
    canonical = json.dumps(ident["config"], sort_keys=True, separators=(",", ":"))
    expected = dataset_version_id(canonical, str(ident["blender_version"]), str(ident["generator_version"]))
    if expected != ident["version_id"]:
        report.inconsistent.append(("dataset.json", f"its config and software give version {expected}, it says "
                                                    f"{ident['version_id']} (edited after rendering?)"))
    cfg = config_from_identity(ident["config"], str(where))
    return cfg, frame_plan(cfg)


def _manifest_frames(manifest: dict) -> list | None:
    """The manifest's frame records when well formed ({frame_id, split, condition} texts), else None."""
    frames = manifest.get("frames")
    if not isinstance(frames, list):
        return None
    keys = ("frame_id", "split", "condition")
    if not all(isinstance(f, dict) and set(f) == set(keys) and all(isinstance(f[k], str) for k in keys)
               for f in frames):
        return None
    return frames


def _frames_problem(frames: list | None, plan, exact: bool) -> str:
    """Why the manifest's frames are not the plan's ("" when they are). ``exact``: splits and
    conditions must match too (a dataset of this generator version; an older one keeps the splits
    its own sampler drew, and only its frame ids are the config's)."""
    if frames is None:
        return "no well-formed 'frames' list ({frame_id, split, condition} each)"
    ids = [f["frame_id"] for f in frames]
    want = [s.frame_id for s in plan]
    if ids != want:
        gone = [fid for fid in want if fid not in set(ids)]
        return (f"frame {gone[0]} of the plan is not listed ({len(gone)} missing)" if gone else
                f"{len(ids)} frames listed, the plan has {len(want)}")
    if exact:
        bad = [f["frame_id"] for f, s in zip(frames, plan) if (f["split"], f["condition"]) != (s.split, s.condition)]
        if bad:
            return f"frame {bad[0]}: split or condition differ from the plan ({len(bad)} frames)"
    if any(f["split"] not in SPLITS for f in frames):
        return "a split that is not one of " + ", ".join(SPLITS)
    return ""


def _check_manifest(ident: dict, cfg: Config, plan, manifest: dict, report: VerifyReport) -> tuple:
    """The manifest must be this version's and list exactly the plan's frames and files; returns
    the plan with the manifest's splits and conditions (the same, for this generator version)."""
    if manifest.get("version_id") != ident["version_id"]:
        report.inconsistent.append(("manifest.json", f"version {manifest.get('version_id')!r}, dataset.json says "
                                                     f"{ident['version_id']}"))
    frames = _manifest_frames(manifest)
    why = _frames_problem(frames, plan, exact=ident["generator_version"] == generator_version())
    if why:
        report.inconsistent.append(("manifest.json", f"frames differ from the plan: {why}"))
    else:
        plan = tuple(replace(s, split=f["split"], condition=f["condition"]) for s, f in zip(plan, frames))
    listed_files = {rec["path"] for rec in manifest["files"]}
    expected = plan_files(cfg, plan)
    for rel in sorted(expected - listed_files)[:20]:
        report.inconsistent.append((rel, "a file of the plan the manifest does not list"))
    for rel in sorted(listed_files - expected)[:20]:
        if not outside_reason(rel):   # paths outside are reported as unsafe
            report.inconsistent.append((rel, "listed in the manifest, not a file of this dataset's plan"))
    return plan


def _check_files(root: Path, manifest: dict, report: VerifyReport, hash_bulk: bool) -> set[str]:
    """Each manifest file against its record (size; sha256 of all, or of all but images/EXR);
    returns the listed paths."""
    listed = set()
    linked = {p for p, _ in report.unsafe}
    for rec in manifest["files"]:
        why = outside_reason(rec["path"])
        if why:   # checked before the path is built: never read
            report.unsafe.append((str(rec["path"]), why))
            continue
        listed.add(rec["path"])
        path = root / rec["path"]
        if rec["path"] in linked or any(p.is_symlink() for p in path.parents if p != root and p.is_relative_to(root)):
            continue   # the symlink (a file or one of its folders) is reported once, by symlinks()
        if not path.is_file():
            report.missing.append(rec["path"])
            continue
        size = path.stat().st_size
        if size != rec["bytes"]:
            report.corrupt.append((rec["path"], f"{size} bytes, manifest says {rec['bytes']}"))
        elif (hash_bulk or rec["path"].split("/")[0] not in BULK_DIRS) and sha256_file(path) != rec["sha256"]:
            report.corrupt.append((rec["path"], "sha256 differs from the manifest"))
    return listed


def _check_unlisted(root: Path, listed: set[str], report: VerifyReport) -> None:
    linked = {p for p, _ in report.unsafe}
    for rel in content_files(root):
        if rel in listed or rel in linked:
            continue
        if is_temp_name(Path(rel).name) and dead_writer(root / rel):
            report.ignored.append(rel)
        else:
            report.unexpected.append(rel + (" (temporary file of a write in progress or of another host)"
                                            if is_temp_name(Path(rel).name) else ""))


def inspect(root, hash_bulk: bool = True) -> tuple[VerifyReport, Checked | None]:
    """Every check of the dataset at ``root`` (sha256 of images and EXR only with ``hash_bulk``):
    the report, and what was read (None when the dataset is incomplete or its identity damaged).
    A folder without dataset.json is not a dataset at all: DatasetError."""
    root = Path(root)
    report = VerifyReport(str(root))
    if not (root / "dataset.json").exists():
        load_identity(root)   # raises: not a dataset at all
    report.unsafe += symlinks(root, dvc_caches(root))
    try:
        ident = load_identity(root)
        cfg, plan = _check_identity(root, ident, report)
    except DockfactoryError as exc:   # a dataset whose identity is damaged: a problem, not bad input
        report.corrupt.append(("dataset.json", str(exc)))
        return report, None
    try:
        manifest = load_manifest(root)
    except DatasetError as exc:
        report.incomplete = str(exc)
        return report, None
    plan = _check_manifest(ident, cfg, plan, manifest, report)
    listed = _check_files(root, manifest, report, hash_bulk)
    _check_unlisted(root, listed, report)
    return report, Checked(ident, cfg, plan, manifest)


def verify(root) -> VerifyReport:
    """Check the dataset at ``root``, every byte hashed (``dockfactory dataset verify``).

    Its identity (the version id recomputed from the stored config), its manifest against its plan,
    every listed file's size and sha256 against the manifest, no unlisted file and no symlink but
    DVC cache links (module docstring). A damaged dataset is a report, not an exception.

    Parameters
    ----------
    root : path
        The dataset folder (holding ``dataset.json``).

    Returns
    -------
    VerifyReport
        ``ok`` True when the dataset is complete and intact; else ``problems()`` lists each one
        (incomplete: no manifest yet; inconsistent; unsafe; missing; corrupt; unexpected), one line
        each; ``ignored`` names the temporaries of dead writers.

    Raises
    ------
    DatasetError
        ``root`` holds no ``dataset.json``: not a dataset at all.
    OSError
        A file of the dataset that exists but cannot be read (permissions).
    """
    return inspect(root, hash_bulk=True)[0]
