"""A complete dockfactory dataset without Blender, for fast tests of the solve, evaluate, report and
run stages (tests only).

Everything but the render is the real code path: the config is loaded and planned by the factory
(``frame_plan``, ``sample_frame``: real cameras, poses and focal lengths), the directory is prepared
by ``generator.dataset.prepare`` (identity and version id of the config), each frame goes through
``generator.frame_output.finish_frame`` (sensor model, exact labels, PNG, meta, kept EXR) and the
manifest is written by ``generator.dataset.write_manifest``. So ``Dataset.open`` and
``run_pipeline`` take it for a rendered dataset of that config, and its render stage finds every
frame done.

The render is replaced by :func:`painted_passes`: the section bodies (convex hull of their
silhouettes, grey) and every marker disc that faces the camera (its exact projected outline, pure
red for A, pure blue for B), painted far to near into the colour, depth and object-index passes.
No occluders, glare or clutter are painted, so every front-facing marker is fully visible: the
labels' ``visibility`` is 2 for them and their ``outline_centroid_px`` is exact, which is what the
oracle feeds the solver.
"""
from __future__ import annotations

import tempfile
from pathlib import Path

import cv2
import numpy as np

from dockfactory.core.config import Config, load_config
from dockfactory.core.geometry import invert_transform, project_points, transform_points
from dockfactory.core.io import sha256_file, write_json_atomic
from dockfactory.core.layout import SECTION_PASS_INDEX, SECTIONS, marker_outline
from dockfactory.core.scene import FrameScene, StaticScene
from dockfactory.generator.dataset import frame_files, prepare, write_manifest
from dockfactory.generator.exr import RenderPasses, write_compact
from dockfactory.generator.frame_output import finish_frame
from dockfactory.generator.labels import section_silhouette
from dockfactory.generator.sampler import frame_plan, sample_frame, static_scene

BACKGROUND = (0.05, 0.05, 0.05)
SECTION_RGB = (0.35, 0.35, 0.35)
MARKER_RGB = {"A": (0.8, 0.01, 0.01), "B": (0.01, 0.02, 0.8)}
SHIFT = 4   # cv2.fillPoly sub-pixel bits: vertices to 1/16 px


def _fill(mask_shape, uv: np.ndarray) -> np.ndarray:
    """Boolean (H, W) mask of the pixel centres inside polygon ``uv`` (N, 2) (OpenCV pixels)."""
    mask = np.zeros(mask_shape, np.uint8)
    pts = np.round(uv * (1 << SHIFT)).astype(np.int32).reshape(-1, 1, 2)
    cv2.fillPoly(mask, [pts], 1, cv2.LINE_8, SHIFT)
    return mask.astype(bool)


def painted_passes(frame: FrameScene, static: StaticScene) -> RenderPasses:
    """Colour (linear), depth (m, as Blender writes it) and object-index passes of ``frame``."""
    cam = frame.camera
    h, w = cam.height, cam.width
    k = cam.k()
    cam_from_d = cam.cam_from_d_array()
    d_from_b = frame.d_from_b_array()
    eye_d = invert_transform(cam_from_d)[:3, 3]
    rgb = np.empty((h, w, 3), np.float32)
    rgb[:] = BACKGROUND
    depth = np.full((h, w), np.inf, np.float32)
    index = np.zeros((h, w), np.int32)

    def paint(mask, colour, z_mm, value):
        rgb[mask] = colour
        depth[mask] = z_mm / 1000.0
        index[mask] = value

    for sec in SECTIONS:
        d_from_s = d_from_b if sec == "B" else np.eye(4)
        uv, z = project_points(k, cam_from_d @ d_from_s, section_silhouette(static, sec))
        if np.all(z > 0):
            hull = cv2.convexHull(uv.astype(np.float32)).reshape(-1, 2).astype(np.float64)
            paint(_fill((h, w), hull), SECTION_RGB, float(z.max()), SECTION_PASS_INDEX[sec])
    discs = []
    for m in static.markers:
        d_from_s = d_from_b if m.section == "B" else np.eye(4)
        centre_d = transform_points(d_from_s, np.array([m.center_mm]))[0]
        normal_d = d_from_s[:3, :3] @ np.asarray(m.normal)
        if float(normal_d @ (eye_d - centre_d)) <= 0:   # faces away: hidden behind its cylinder
            continue
        uv, z = project_points(k, cam_from_d, transform_points(d_from_s, marker_outline(m)))
        if np.all(z > 0):
            discs.append((float(z.mean()), m, uv))
    for z, m, uv in sorted(discs, key=lambda d: -d[0]):   # far to near
        paint(_fill((h, w), uv), MARKER_RGB[m.section], z, m.pass_index)
    return RenderPasses(rgb=rgb, depth_mm=depth, index=index)


def write_painted_dataset(root, config_path) -> Config:
    """A complete dataset of ``config_path`` in ``root`` (every planned frame, manifest)."""
    root = Path(root)
    cfg = load_config(config_path)
    prepare(root, cfg, Path(config_path).read_text())
    static = static_scene(cfg)
    with tempfile.TemporaryDirectory(prefix="painted-") as scratch:
        for spec in frame_plan(cfg):
            frame = sample_frame(cfg, spec)
            exr = Path(scratch) / f"{spec.frame_id}.exr"
            write_compact(exr, painted_passes(frame, static))
            finish_frame(frame, static, exr, root, cfg.render.keep_exr, cfg.labels.visible_threshold,
                         min_chroma=cfg.labels.min_chroma)
    write_manifest(root, cfg)
    return cfg


def seal_hand_made(root, cfg: Config) -> None:
    """Finish a dataset whose frames were written by hand (images/<id>.png and labels/<id>.json of
    every planned frame, after ``prepare``): the meta records ``finish_frame`` would write, then the
    manifest. The result is a complete dataset ``Dataset.open`` accepts."""
    root = Path(root)
    for spec in frame_plan(cfg):
        files = {}
        for kind, rel in frame_files(spec.frame_id, cfg.render.keep_exr).items():
            path = root / rel
            files[kind] = {"path": rel, "bytes": path.stat().st_size, "sha256": sha256_file(path)}
        write_json_atomic(root / "meta" / f"{spec.frame_id}.json", {"frame_id": spec.frame_id, "files": files})
    write_manifest(root, cfg)
