"""Read the render's multilayer EXR and write the compact EXR kept with a dataset (no bpy).

Blender 5 writes a multi-part file, one part per pass; ``OpenEXR.File.channels()`` only sees the
first part, so every part is read. The kept EXR is one ZIP-compressed part with the channels
``Combined.R/G/B`` (half, linear), ``Depth.Z`` (float, mm along the optical axis) and
``IndexOB.X`` (uint, the marker index pass).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import OpenEXR

from dockfactory.core.camera_chain import RenderPasses
from dockfactory.core.errors import DockfactoryError
from dockfactory.core.io import atomic_path
from dockfactory.core.names import MARKER_CLASS_AOV


class ExrError(DockfactoryError):
    pass


def _find(channels: dict, *suffixes) -> np.ndarray | None:
    for name, ch in channels.items():
        if any(name.endswith(s) for s in suffixes):
            return ch.pixels
    return None


def read_rgb(path) -> np.ndarray:
    """(H, W, 3) float32 linear colour (the Combined pass) of a Blender multilayer EXR, such as a
    cropped marker region of label-aware sampling."""
    return _read_parts(path)[0]


def _class_coverage(channels: dict, path, aov: str) -> np.ndarray:
    packed = _find(channels, f"{aov}.RGB", f"{aov}.RGBA", f"{aov}")
    if packed is not None and packed.ndim == 3:
        return np.ascontiguousarray(packed[..., :2], dtype=np.float32)
    comps = [_find(channels, f"{aov}.{c}") for c in "RG"]
    if any(c is None for c in comps):
        raise ExrError(f"{path}: no coverage pass {aov!r} (channels: {sorted(channels)})")
    return np.stack(comps, axis=-1).astype(np.float32)


def read_class_coverage(path, aov: str = MARKER_CLASS_AOV) -> np.ndarray:
    """(H, W, 2) float32: the disc and ring coverage (the R and G of the colour AOV ``aov``,
    blender_scenes.coverage) of a Blender multilayer EXR; ExrError when it has no such pass."""
    return _class_coverage(_read_parts(path)[1], path, aov)


@dataclass
class RegionPasses:
    """A marker region's render: its colour, the colour before the denoiser (None: not denoised)
    and the disc and ring coverage of its samples (each float32, linear; (h, w, 3) / (h, w, 2))."""
    rgb: np.ndarray
    noisy: np.ndarray | None
    coverage: np.ndarray


def read_region(path) -> RegionPasses:
    """The passes of a marker region's EXR the coverage correction needs (one read); ExrError
    when it has no coverage pass."""
    rgb, channels = _read_parts(path)
    noisy = _find(channels, "Noisy Image", "Noisy Image.RGBA")
    if noisy is not None:
        noisy = np.ascontiguousarray(noisy[..., :3], dtype=np.float32)
    return RegionPasses(rgb, noisy, _class_coverage(channels, path, MARKER_CLASS_AOV))


def _read_parts(path) -> tuple[np.ndarray, dict]:
    """(rgb (H, W, 3) float32, every channel by name) of an EXR; ExrError when unreadable or
    without a Combined pass."""
    try:
        f = OpenEXR.File(str(path), separate_channels=False)
    except Exception as exc:  # OpenEXR raises plain RuntimeError/OSError
        raise ExrError(f"{path}: cannot read EXR: {exc}") from exc
    channels = {}
    for part in f.parts:
        channels.update(part.channels)
    rgb = _find(channels, "Combined", "Combined.RGB", "Combined.RGBA")
    if rgb is None:  # separate R, G, B channels
        comps = [_find(channels, f"Combined.{c}") for c in "RGB"]
        if any(c is None for c in comps):
            raise ExrError(f"{path}: no Combined pass (channels: {sorted(channels)})")
        rgb = np.stack(comps, axis=-1)
    return np.ascontiguousarray(rgb[..., :3], dtype=np.float32), channels


def read_passes(path, depth_scale_mm: float = 1000.0) -> RenderPasses:
    """Passes of a Blender multilayer EXR or of a kept compact EXR.

    ``depth_scale_mm``: mm per depth unit in the file (Blender renders in metres: 1000).
    """
    rgb, channels = _read_parts(path)
    depth = _find(channels, "Depth.Z", ".Z")
    index = _find(channels, "Object Index.X", "IndexOB.X", "IndexOB")
    if depth is None or index is None:
        raise ExrError(f"{path}: missing Depth or Object Index pass (channels: {sorted(channels)})")
    return RenderPasses(rgb=rgb, depth_mm=depth.astype(np.float32) * np.float32(depth_scale_mm),
                        index=np.rint(index).astype(np.int32))


def write_compact(path, passes: RenderPasses) -> None:
    """Atomically write the compact EXR kept beside a frame's PNG."""
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    ch = {
        "Combined.R": passes.rgb[..., 0].astype(np.float16),
        "Combined.G": passes.rgb[..., 1].astype(np.float16),
        "Combined.B": passes.rgb[..., 2].astype(np.float16),
        "Depth.Z": passes.depth_mm.astype(np.float32),
        "IndexOB.X": passes.index.astype(np.uint32),
    }
    with atomic_path(path) as tmp:
        OpenEXR.File(header, ch).write(str(tmp))


def read_compact(path) -> RenderPasses:
    """Read an EXR written by :func:`write_compact` (depth already in mm)."""
    return read_passes(path, depth_scale_mm=1.0)
