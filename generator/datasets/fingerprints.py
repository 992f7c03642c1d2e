"""The fingerprint files published beside a dataset's manifest (``generator.datasets.published``).

- ``fingerprints.npz`` (v1): per frame, the mean of every 80 x 80 px image tile per channel and
  the label's geometry digest (``label_prints.label_geometry_sha256``);
- ``fingerprints_v2.npz``: per frame, the label's core digest and its index-pass pixel counts
  and boxes (``label_prints``), so that a label whose edge pixels went to a neighbour on another
  CPU can be told from a label that differs.
"""
from __future__ import annotations

import io
import json
import zipfile
from pathlib import Path

from dockfactory.core.cv import cv2
import numpy as np

from dockfactory.core.io import write_bytes_atomic
from dockfactory.generator.datasets.folder import DatasetError
from dockfactory.generator.datasets.label_prints import index_measurements, label_core_sha256, label_geometry_sha256

TILE_PX = 80
FINGERPRINTS_NAME = "fingerprints.npz"
FINGERPRINTS_V2_NAME = "fingerprints_v2.npz"
# v2's format; each frame's label core as a generator with numpy's trigonometry pinned to libm
# computes it, for a dataset published with another (generator.datasets.published)
FINGERPRINTS_V3_NAME = "fingerprints_v3.npz"


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


def _manifest_frame_ids(root: Path) -> list[str]:
    return [f["frame_id"] for f in json.loads((root / "manifest.json").read_text())["frames"]]


def _npz_bytes(**arrays) -> bytes:
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    return buf.getvalue()


def _bound(manifest_sha256: str | None) -> dict:
    """The npz entry binding a fingerprint file to the manifest it was published with (one string)."""
    return {} if manifest_sha256 is None else {"manifest_sha256": np.array([manifest_sha256])}


def write_fingerprints(root, out_path, manifest_sha256: str | None = None) -> int:
    """Fingerprints of every frame of the complete dataset at ``root`` (ids from its manifest):
    image tile means and label geometry digests, written atomically to ``out_path`` (npz:
    ``frame_ids``, ``tiles``, ``label_geometry``, and ``manifest_sha256`` when given: the sha256
    of the manifest published with them); returns the count."""
    root = Path(root)
    ids = _manifest_frame_ids(root)
    tiles = np.stack([read_image_tiles(root / "images" / f"{fid}.png") for fid in ids])
    geometry = [label_geometry_sha256((root / "labels" / f"{fid}.json").read_bytes()) for fid in ids]
    write_bytes_atomic(Path(out_path), _npz_bytes(frame_ids=np.array(ids), tiles=tiles.astype(np.float32),
                                                  label_geometry=np.array(geometry), **_bound(manifest_sha256)))
    return len(ids)


def fingerprints_v2(frame_ids, label_texts, manifest_sha256: str | None = None) -> bytes:
    """The npz bytes of fingerprint v2 of the labels ``label_texts`` (bytes, one per frame id):
    ``frame_ids``, ``label_core`` (digests), ``index`` (index-pass numbers, one row per frame,
    NaN-padded), ``index_len`` (each row's length) and, when given, ``manifest_sha256``."""
    texts = list(label_texts)
    return fingerprints_of(frame_ids, [label_core_sha256(t) for t in texts], [index_measurements(t) for t in texts],
                           manifest_sha256)


def fingerprints_of(frame_ids, cores, rows, manifest_sha256: str | None = None) -> bytes:
    """The npz bytes of v2-format fingerprints from their parts: per frame id a label core digest
    and a row of index-pass numbers (``generator.datasets.label_prints``)."""
    index = np.full((len(rows), max((len(r) for r in rows), default=0)), np.nan)
    for i, r in enumerate(rows):
        index[i, :len(r)] = r
    return _npz_bytes(frame_ids=np.array(list(frame_ids)), label_core=np.array(cores), index=index,
                      index_len=np.array([len(r) for r in rows], np.int64), **_bound(manifest_sha256))


def write_fingerprints_v2(root, out_path, manifest_sha256: str | None = None) -> int:
    """Fingerprint v2 of every label of the complete dataset at ``root``, written atomically."""
    root = Path(root)
    ids = _manifest_frame_ids(root)
    texts = [(root / "labels" / f"{fid}.json").read_bytes() for fid in ids]
    write_bytes_atomic(Path(out_path), fingerprints_v2(ids, texts, manifest_sha256))
    return len(ids)


def bound_manifest_sha256(path: Path) -> str | None:
    """The sha256 of the manifest a fingerprint file was published with (None: the file is absent
    or older than the binding)."""
    return _read_npz(Path(path), _binding)


def _binding(z) -> str | None:
    if "manifest_sha256" not in z.files:
        return None
    a = z["manifest_sha256"]
    if a.shape != (1,) or a.dtype.kind != "U":
        raise ValueError(f"manifest_sha256 of shape {a.shape} and dtype {a.dtype} (one string expected)")
    return str(a[0])


def _read_npz(path: Path, read) -> dict | None:
    if not path.exists():
        return None
    try:
        with np.load(path, allow_pickle=False) as z:
            return read(z)
    except (OSError, ValueError, KeyError, TypeError, IndexError, EOFError, zipfile.BadZipFile) as exc:
        raise DatasetError(f"{path}: not a fingerprint file ({type(exc).__name__}: {exc})"[:300]) from None


def _v1(z) -> dict:
    ids, tiles, geometry = z["frame_ids"], z["tiles"], z["label_geometry"]
    if tiles.ndim != 4 or tiles.dtype.kind != "f" or not len(ids) == len(tiles) == len(geometry):
        raise ValueError(f"tiles of shape {tiles.shape} for {len(ids)} frames (frames, rows, cols, channels expected)")
    return dict(zip((str(f) for f in z["frame_ids"]), zip(z["tiles"], (str(g) for g in z["label_geometry"]))))


def _v2(z) -> dict:
    if z["index"].ndim != 2 or not len(z["frame_ids"]) == len(z["label_core"]) == len(z["index"]) == len(z["index_len"]):
        raise ValueError("frame_ids, label_core, index and index_len do not line up")
    if z["index_len"].dtype.kind not in "iu" or z["index"].dtype.kind != "f":
        raise ValueError(f"index_len of {z['index_len'].dtype}, index of {z['index'].dtype} (integers, floats expected)")
    rows = (row[:n] for row, n in zip(z["index"], z["index_len"]))
    return dict(zip((str(f) for f in z["frame_ids"]), zip((str(c) for c in z["label_core"]), rows)))


def read_fingerprints(path: Path) -> dict | None:
    """v1 fingerprints: {frame_id: (tile means, label geometry sha256)}, None without the file."""
    return _read_npz(Path(path), _v1)


def read_fingerprints_v2(path: Path) -> dict | None:
    """v2 (or v3) fingerprints: {frame_id: (label core sha256, index measurements)}, None without
    the file."""
    return _read_npz(Path(path), _v2)
