"""``dockfactory dataset diff A B``: what differs between two dataset folders, by content.

Compared: the identities (version id, config key by key, generator and Blender versions) and
every file of the content as it is on disk (``manifest.json`` included; not ``logs/``,
``exports/``, the card ``README.md`` or ``hf/``: derived files): its size and sha256, whatever the
manifests say, so a corrupted copy shows its changed files even when its manifest is intact.
Labels that differ are compared field by field (``markers[3].center_px[0]: 101.2 -> 101.7``).
A symlink is compared by where it points, never followed, except a DVC cache link
(``generator.datasets.dvc_links``), whose file is compared.

Bad input (a folder that is not a dataset, an unreadable identity or manifest) raises
DatasetError; the command line exits like ``git diff --exit-code``: 0 identical, 1 different,
2 bad input.
"""
from __future__ import annotations

import json
import os
from pathlib import Path

from dockfactory.core.io import sha256_file
from dockfactory.generator.datasets.folder import config_differences, load_identity
from dockfactory.generator.datasets.check import NOT_CONTENT, content_files, load_manifest
from dockfactory.generator.datasets.dvc_links import cache_link, dvc_caches

MAX_FIELDS = 20   # field differences kept per label


def file_print(path: Path, caches) -> tuple:
    """(kind, size, sha256) of a file on disk; ("symlink", target, "") for a link not into a DVC
    cache; ("unreadable", why, "") for a file that cannot be read."""
    if path.is_symlink() and cache_link(path, caches) is None:
        return ("symlink", os.readlink(path), "")
    try:
        return ("file", path.stat().st_size, sha256_file(path))
    except OSError as exc:
        return ("unreadable", exc.strerror or str(exc), "")


def content_prints(root: Path) -> dict[str, tuple]:
    """relative path -> :func:`file_print` of every content file of ``root`` and its manifest."""
    caches = dvc_caches(root)
    rels = content_files(root)
    rels += [rel for rel in ("manifest.json",) if (root / rel).exists() or (root / rel).is_symlink()]
    for dirpath, _, filenames in os.walk(root):   # symlinks content_files cannot see (dangling ones)
        for name in filenames:
            p = Path(dirpath) / name
            rel = p.relative_to(root).as_posix()
            if p.is_symlink() and not p.exists() and rel.split("/")[0] not in NOT_CONTENT:
                rels.append(rel)
    return {rel: file_print(root / rel, caches) for rel in sorted(set(rels))}


def field_differences(a, b, path: str = "", out: list | None = None) -> list[str]:
    """Leaf-by-leaf differences of two JSON values: ``path: a -> b`` (at most MAX_FIELDS + 1)."""
    out = [] if out is None else out
    if len(out) > MAX_FIELDS:
        return out
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b), key=str):
            key = f"{path}.{k}" if path else str(k)
            if k not in a or k not in b:
                out.append(f"{key}: {'added' if k not in a else 'removed'}")
            else:
                field_differences(a[k], b[k], key, out)
    elif isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        for i, (x, y) in enumerate(zip(a, b)):
            field_differences(x, y, f"{path}[{i}]", out)
    elif a != b or type(a) is not type(b):
        out.append(f"{path or '(whole file)'}: {json.dumps(a)[:60]} -> {json.dumps(b)[:60]}")
    return out


def _what(p: tuple) -> str:
    return {"symlink": f"a symlink to {p[1]}", "unreadable": f"unreadable ({p[1]})"}.get(p[0], f"{p[1]} bytes")


def _why(pa: tuple, pb: tuple) -> str:
    """Why two prints of one path differ, in a few words."""
    if pa[0] != "file" or pb[0] != "file" or pa[1] != pb[1]:
        return f"A: {_what(pa)}, B: {_what(pb)}"
    return "same size, sha256 differs"


def _label_fields(a: Path, b: Path) -> list[str]:
    try:
        return field_differences(json.loads(a.read_bytes()), json.loads(b.read_bytes()))
    except (OSError, ValueError, RecursionError) as exc:
        return [f"(not comparable as JSON: {exc})"]


def diff(root_a, root_b) -> dict:
    """What differs between datasets ``root_a`` (A) and ``root_b`` (B), by content (module docstring).

    Parameters
    ----------
    root_a, root_b : path
        The two dataset folders, complete or not.

    Returns
    -------
    dict
        ``version`` [A's, B's], ``config`` and ``software`` (readable differences), ``only_in_a``, ``only_in_b``,
        ``different`` (content paths), ``why`` (path -> why, in a few words), ``label_fields`` (label path -> its
        field differences), ``same`` (identical files) and ``identical`` (True when nothing differs).

    Raises
    ------
    DatasetError
        A folder without ``dataset.json`` or whose identity is unreadable, or a ``manifest.json`` that is not one.
    """
    a, b = Path(root_a), Path(root_b)
    ia, ib = load_identity(a), load_identity(b)
    for root in (a, b):
        if (root / "manifest.json").exists():
            load_manifest(root)   # a manifest that is not one is bad input, as for info
    fa, fb = content_prints(a), content_prints(b)
    both = sorted(set(fa) & set(fb))
    different = [p for p in both if fa[p] != fb[p]]
    labels = {p: _label_fields(a / p, b / p) for p in different
              if p.startswith("labels/") and fa[p][0] == fb[p][0] == "file"}
    out = {
        "version": [ia["version_id"], ib["version_id"]],
        "config": config_differences(ia["config"], ib["config"]),
        "software": config_differences({k: ia[k] for k in ("generator_version", "blender_version")},
                                       {k: ib[k] for k in ("generator_version", "blender_version")}),
        "only_in_a": sorted(set(fa) - set(fb)),
        "only_in_b": sorted(set(fb) - set(fa)),
        "different": different,
        "why": {p: _why(fa[p], fb[p]) for p in different},
        "label_fields": labels,
        "same": len(both) - len(different),
    }
    out["identical"] = not (out["version"][0] != out["version"][1] or out["config"] or out["software"]
                            or out["only_in_a"] or out["only_in_b"] or different)
    return out


def diff_text(d: dict, a, b) -> str:
    """The report of :func:`diff` for people: what differs, file by file, label field by field."""
    lines = [f"A = {a} (version {d['version'][0]})", f"B = {b} (version {d['version'][1]})"]
    lines.append("config: identical" if not d["config"] else "config differences:")
    lines += [f"  {c}" for c in d["config"]]
    lines += [f"software: {c}" for c in d["software"]]
    lines.append(f"files: {d['same']} identical, {len(d['different'])} different, "
                 f"{len(d['only_in_a'])} only in A, {len(d['only_in_b'])} only in B")
    for key, tag in (("different", "~"), ("only_in_a", "-"), ("only_in_b", "+")):
        shown = d[key][:20]
        for p in shown:
            lines.append(f"  {tag} {p}" + (f" ({d['why'][p]})" if key == "different" else ""))
            fields = d["label_fields"].get(p, []) if key == "different" else []
            lines += [f"      {f}" for f in fields[:5]]
            if len(fields) > 5:
                lines.append(f"      ... {'more than ' if len(fields) > MAX_FIELDS else ''}{len(fields) - 5} more fields")
        if len(d[key]) > len(shown):
            lines.append(f"  {tag} ... {len(d[key]) - len(shown)} more")
    lines.append("identical" if d["identical"] else "different")
    return "\n".join(lines)
