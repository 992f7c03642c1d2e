"""Fingerprint v3 of a published dataset: its label cores as libm's trigonometry gives them.

A generator whose numpy took its AVX-512 (SVML) paths for sin and cos wrote labels whose geometry
differs in the last bits from what every other CPU computes, and since ``dockfactory.core.blas``
pins numpy to libm's paths on every CPU, no re-render reproduces those bits. ``derive`` turns a
re-render of some of such a dataset's frames (made by the pinned generator) into fingerprint v3 for
those frames: per frame the label core digest of the re-render, with the sections' silhouettes
drawn as the manifest's generator drew them (``generator.datasets.label_legacy``), beside v2's published
index-pass numbers. It refuses a frame whose index-pass numbers are not within v2's tolerance of
the published ones, and a frame already in the v3 file with another digest; frames whose core
already equals v2's are counted (for them the derivation reproduces the published digest exactly,
which checks everything but the trigonometry's last bits).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from dockfactory.core.io import write_bytes_atomic
from dockfactory.generator.datasets.folder import DatasetError, load_identity
from dockfactory.generator.datasets.fingerprints import FINGERPRINTS_V3_NAME, fingerprints_of, read_fingerprints_v2
from dockfactory.generator.datasets.label_prints import (
    INDEX_TOLERANCE_PX,
    index_difference,
    index_measurements,
    label_core_sha256,
)
from dockfactory.generator.datasets.published import LegacyLabels, _load_published, _rerendered_frames, _version_difference


@dataclass
class LibmDerivation:
    frames: int = 0           # re-rendered frames derived
    same_as_v2: int = 0       # of those, whose core is v2's digest already
    kept: int = 0             # frames the v3 file held before, kept
    problems: list = field(default_factory=list)

    def text(self) -> str:
        return (f"{self.frames} frames derived: {self.same_as_v2} with v2's core as they are, "
                f"{self.frames - self.same_as_v2} with libm's last bits; {self.kept} kept from the v3 file")


def derive(root, manifest_path, out=None) -> LibmDerivation:
    """Write (atomically, to ``out``, default ``fingerprints_v3.npz`` beside the manifest) the v3
    fingerprints of the frames re-rendered at ``root``, merged with those ``out`` holds. Nothing is
    written when any frame has a problem (returned in the derivation's ``problems``)."""
    root, manifest_path = Path(root), Path(manifest_path)
    out = Path(out) if out else manifest_path.with_name(FINGERPRINTS_V3_NAME)
    pub = _load_published(manifest_path)
    if pub.prints_v2 is None:
        raise DatasetError(f"{manifest_path}: no fingerprint v2 beside it, which v3 completes")
    core_of = _core_reader(root, pub.manifest)
    have = read_fingerprints_v2(out) or {}
    rows = {fid: (core, index) for fid, (core, index) in have.items()}
    der = LibmDerivation(kept=len(have))
    for fid in _rerendered_frames(root):
        text = (root / "labels" / f"{fid}.json").read_bytes()
        core = core_of(fid, text)
        problem = _frame_problem(fid, text, core, pub.prints_v2.get(fid), have.get(fid), der)
        if problem:
            der.problems.append(problem)
            continue
        rows[fid] = (core, pub.prints_v2[fid][1])
        der.frames += 1
        der.kept -= fid in have
    if not der.problems and der.frames:
        ids = sorted(rows)
        write_bytes_atomic(out, fingerprints_of(ids, [rows[f][0] for f in ids], [rows[f][1] for f in ids]))
    return der


def _core_reader(root: Path, manifest: dict):
    """(frame id, label text) -> the label core digest as the manifest's generator would have
    written it (its sections' silhouettes when it is another generator, ``verify_against``'s rule);
    DatasetError when the re-render is of another config or Blender."""
    ident = load_identity(root)
    if ident["version_id"] == manifest["version_id"]:
        return lambda fid, text: label_core_sha256(text)
    why = _version_difference(ident, manifest)
    if why is not None:
        raise DatasetError(f"{root}: version {ident['version_id']}, the manifest's is {manifest['version_id']} ({why})")
    return LegacyLabels(root).core_sha256


def _frame_problem(fid, text, core, published, held, der) -> str | None:
    if published is None:
        return f"labels/{fid}.json: frame {fid} has no fingerprint v2"
    if core is None:
        return f"labels/{fid}.json: frame {fid} is not in the re-render's plan"
    diff = index_difference(index_measurements(text), published[1])
    if diff is None or diff > INDEX_TOLERANCE_PX:
        return f"labels/{fid}.json: index-pass numbers differ from v2's beyond {INDEX_TOLERANCE_PX:g} px"
    if held is not None and held[0] != core:
        return f"labels/{fid}.json: the v3 file holds another core for frame {fid}"
    der.same_as_v2 += core == published[0]
    return None
