"""Datasets tracked by DVC: the links its cache puts in place, and where exports may go.

``dvc add DIR`` with ``cache.type symlink`` replaces every file of DIR by a symlink into the DVC
cache (``.dvc/cache/files/md5/xx/...``); hardlinks and reflinks are regular files and need nothing.
A symlink inside a dataset is accepted only when it is such a link (``cache_link``): it resolves
to a regular file inside a DVC cache. The caches are

- ``DOCKFACTORY_DVC_CACHE``: cache folders the user names (``os.pathsep``-separated), and
- the cache of the DVC project the dataset sits in: the first folder upward from the dataset
  that holds ``.dvc/``; its cache is ``.dvc/cache`` unless ``.dvc/config`` (or ``config.local``)
  sets ``[cache] dir`` (relative to ``.dvc/``, as DVC reads it).

Why and how: docs/datasets.md, "DVC links and exports".
"""
from __future__ import annotations

import configparser
import os
from pathlib import Path

CACHE_ENV = "DOCKFACTORY_DVC_CACHE"
# .dvcignore lines (at the DVC project's root) that dockfactory recognises as ignoring a dataset's
# derived folders in every dataset of the project (gitignore syntax: a name matches at any depth)
IGNORE_LINES = {"exports": ("exports", "exports/", "**/exports", "**/exports/"),
                "logs": ("logs", "logs/", "**/logs", "**/logs/")}


def dvc_project(root) -> Path | None:
    """The DVC project folder (the first folder upward from ``root`` holding ``.dvc/``), or None."""
    here = Path(root).resolve()
    for folder in (here, *here.parents):
        if (folder / ".dvc").is_dir():
            return folder
    return None


def _configured_cache(dot_dvc: Path) -> Path | None:
    """``[cache] dir`` of the project's ``config.local`` or ``config`` (the local one wins)."""
    for name in ("config.local", "config"):
        parser = configparser.ConfigParser()
        try:
            parser.read(dot_dvc / name, encoding="utf-8")
        except (configparser.Error, UnicodeDecodeError):
            continue
        value = parser.get("cache", "dir", fallback="").strip()
        if value:
            return (dot_dvc / value).resolve()
    return None


def dvc_caches(root) -> tuple[Path, ...]:
    """The resolved DVC cache folders a link of the dataset at ``root`` may point into."""
    out = [Path(p).expanduser().resolve() for p in os.environ.get(CACHE_ENV, "").split(os.pathsep) if p.strip()]
    project = dvc_project(root)
    if project is not None:
        dot_dvc = project / ".dvc"
        out.append(_configured_cache(dot_dvc) or (dot_dvc / "cache").resolve())
    return tuple(dict.fromkeys(out))


def cache_link(path: Path, caches: tuple[Path, ...]) -> Path | None:
    """The file a symlink ``path`` resolves to when it is a DVC cache link (a regular file inside
    one of ``caches``), else None (not a symlink, dangling, a loop, or pointing elsewhere)."""
    if not caches or not path.is_symlink():
        return None
    try:
        target = path.resolve(strict=True)
    except (OSError, RuntimeError):
        return None
    if not target.is_file():
        return None
    return target if any(target.is_relative_to(c) for c in caches) else None


def tracking_file(root) -> Path | None:
    """The ``.dvc`` file that tracks ``root`` or one of its parents (``dvc add`` writes
    ``NAME.dvc`` beside the folder NAME it adds) inside a DVC project, or None."""
    project = dvc_project(root)
    if project is None:
        return None
    here = Path(root).resolve()
    for folder in (here, *here.parents):
        if folder == project:
            break
        candidate = folder.parent / f"{folder.name}.dvc"
        if candidate.is_file():
            return candidate
    return None


def ignored(root, folder: str) -> bool:
    """True when the DVC project's root ``.dvcignore`` ignores ``folder`` (``exports`` or ``logs``)
    of every dataset, or of this one (``<path of root in the project>/<folder>/``)."""
    project = dvc_project(root)
    if project is None:
        return False
    try:
        lines = {ln.strip() for ln in (project / ".dvcignore").read_text(encoding="utf-8").splitlines()}
    except (OSError, UnicodeDecodeError):
        return False
    rel = Path(root).resolve().relative_to(project).as_posix()
    own = {f"{rel}/{folder}", f"{rel}/{folder}/", f"/{rel}/{folder}", f"/{rel}/{folder}/"}
    return bool(lines & (set(IGNORE_LINES[folder]) | own))


def outside_exports(root) -> Path | None:
    """Where exports of the dataset at ``root`` go by default when they may not go inside it (it is
    tracked by DVC and its project's ``.dvcignore`` does not ignore ``exports/``): beside the
    tracked folder T, ``T.exports/`` (plus the dataset's path inside T); None when they may go
    inside (``root/exports/``)."""
    tracker = tracking_file(root)
    if tracker is None or ignored(root, "exports"):
        return None
    tracked = tracker.with_suffix("")
    return tracked.parent / f"{tracked.name}.exports" / Path(root).resolve().relative_to(tracked)


def outside_note(root) -> str:
    """"" when exports of the dataset at ``root`` go inside it, else a line saying where they go
    instead and why (:func:`outside_exports`)."""
    dest = outside_exports(root)
    if dest is None:
        return ""
    return (f"{root}: tracked by DVC ({tracking_file(root)}); exports written inside it would make `dvc status` "
            f"report it modified, so `dockfactory dataset export` writes them to {dest} (or --out FOLDER); to "
            f"keep them inside, add the line `exports/` to {dvc_project(root) / '.dvcignore'} before `dvc add`")
