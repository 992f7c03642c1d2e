"""``dockfactory dataset verify | info | diff``: check, describe and compare dataset directories."""
from __future__ import annotations

import json
import os
import shutil
from dataclasses import dataclass, field
from pathlib import Path

from dockfactory.core.config import config_from_dict
from dockfactory.core.io import is_temp_name, sha256_file
from dockfactory.generator.dataset import (
    DatasetError,
    config_differences,
    read_identity,
)
from dockfactory.generator.export_bop import export_bop
from dockfactory.generator.export_coco import export_coco
from dockfactory.generator.export_yolo import export_yolo
from dockfactory.generator.sampler import frame_plan

EXPORT_WRITERS = {"coco": export_coco, "yolo": export_yolo, "bop": export_bop}

NOT_CONTENT = ("logs", "exports")  # job logs and derived exports are not part of the hashed content


@dataclass
class VerifyReport:
    root: str
    missing: list = field(default_factory=list)
    corrupt: list = field(default_factory=list)      # (path, reason)
    unexpected: list = field(default_factory=list)
    incomplete: str = ""

    @property
    def ok(self) -> bool:
        return not (self.missing or self.corrupt or self.unexpected or self.incomplete)

    def text(self) -> str:
        lines = [f"{self.root}: {'OK: complete and intact' if self.ok else 'FAILED'}"]
        if self.incomplete:
            lines.append(f"  incomplete: {self.incomplete}")
        lines += [f"  missing: {p}" for p in self.missing]
        lines += [f"  corrupt: {p} ({why})" for p, why in self.corrupt]
        lines += [f"  unexpected: {p}" for p in self.unexpected]
        return "\n".join(lines)


def content_files(root: Path) -> list[str]:
    """Every file of the dataset's content (relative paths), excluding logs/ and exports/."""
    out = []
    for p in root.rglob("*"):
        rel = p.relative_to(root)
        if p.is_file() and rel.parts[0] not in NOT_CONTENT and rel.as_posix() != "manifest.json":
            out.append(rel.as_posix())
    return sorted(out)


def load_manifest(root: Path) -> dict:
    path = root / "manifest.json"
    try:
        return json.loads(path.read_text())
    except FileNotFoundError:
        raise DatasetError(f"{root}: no manifest.json (dataset not complete: run its render command again)") from None
    except (OSError, json.JSONDecodeError) as exc:
        raise DatasetError(f"{path}: unreadable manifest ({exc})") from exc


def verify(root) -> VerifyReport:
    root = Path(root)
    report = VerifyReport(str(root))
    if read_identity(root) is None:
        raise DatasetError(f"{root}: not a dockfactory dataset (no dataset.json)")
    try:
        manifest = load_manifest(root)
    except DatasetError as exc:
        report.incomplete = str(exc)
        return report
    listed = {}
    for rec in manifest["files"]:
        listed[rec["path"]] = rec
        path = root / rec["path"]
        if not path.is_file():
            report.missing.append(rec["path"])
            continue
        size = path.stat().st_size
        if size != rec["bytes"]:
            report.corrupt.append((rec["path"], f"{size} bytes, manifest says {rec['bytes']}"))
        elif sha256_file(path) != rec["sha256"]:
            report.corrupt.append((rec["path"], "sha256 differs from the manifest"))
    for rel in content_files(root):
        if rel not in listed:
            report.unexpected.append(rel + (" (temporary file of an interrupted write)" if is_temp_name(Path(rel).name) else ""))
    return report


def info(root) -> dict:
    root = Path(root)
    ident = read_identity(root)
    if ident is None:
        raise DatasetError(f"{root}: not a dockfactory dataset (no dataset.json)")
    out = {"root": str(root), "name": ident["name"], "version_id": ident["version_id"], "seed": ident["seed"],
           "generator_version": ident["generator_version"], "blender_version": ident["blender_version"],
           "image_size": [ident["config"]["image"]["width"], ident["config"]["image"]["height"]]}
    cfg = config_from_dict(ident["config"], str(root / "dataset.json"))
    plan = frame_plan(cfg)
    done = sum(1 for s in plan if (root / "labels" / f"{s.frame_id}.json").is_file())
    out["frames"] = {"planned": len(plan), "done": done}
    manifest_path = root / "manifest.json"
    if manifest_path.exists():
        m = json.loads(manifest_path.read_text())
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


def _file_index(root: Path) -> dict[str, str]:
    manifest_path = root / "manifest.json"
    if manifest_path.exists():
        return {f["path"]: f["sha256"] for f in json.loads(manifest_path.read_text())["files"]}
    return {rel: sha256_file(root / rel) for rel in content_files(root)}


def diff(root_a, root_b) -> dict:
    a, b = Path(root_a), Path(root_b)
    ia, ib = read_identity(a), read_identity(b)
    for r, i in ((a, ia), (b, ib)):
        if i is None:
            raise DatasetError(f"{r}: not a dockfactory dataset (no dataset.json)")
    fa, fb = _file_index(a), _file_index(b)
    return {
        "version": [ia["version_id"], ib["version_id"]],
        "config": config_differences(ia["config"], ib["config"]),
        "software": config_differences({k: ia[k] for k in ("generator_version", "blender_version")},
                                       {k: ib[k] for k in ("generator_version", "blender_version")}),
        "only_in_a": sorted(set(fa) - set(fb)),
        "only_in_b": sorted(set(fb) - set(fa)),
        "different": sorted(p for p in set(fa) & set(fb) if fa[p] != fb[p]),
        "same": sum(1 for p in set(fa) & set(fb) if fa[p] == fb[p]),
    }


def diff_text(d: dict, a, b) -> str:
    lines = [f"A = {a} (version {d['version'][0]})", f"B = {b} (version {d['version'][1]})"]
    lines.append("config: identical" if not d["config"] else "config differences:")
    lines += [f"  {c}" for c in d["config"]]
    lines += [f"software: {c}" for c in d["software"]]
    lines.append(f"files: {d['same']} identical, {len(d['different'])} different, "
                 f"{len(d['only_in_a'])} only in A, {len(d['only_in_b'])} only in B")
    for key, tag in (("different", "~"), ("only_in_a", "-"), ("only_in_b", "+")):
        shown = d[key][:20]
        lines += [f"  {tag} {p}" for p in shown]
        if len(d[key]) > len(shown):
            lines.append(f"  {tag} ... {len(d[key]) - len(shown)} more")
    return "\n".join(lines)


def export(root, fmt: str) -> Path:
    """Write one export of a complete dataset as DIR/exports/<fmt>/ (built aside, then renamed)."""
    root = Path(root)
    if fmt not in EXPORT_WRITERS:
        raise DatasetError(f"unknown export format {fmt!r} (known: {', '.join(EXPORT_WRITERS)})")
    if not (root / "manifest.json").exists():
        raise DatasetError(f"{root}: dataset is not complete (no manifest.json); finish rendering first")
    final = root / "exports" / fmt
    tmp = root / "exports" / f".{fmt}.tmp-{os.getpid()}"
    shutil.rmtree(tmp, ignore_errors=True)
    EXPORT_WRITERS[fmt](root, tmp)
    if final.exists():
        shutil.rmtree(final)
    os.replace(tmp, final)
    return final
