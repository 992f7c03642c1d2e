"""A re-render checked against a published dataset (``dockfactory dataset verify DIR --manifest M``).

Anyone can re-render any subset of a published dataset (``dockfactory render CONFIG --out DIR
--frames ...`` or ``--shard K/N``) and check it against the published ``manifest.json`` (every
file's sha256) and its fingerprints (``fingerprints.npz`` beside the manifest):

Frames of the manifest that were not re-rendered are not checked (a subset is the point).

Why and how: docs/datasets.md, "Checking a re-render".
"""
from __future__ import annotations

import json
import math
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path

from dockfactory.core.cv import cv2
import numpy as np

from dockfactory.core.config import config_from_dict, config_from_identity
from dockfactory.core.errors import DockfactoryError
from dockfactory.core.io import sha256_bytes, sha256_file, write_bytes_atomic
from dockfactory.core.user_files import check_regular_file
from dockfactory.generator.datasets.folder import FRAME_ID_RE, DatasetError, load_identity
from dockfactory.generator.datasets.check import verify
from dockfactory.generator.datasets.fingerprints import (
    FINGERPRINTS_NAME,
    FINGERPRINTS_V2_NAME,
    FINGERPRINTS_V3_NAME,
    bound_manifest_sha256,
    read_fingerprints,
    read_fingerprints_v2,
    image_tiles,
    write_fingerprints,
    write_fingerprints_v2,
)
from dockfactory.generator.datasets.label_legacy import legacy_section_fields, with_legacy_sections
from dockfactory.generator.datasets.marker_check import marker_problems
from dockfactory.generator.random_draws import static_scene
from dockfactory.generator.sampler import frame_plan, sample_frame
from dockfactory.generator.datasets.label_prints import (
    INDEX_TOLERANCE_PX,
    index_difference,
    index_measurements,
    label_core_sha256,
    label_geometry_sha256,
)

__all__ = ["FINGERPRINTS_NAME", "FINGERPRINTS_V2_NAME", "PublishedReport", "publish", "verify_against"]

DEFAULT_TOLERANCE = 2.5      # 8-bit levels of a tile mean (its measurement: docs/datasets.md)
EXACT_ROOT_FILES = ("config.toml", "layout.json")


@dataclass
class PublishedReport:
    root: str
    manifest: str
    frames: int = 0
    labels_identical: int = 0
    labels_geometry: int = 0
    labels_index_within: int = 0
    labels_legacy_sections: int = 0    # of those, with the sections' silhouettes of the manifest's generator
    labels_libm: int = 0               # of those, matched on the v3 core (libm's trigonometry)
    max_index_diff: float = 0.0
    images_identical: int = 0
    images_within: int = 0
    markers_checked: int = 0
    max_tile_diff: float = 0.0
    tolerance: float = DEFAULT_TOLERANCE
    problems: list = field(default_factory=list)
    notes: list = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.problems and self.frames > 0

    def text(self) -> str:
        head = f"{self.root} against {self.manifest}: {'OK' if self.ok else 'FAILED'}"
        index = (f"{self.labels_index_within} with index-pass pixels within {INDEX_TOLERANCE_PX:g} px "
                 f"(max {self.max_index_diff:g}); " if self.labels_index_within else "")
        lines = [head, f"  {self.frames} frames checked: labels {self.labels_identical}/{self.frames} byte for byte, "
                       f"{self.labels_geometry} with the same geometry (image measurements differ), {index}"
                       f"images {self.images_identical} byte for byte, {self.images_within} within "
                       f"{self.tolerance} levels (max tile-mean difference {self.max_tile_diff:.3f}) "
                       f"with their markers where the labels say ({self.markers_checked} markers judged)"]
        notes = list(self.notes)
        if self.labels_legacy_sections:
            notes.append(f"{self.labels_legacy_sections} labels match once their sections' pixels_all and bbox_obj_px "
                         "are drawn as the manifest's generator drew them (the convex hull of each section, 2 % "
                         "too large; fixed since, generator/datasets/label_legacy.py): everything else matches")
        if self.labels_libm:
            notes.append(f"{self.labels_libm} labels match the published geometry as libm's sin and cos give it "
                         f"({FINGERPRINTS_V3_NAME}; the manifest's generator took numpy's AVX-512 paths, which "
                         "round the last bits otherwise)")
        return "\n".join(lines + [f"  note: {n}" for n in notes] + [f"  {p}" for p in self.problems])


@dataclass
class _Published:
    manifest: dict
    records: dict                      # {path: manifest record}
    prints: dict | None = None         # v1: {frame_id: (tiles, label geometry sha256)}
    prints_v2: dict | None = None      # v2: {frame_id: (label core sha256, index measurements)}
    prints_v3: dict | None = None      # v3: v2's, the core as libm's trigonometry gives it


def _load_published(manifest_path: Path) -> _Published:
    """The manifest, its records and the fingerprint files beside it (None where absent);
    DatasetError naming the file and key when the manifest is not one a publish writes."""
    check_regular_file(manifest_path, "manifest")
    try:
        manifest = json.loads(manifest_path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError, RecursionError) as exc:
        raise DatasetError(f"{manifest_path}: not a published dataset manifest ({type(exc).__name__})") from None
    problem = _manifest_problem(manifest)
    if problem:
        raise DatasetError(f"{manifest_path}: not a published dataset manifest: {problem}"[:400])
    records = {r["path"]: r for r in manifest["files"]}
    _check_bound(manifest_path)
    return _Published(manifest, records, read_fingerprints(manifest_path.with_name(FINGERPRINTS_NAME)),
                      read_fingerprints_v2(manifest_path.with_name(FINGERPRINTS_V2_NAME)),
                      read_fingerprints_v2(manifest_path.with_name(FINGERPRINTS_V3_NAME)))


def manifest_binding(manifest: dict) -> str:
    """The sha256 of a manifest's content (canonical JSON: the same for any serialisation of it),
    which a published fingerprint file carries."""
    return sha256_bytes(json.dumps(manifest, sort_keys=True, separators=(",", ":")).encode("utf-8"))


def _check_bound(manifest_path: Path) -> None:
    """DatasetError when a fingerprint file beside the manifest was published with another
    manifest (a publish that stopped half-way); files older than the binding pass."""
    mine = manifest_binding(json.loads(manifest_path.read_text(encoding="utf-8")))
    for name in (FINGERPRINTS_NAME, FINGERPRINTS_V2_NAME, FINGERPRINTS_V3_NAME):
        bound = bound_manifest_sha256(manifest_path.with_name(name))
        if bound is not None and bound != mine:
            raise DatasetError(f"{manifest_path}: not the manifest {name} was published with (edited, or "
                               "a publish over another that did not finish): publish again")


def _manifest_problem(manifest) -> str | None:
    """Why ``manifest`` (parsed JSON) lacks what verify reads, or None."""
    if not isinstance(manifest, dict):
        return "expected a JSON object"
    if not isinstance(manifest.get("version_id"), str):
        return f"version_id: expected a string, got {manifest.get('version_id')!r}"
    for key, fields in (("files", (("path", str), ("bytes", int), ("sha256", str))), ("frames", (("frame_id", str),))):
        items = manifest.get(key)
        if not isinstance(items, list):
            return f"{key}: expected a list"
        for i, rec in enumerate(items):
            for name, kind in fields:
                value = rec.get(name) if isinstance(rec, dict) else None
                if not isinstance(value, kind) or isinstance(value, bool):
                    return f"{key}[{i}].{name}: expected {kind.__name__}, got {value!r}"
    if not isinstance(manifest.get("software", {}), dict):
        return "software: expected an object"
    return None


def _rerendered_frames(root: Path) -> list[str]:
    ids = sorted(p.stem for p in (root / "labels").glob("*.json")) if (root / "labels").is_dir() else []
    return [fid for fid in ids if FRAME_ID_RE.match(fid)]


def _same_config(path: Path, manifest: dict) -> bool:
    """Whether the re-render's config text ``path`` resolves to the manifest's config (the
    manifest's read as a stored identity: a key it leaves out at its identity-neutral value; the
    text either so, or as a config file: a key it leaves out at today's default), so that a config
    pinning a key whose default moved since publishing still verifies, and so does one that leaves
    out a key whose default it renders."""
    errors = (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError, RecursionError, DockfactoryError, KeyError, TypeError)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
        published = config_from_identity(manifest["config"]).canonical_json()
    except errors:
        return False
    for read in (config_from_identity, config_from_dict):
        try:
            if read(data, str(path)).canonical_json() == published:
                return True
        except errors:
            pass
    return False


def _same_bytes(path: Path, record: dict | None) -> bool:
    return record is not None and path.is_file() and path.stat().st_size == record["bytes"] \
        and sha256_file(path) == record["sha256"]


def _index_problem(fid: str, text: bytes, published: tuple, rep: PublishedReport, legacy=None,
                   libm_core: str | None = None) -> str | None:
    """Fingerprint v2 of one label: None when it passes (counted in ``rep``), else the problem.
    ``legacy``: a :class:`LegacyLabels` when the manifest's generator is another one (its
    sections' silhouettes are then also compared as that generator drew them); ``libm_core``: the
    frame's v3 core, accepted in place of v2's."""
    core, index = published
    cores = (core,) if libm_core is None else (core, libm_core)
    mine = label_core_sha256(text)
    if mine not in cores:
        mine = legacy.core_sha256(fid, text) if legacy is not None else None
        if mine not in cores:
            return f"labels/{fid}.json: differs from the manifest beyond its image and index-pass measurements"
        rep.labels_legacy_sections += 1
    rep.labels_libm += mine != core
    diff = index_difference(index_measurements(text), index)
    if diff is None or diff > INDEX_TOLERANCE_PX:
        what = "another set of counts and boxes" if diff is None else f"up to {diff:g} px"
        return (f"labels/{fid}.json: index-pass pixel counts or boxes differ from the manifest by {what} "
                f"(tolerance {INDEX_TOLERANCE_PX:g} px)")
    rep.labels_index_within += 1
    rep.max_index_diff = max(rep.max_index_diff, diff)
    return None


class LegacyLabels:
    """A re-render's labels with their sections' silhouettes as generators before the silhouette
    fix drew them (generator.datasets.label_legacy), for a manifest such a generator made: the frames'
    scenes come from the re-render's own config (the same as the manifest's), drawn once."""

    def __init__(self, root: Path):
        self.root, self.cfg, self.specs, self.static = root, None, None, None

    def core_sha256(self, fid: str, text: bytes) -> str | None:
        """Fingerprint v2's digest of the label ``text`` of frame ``fid`` with legacy section
        silhouettes; None when the frame is not in the re-render's plan."""
        if self.cfg is None:
            ident = json.loads((self.root / "dataset.json").read_text(encoding="utf-8"))
            self.cfg = config_from_identity(ident["config"], str(self.root / "dataset.json"))
            self.specs = {s.frame_id: s for s in frame_plan(self.cfg)}
            self.static = static_scene(self.cfg)
        if fid not in self.specs:
            return None
        fields = legacy_section_fields(sample_frame(self.cfg, self.specs[fid]), self.static)
        label = with_legacy_sections(json.loads(text), fields)
        return label_core_sha256(json.dumps(label).encode())


def _check_label(root: Path, fid: str, pub: _Published, rep: PublishedReport, legacy=None) -> None:
    path = root / "labels" / f"{fid}.json"
    if _same_bytes(path, pub.records.get(f"labels/{fid}.json")):
        rep.labels_identical += 1
        return
    text = path.read_bytes()
    if pub.prints is not None and fid in pub.prints and label_geometry_sha256(text) == pub.prints[fid][1]:
        rep.labels_geometry += 1
    elif pub.prints_v2 is not None and fid in pub.prints_v2:
        libm = pub.prints_v3.get(fid, (None,))[0] if pub.prints_v3 is not None else None
        problem = _index_problem(fid, text, pub.prints_v2[fid], rep, legacy, libm)
        if problem:
            rep.problems.append(problem)
    else:
        rep.problems.append(f"labels/{fid}.json: differs from the manifest"
                            + (" beyond its image measurements" if pub.prints else ""))


def _check_image(root: Path, fid: str, pub: _Published, rep: PublishedReport) -> None:
    path = root / "images" / f"{fid}.png"
    if _same_bytes(path, pub.records.get(f"images/{fid}.png")):
        rep.images_identical += 1
        return
    if pub.prints is None or fid not in pub.prints:
        rep.problems.append(f"images/{fid}.png: differs from the manifest and no fingerprint to compare it with")
        return
    image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED) if path.is_file() else None
    if image is None or image.ndim != 3 or image.shape[2] != 3 or image.dtype != np.uint8:
        rep.problems.append(f"{path}: unreadable image (8-bit RGB PNG expected)")
        return
    tiles = pub.prints[fid][0]
    means = image_tiles(image)
    diff = float(np.abs(means - tiles).max()) if means.shape == tiles.shape else math.inf
    rep.max_tile_diff = max(rep.max_tile_diff, diff)
    if diff > rep.tolerance:
        rep.problems.append(f"images/{fid}.png: tile means differ by up to {diff:.3f} levels "
                            f"(tolerance {rep.tolerance})")
        return
    judged, markers = marker_problems(image[..., ::-1], _label_json(root / "labels" / f"{fid}.json"),
                                      f"images/{fid}.png")
    rep.markers_checked += judged
    if markers:
        rep.problems.extend(markers)
    else:
        rep.images_within += 1


def _label_json(path: Path) -> dict:
    try:
        label = json.loads(path.read_bytes())
    except (OSError, ValueError, RecursionError):
        return {}
    return label if isinstance(label, dict) else {}


def _version_difference(ident: dict, manifest: dict) -> str | None:
    """Why a re-render's version differs from the manifest's in a way that makes its frames
    incomparable (another config, resolved with today's defaults, or another Blender); None when
    only the generator differs."""
    software = manifest.get("software") or {}
    if ident.get("blender_version") != software.get("blender"):
        return f"another Blender: {ident.get('blender_version')}, published {software.get('blender')}"
    try:
        mine, theirs = config_from_identity(ident["config"]), config_from_identity(manifest["config"])
        mine = replace(mine, render=replace(mine.render, device=theirs.render.device))   # compared apart
        same = mine.canonical_json() == theirs.canonical_json()
    except (DockfactoryError, KeyError, TypeError):
        same = False
    return None if same else "another config"


def _devices(ident: dict, manifest: dict) -> tuple[str, str]:
    """([render] device of the re-render, of the published dataset); ("cpu", "cpu") if unreadable."""
    try:
        return (config_from_identity(ident["config"]).render.device,
                config_from_identity(manifest["config"]).render.device)
    except (DockfactoryError, KeyError, TypeError):
        return "cpu", "cpu"


def _difference_note(ident: dict, manifest: dict, devices: tuple[str, str]) -> str:
    if devices[0] != devices[1]:
        return (f"rendered on {devices[0]}, published on {devices[1]}, the same config otherwise: no image of one "
                f"device is byte-identical to the other's, so images are compared within --tolerance, labels on "
                f"their geometry (config.toml, which names the device, is not compared)")
    return (f"generator {ident.get('generator_version')}, the manifest's "
            f"{manifest.get('software', {}).get('generator')}: the same config and Blender, so the "
            f"frames are compared as they are (a newer generator must reproduce them)")


def _check_root_files(root: Path, pub: _Published, devices: tuple[str, str], rep: PublishedReport) -> None:
    """The dataset's root files against the manifest's records (config.toml by its config when its
    text differs, and not at all across render devices)."""
    for name in EXACT_ROOT_FILES:
        if name == "config.toml" and devices[0] != devices[1]:
            continue
        if _same_bytes(root / name, pub.records.get(name)):
            continue
        if name == "config.toml" and _same_config(root / name, pub.manifest):
            rep.notes.append("config.toml: its text is not the published one (comments, or a key stated at the "
                             "value the published config left to its default then), its config is the same")
            continue
        rep.problems.append(f"{name}: differs from the manifest")


def verify_against(root, manifest_path, tolerance: float = DEFAULT_TOLERANCE) -> PublishedReport:
    """Check the (partial) dataset at ``root`` against a published manifest (module docstring).

    Parameters
    ----------
    root : path
        A dataset folder holding some or all of the manifest's frames (a re-render).
    manifest_path : path
        The published ``manifest.json``, its fingerprint files beside it (:func:`publish`).
    tolerance : float
        8-bit levels an image may differ by (renders are not bit-exact across CPUs).

    Returns
    -------
    PublishedReport
        Its frames checked, notes and problems (empty: the re-render reproduces the manifest).

    Raises
    ------
    DatasetError
        A bad tolerance, a missing or unbound manifest, or a folder that is no dataset.
    """
    root, manifest_path = Path(root), Path(manifest_path)
    if isinstance(tolerance, bool) or not isinstance(tolerance, (int, float)) or not math.isfinite(tolerance) \
            or tolerance <= 0:
        raise DatasetError(f"--tolerance: expected a finite number of levels > 0, got {tolerance!r}")
    pub, ident, legacy = _load_published(manifest_path), load_identity(root), None
    rep = PublishedReport(str(root), str(manifest_path), tolerance=tolerance)
    devices = _devices(ident, pub.manifest)
    if ident["version_id"] != pub.manifest["version_id"]:
        why = _version_difference(ident, pub.manifest)
        if why is not None:
            rep.problems.append(f"dataset.json: version {ident['version_id']}, the manifest's is "
                                f"{pub.manifest['version_id']} ({why})")
            return rep
        rep.notes.append(_difference_note(ident, pub.manifest, devices))
        legacy = LegacyLabels(root)
    _check_root_files(root, pub, devices, rep)
    published = {f["frame_id"] for f in pub.manifest["frames"]}
    for fid in _rerendered_frames(root):
        if fid not in published:
            rep.problems.append(f"labels/{fid}.json: frame {fid} is not in the manifest")
            continue
        rep.frames += 1
        _check_label(root, fid, pub, rep, legacy)
        _check_image(root, fid, pub, rep)
    if rep.frames == 0:
        rep.problems.append("no re-rendered frame to check (labels/ is empty)")
    return rep


def publish(root, out) -> str:
    """Verify the complete dataset at ``root`` (every byte), then write its manifest.json (a byte
    copy) and the fingerprints of its frames (``fingerprints.npz``, ``fingerprints_v2.npz``) into
    the folder ``out``; a damaged or incomplete dataset is refused and nothing is written. Each
    file is written atomically, the fingerprints first and bound to the manifest (the sha256 of
    its content in them, :func:`manifest_binding`): a publish over an earlier one that stops half-way leaves the earlier manifest beside
    fingerprints that name another, which verify refuses in one line (publish again).

    Parameters
    ----------
    root : path
        A complete dataset folder.
    out : path
        The folder the manifest and fingerprints go to (made if missing).

    Returns
    -------
    str
        One line naming the frames published and the files written.

    Raises
    ------
    DatasetError
        No ``out``, or a damaged or incomplete dataset (its problems in one line).
    """
    if not out:
        raise DatasetError("dataset publish needs --out FOLDER")
    report = verify(root)
    if not report.ok:
        raise DatasetError(report.refusal())
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    manifest = (Path(root) / "manifest.json").read_bytes()
    bound = manifest_binding(json.loads(manifest))   # the fingerprints name their manifest, written last
    n = write_fingerprints(root, out / FINGERPRINTS_NAME, bound)
    write_fingerprints_v2(root, out / FINGERPRINTS_V2_NAME, bound)
    write_bytes_atomic(out / "manifest.json", manifest)
    return (f"{root}: published {n} frames to {out / 'manifest.json'}, {out / FINGERPRINTS_NAME} "
            f"and {out / FINGERPRINTS_V2_NAME}")
