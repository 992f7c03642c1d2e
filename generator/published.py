"""A re-render checked against a published dataset (``dockfactory dataset verify DIR --manifest M``).

Anyone can re-render any subset of a published dataset (``dockfactory render CONFIG --out DIR
--frames ...`` or ``--shard K/N``) and check it against the published ``manifest.json`` (every
file's sha256) and its fingerprints (``fingerprints.npz`` beside the manifest):

- the re-render must carry the published version id (same config, generator and Blender);
- every re-rendered frame must be a frame of the manifest; its label must match byte for byte
  or, where Cycles on another CPU gives other bits, everything but the two measurements a label
  takes from the rendered image (each marker's ``chroma``, the frame's ``auto_exposure_scale``)
  must match byte for byte (the sha256 of the label without them);
- its image must match byte for byte or its fingerprint (the mean of every 80 x 80 px tile per
  channel, in 8-bit levels) must be within ``tolerance`` levels of the published one;
- the config and layout files must match byte for byte.

Frames of the manifest that were not re-rendered are not checked (a subset is the point).
"""
from __future__ import annotations

import hashlib
import io
import json
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from dockfactory.core.io import sha256_file, write_bytes_atomic
from dockfactory.generator.dataset import FRAME_ID_RE, DatasetError, load_identity
from dockfactory.generator.dataset_check import verify

TILE_PX = 80
FINGERPRINTS_NAME = "fingerprints.npz"
DEFAULT_TOLERANCE = 2.5      # 8-bit levels of a tile mean (bench/results/paper/rerender_2026-12-01.txt)
EXACT_ROOT_FILES = ("config.toml", "layout.json")


def image_tiles(image: np.ndarray, tile: int = TILE_PX) -> np.ndarray:
    """Mean of every ``tile`` x ``tile`` block per channel (float32, (rows, cols, channels)); edge
    blocks are the partial tiles that remain."""
    h, w = image.shape[:2]
    rows, cols = -(-h // tile), -(-w // tile)
    img = image.reshape(h, w, -1).astype(np.float64)
    out = np.empty((rows, cols, img.shape[2]), np.float32)
    for i in range(rows):
        for j in range(cols):
            out[i, j] = img[i * tile:(i + 1) * tile, j * tile:(j + 1) * tile].mean(axis=(0, 1))
    return out


def read_image_tiles(path) -> np.ndarray:
    image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED) if Path(path).is_file() else None
    if image is None:
        raise DatasetError(f"{path}: unreadable image")
    return image_tiles(image)


def label_geometry_sha256(text: bytes) -> str:
    """sha256 of a label without what it measures on the rendered image (markers' ``chroma``,
    ``derived.auto_exposure_scale``): the part that must not change with Cycles' bits."""
    label = json.loads(text)
    for m in label.get("markers", []):
        m.pop("chroma", None)
    label.get("derived", {}).pop("auto_exposure_scale", None)
    return hashlib.sha256(json.dumps(label, sort_keys=True, separators=(",", ":")).encode()).hexdigest()


def write_fingerprints(root, out_path) -> int:
    """Fingerprints of every frame of the complete dataset at ``root`` (ids from its manifest):
    image tile means and label geometry digests, written atomically to ``out_path`` (npz:
    ``frame_ids``, ``tiles``, ``label_geometry``); returns the count."""
    root = Path(root)
    manifest = json.loads((root / "manifest.json").read_text())
    ids = [f["frame_id"] for f in manifest["frames"]]
    tiles = np.stack([read_image_tiles(root / "images" / f"{fid}.png") for fid in ids])
    geometry = [label_geometry_sha256((root / "labels" / f"{fid}.json").read_bytes()) for fid in ids]
    out_path = Path(out_path)
    buf = io.BytesIO()
    np.savez_compressed(buf, frame_ids=np.array(ids), tiles=tiles.astype(np.float32),
                        label_geometry=np.array(geometry))
    write_bytes_atomic(out_path, buf.getvalue())
    return len(ids)


@dataclass
class PublishedReport:
    root: str
    manifest: str
    frames: int = 0
    labels_identical: int = 0
    labels_geometry: int = 0
    images_identical: int = 0
    images_within: int = 0
    max_tile_diff: float = 0.0
    tolerance: float = DEFAULT_TOLERANCE
    problems: list = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.problems and self.frames > 0

    def text(self) -> str:
        head = f"{self.root} against {self.manifest}: {'OK' if self.ok else 'FAILED'}"
        lines = [head, f"  {self.frames} frames checked: labels {self.labels_identical}/{self.frames} byte for byte, "
                       f"{self.labels_geometry} with the same geometry (image measurements differ); "
                       f"images {self.images_identical} byte for byte, {self.images_within} within "
                       f"{self.tolerance} levels (max tile-mean difference {self.max_tile_diff:.3f})"]
        return "\n".join(lines + [f"  {p}" for p in self.problems])


def _load_published(manifest_path: Path) -> tuple[dict, dict, dict | None]:
    """(manifest, {path: record}, {frame_id: (tiles, label geometry sha256)} or None without a
    fingerprint file)."""
    try:
        manifest = json.loads(manifest_path.read_text())
        records = {r["path"]: r for r in manifest["files"]}
        manifest["version_id"], manifest["frames"]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise DatasetError(f"{manifest_path}: not a published dataset manifest ({type(exc).__name__}: {exc})") from None
    prints_path = manifest_path.with_name(FINGERPRINTS_NAME)
    if not prints_path.exists():
        return manifest, records, None
    try:
        with np.load(prints_path, allow_pickle=False) as z:
            prints = dict(zip((str(f) for f in z["frame_ids"]), zip(z["tiles"], (str(g) for g in z["label_geometry"]))))
    except (OSError, ValueError, KeyError) as exc:
        raise DatasetError(f"{prints_path}: not a fingerprint file ({type(exc).__name__}: {exc})") from None
    return manifest, records, prints


def _rerendered_frames(root: Path) -> list[str]:
    ids = sorted(p.stem for p in (root / "labels").glob("*.json")) if (root / "labels").is_dir() else []
    return [fid for fid in ids if FRAME_ID_RE.match(fid)]


def _same_bytes(path: Path, record: dict | None) -> bool:
    return record is not None and path.is_file() and path.stat().st_size == record["bytes"] \
        and sha256_file(path) == record["sha256"]


def _check_label(root: Path, fid: str, records: dict, prints: dict | None, rep: PublishedReport) -> None:
    path = root / "labels" / f"{fid}.json"
    if _same_bytes(path, records.get(f"labels/{fid}.json")):
        rep.labels_identical += 1
    elif prints is not None and fid in prints and label_geometry_sha256(path.read_bytes()) == prints[fid][1]:
        rep.labels_geometry += 1
    else:
        rep.problems.append(f"labels/{fid}.json: differs from the manifest"
                            + (" beyond its image measurements" if prints else ""))


def _check_image(root: Path, fid: str, records: dict, prints: dict | None, rep: PublishedReport) -> None:
    path = root / "images" / f"{fid}.png"
    if _same_bytes(path, records.get(f"images/{fid}.png")):
        rep.images_identical += 1
        return
    if prints is None or fid not in prints:
        rep.problems.append(f"images/{fid}.png: differs from the manifest and no fingerprint to compare it with")
        return
    try:
        diff = float(np.abs(read_image_tiles(path) - prints[fid][0]).max())
    except DatasetError as exc:
        rep.problems.append(str(exc))
        return
    rep.max_tile_diff = max(rep.max_tile_diff, diff)
    if diff <= rep.tolerance:
        rep.images_within += 1
    else:
        rep.problems.append(f"images/{fid}.png: tile means differ by up to {diff:.3f} levels "
                            f"(tolerance {rep.tolerance})")


def verify_against(root, manifest_path, tolerance: float = DEFAULT_TOLERANCE) -> PublishedReport:
    """Check the (partial) dataset at ``root`` against a published manifest (module docstring)."""
    root, manifest_path = Path(root), Path(manifest_path)
    manifest, records, prints = _load_published(manifest_path)
    rep = PublishedReport(str(root), str(manifest_path), tolerance=tolerance)
    ident = load_identity(root)
    if ident["version_id"] != manifest["version_id"]:
        rep.problems.append(f"dataset.json: version {ident['version_id']}, the manifest's is "
                            f"{manifest['version_id']} (another config, generator or Blender)")
        return rep
    for name in EXACT_ROOT_FILES:
        if not _same_bytes(root / name, records.get(name)):
            rep.problems.append(f"{name}: differs from the manifest")
    published = {f["frame_id"] for f in manifest["frames"]}
    for fid in _rerendered_frames(root):
        if fid not in published:
            rep.problems.append(f"labels/{fid}.json: frame {fid} is not in the manifest")
            continue
        rep.frames += 1
        _check_label(root, fid, records, prints, rep)
        _check_image(root, fid, records, prints, rep)
    if rep.frames == 0:
        rep.problems.append("no re-rendered frame to check (labels/ is empty)")
    return rep


def publish(root, out) -> str:
    """Verify the complete dataset at ``root`` (every byte), then write its manifest.json (a byte
    copy) and the fingerprints of its frames (``fingerprints.npz``) into the folder ``out``; a
    damaged or incomplete dataset is refused and nothing is written."""
    if not out:
        raise DatasetError("dataset publish needs --out FOLDER")
    report = verify(root)
    if not report.ok:
        raise DatasetError(report.refusal())
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    n = write_fingerprints(root, out / FINGERPRINTS_NAME)
    write_bytes_atomic(out / "manifest.json", (Path(root) / "manifest.json").read_bytes())
    return f"{root}: published {n} frames to {out / 'manifest.json'} and {out / FINGERPRINTS_NAME}"
