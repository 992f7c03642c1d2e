"""A complete dockfactory dataset without Blender, for fast tests of the solve, evaluate, report and
run stages (tests only).

Everything but the render is the real code path: the config is loaded and planned by the factory
(``frame_plan``, ``sample_frame``: real cameras, poses and focal lengths), the directory is prepared
by ``generator.datasets.folder.prepare`` (identity and version id of the config), each frame goes through
``generator.frame_output.finish_frame`` (sensor model, exact labels, PNG, meta, kept EXR) and the
manifest is written by ``generator.datasets.folder.write_manifest``. So ``Dataset.open`` and
``run_pipeline`` take it for a rendered dataset of that config, and its render stage finds every
frame done.

The render is replaced by :func:`painted_passes`: the section bodies (convex hull of their
silhouettes, grey) and every marker disc that faces the camera (its exact projected outline, pure
red for A, pure blue for B), painted far to near into the colour, depth and object-index passes
of the pinhole render canvas (``CameraModel.canvas``: the image itself for a pinhole camera, the
overscan a distorted one is resampled from, as Blender renders it).
No occluders, glare or clutter are painted, so every front-facing marker is fully visible: the
labels' ``visibility`` is 2 for them and their ``outline_centroid_px`` is exact, which is what the
oracle feeds the solver.
"""
from __future__ import annotations

import fcntl
import hashlib
import os
import shutil
import tempfile
from pathlib import Path

import cv2
import numpy as np

from dockfactory.core.config import Config
from dockfactory.core.config_text import load_config_text
from dockfactory.core.geometry import intrinsics, invert_transform, project_points, transform_points
from dockfactory.core.io import sha256_file, write_json_atomic
from dockfactory.core.layout import SECTION_PASS_INDEX, SECTIONS, marker_outline
from dockfactory.core.scene import FrameScene, StaticScene
from dockfactory.generator.datasets.folder import frame_files, prepare, write_manifest
from dockfactory.generator.random_draws import static_scene
from dockfactory.generator.exr import RenderPasses, write_compact
from dockfactory.generator.frame_output import finish_frame
from dockfactory.generator.silhouette import silhouette_parts
from dockfactory.generator.sampler import frame_plan, sample_frame

BACKGROUND = (0.05, 0.05, 0.05)
SECTION_RGB = (0.35, 0.35, 0.35)
MARKER_RGB = {"A": (0.8, 0.01, 0.01), "B": (0.01, 0.02, 0.8)}
SHIFT = 4   # cv2.fillPoly sub-pixel bits: vertices to 1/16 px


def _fill(mask_shape, uv: np.ndarray) -> np.ndarray:
    """Boolean (H, W) mask of the pixel centres inside polygon ``uv`` (N, 2) (OpenCV pixels);
    cv2.fillPoly also fills the pixels its edges cross, so the mask is about half a pixel fat."""
    mask = np.zeros(mask_shape, np.uint8)
    pts = np.round(uv * (1 << SHIFT)).astype(np.int32).reshape(-1, 1, 2)
    cv2.fillPoly(mask, [pts], 1, cv2.LINE_8, SHIFT)
    return mask.astype(bool)


def fill_exact(mask_shape, uv: np.ndarray) -> np.ndarray:
    """Boolean (H, W) mask of exactly the pixel centres inside polygon ``uv`` (N, 2): the exact
    rasterisation a renderer that samples pixel centres produces."""
    from matplotlib.path import Path as PolyPath
    h, w = mask_shape
    x0, y0 = np.clip(np.floor(uv.min(0)).astype(int), 0, [w, h])
    x1, y1 = np.clip(np.ceil(uv.max(0)).astype(int) + 1, 0, [w, h])
    mask = np.zeros(mask_shape, bool)
    if x1 > x0 and y1 > y0:
        ys, xs = np.mgrid[y0:y1, x0:x1]
        inside = PolyPath(uv).contains_points(np.stack([xs.ravel(), ys.ravel()], 1))
        mask[y0:y1, x0:x1] = inside.reshape(xs.shape)
    return mask


def fill_convex(mask_shape, uv: np.ndarray) -> np.ndarray:
    """:func:`fill_exact` of a convex polygon ``uv`` (N, 2), row by row: the pixel centres of each
    row between the row's crossings of the outline (the same mask, about 20x faster than testing
    every pixel of the bounding box)."""
    h, w = mask_shape
    mask = np.zeros(mask_shape, bool)
    y0, y1 = max(int(np.ceil(uv[:, 1].min())), 0), min(int(np.floor(uv[:, 1].max())), h - 1)
    if y1 < y0:
        return mask
    ys = np.arange(y0, y1 + 1, dtype=np.float64)[:, None]
    a, b = uv, np.roll(uv, -1, axis=0)
    dy = b[:, 1] - a[:, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        x = a[:, 0] + (ys - a[:, 1]) / dy * (b[:, 0] - a[:, 0])
    crosses = (ys >= np.minimum(a[:, 1], b[:, 1])) & (ys <= np.maximum(a[:, 1], b[:, 1])) & (dy != 0)
    left = np.clip(np.ceil(np.where(crosses, x, np.inf).min(1)), 0, w).astype(int)
    right = np.clip(np.floor(np.where(crosses, x, -np.inf).max(1)) + 1, 0, w).astype(int)
    for row, (x0, x1) in enumerate(zip(left, right)):
        if x1 > x0:
            mask[y0 + row, x0:x1] = True
    return mask


def painted_passes(frame: FrameScene, static: StaticScene, exact: bool = False) -> RenderPasses:
    """Colour (linear), depth (m, as Blender writes it) and object-index passes of ``frame``'s
    render canvas; ``exact``: markers rasterised exactly at pixel centres (``fill_exact``)."""
    cam = frame.camera
    ox, oy, w, h = cam.canvas()
    k = intrinsics(cam.focal_px, (cam.principal_point[0] - ox, cam.principal_point[1] - oy))
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

    for sec in SECTIONS:   # the flange and the body, each the hull of its circles, at pixel centres
        d_from_s = d_from_b if sec == "B" else np.eye(4)
        for pts in silhouette_parts(static, sec):
            uv, z = project_points(k, cam_from_d @ d_from_s, pts)
            if np.all(z > 0):
                hull = cv2.convexHull(uv.astype(np.float32)).reshape(-1, 2).astype(np.float64)
                paint(fill_convex((h, w), hull), SECTION_RGB, float(z.max()), SECTION_PASS_INDEX[sec])
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
        paint((fill_exact if exact else _fill)((h, w), uv), MARKER_RGB[m.section], z, m.pass_index)
    return RenderPasses(rgb=rgb, depth_mm=depth, index=index)


def write_painted_dataset(root, config_path, exact: bool = False) -> Config:
    """A complete dataset of ``config_path`` in ``root`` (every planned frame, manifest);
    ``exact``: see :func:`painted_passes`."""
    root = Path(root)
    cfg, text = load_config_text(config_path)
    prepare(root, cfg, text)
    static = static_scene(cfg)
    with tempfile.TemporaryDirectory(prefix="painted-") as scratch:
        for spec in frame_plan(cfg):
            frame = sample_frame(cfg, spec)
            exr = Path(scratch) / f"{spec.frame_id}.exr"
            write_compact(exr, painted_passes(frame, static, exact))
            finish_frame(frame, static, exr, root, cfg.render.keep_exr, cfg.labels.visible_threshold,
                         min_chroma=cfg.labels.min_chroma, keep_raw=cfg.sensor.raw_output)
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


# A small camera-unit config (320 x 240): two units with a strong barrel lens, the principal point
# off centre, tangential distortion, chromatic aberration and JPEG; large markers close to the
# camera, so that most are 150 px or more (the label-vs-pixels tests of distorted frames:
# tests/generator/test_camera_units.py paints it, tests/generator/test_render.py renders it).
LENS_CHECK = """
[dataset]
name = "lens-check"
seed = 5
frames = 4
[conditions]
normal = 1
low_light = 0
occlusion = 0
glare = 0
[image]
width = 320
height = 240
[camera]
distance_mm = [600, 650]
focal_px = [330, 345]
margin_px = 10
tilt_deg = 2
lateral_jitter_mm = 10
[pose]
x_mm = [5, 40]
[markers]
diameter_mm = 30
layout_a = [[45, -18], [100, -10], [62, 10], [125, 16], [44, 34], [98, 36]]
layout_b = [[46, -14], [104, -20], [70, 4], [128, 22], [50, 32], [110, 40]]
[camera_units]
count = 2
principal_offset_x_px = [-12, 12]
principal_offset_y_px = [-10, 10]
k1 = [-0.15, -0.1]
k2 = [-0.05, 0.05]
p1 = [-1e-3, 1e-3]
p2 = [-1e-3, 1e-3]
aberration_red_px = [-0.3, 0.3]
aberration_blue_px = [-0.3, 0.3]
jpeg = true
[render]
samples = 1
keep_exr = true
frame_timeout_s = 120
marker_samples = 0   # the job mechanics, not label-aware sampling (its own render tests)
"""


def label_vs_index(root, cfg: Config, min_pixels: int = 150) -> dict:
    """Every fully visible marker of a dataset with kept EXRs: its index-pass pixels against the
    exact rasterisation (pixel centres) of the label's outline in the delivered image (K, lens
    distortion), and the centroid of its index pixels against ``center_px`` and
    ``outline_centroid_px`` for markers of ``min_pixels`` or more. Returns mismatched pixels,
    outline pixels, markers compared and the centroid errors (px) as arrays."""
    import json

    from matplotlib.path import Path as PolyPath

    from dockfactory.generator.exr import read_compact
    from dockfactory.generator.labels import marker_outline_px
    layout = {m.id: m for m in static_scene(cfg).markers}
    out = {"mismatch": 0, "pixels": 0, "markers": 0, "centre_err": [], "centroid_err": []}
    for label_path in sorted((Path(root) / "labels").glob("*.json")):
        label = json.loads(label_path.read_text())
        cam = label["camera"]
        index = read_compact(Path(root) / "exr" / f"{label['frame_id']}.exr").index
        for m in label["markers"]:
            if not m["in_frame"] or m["visible_fraction"] < 0.9:
                continue
            cam_from_s = np.array(cam["cam_from_d"]) @ (np.array(label["d_from_b"]) if m["section"] == "B" else np.eye(4))
            outline, _ = marker_outline_px(layout[m["id"]], np.array(cam["K"]), cam["distortion"], cam_from_s)
            x0, y0 = np.floor(outline.min(0)).astype(int) - 2
            x1, y1 = np.ceil(outline.max(0)).astype(int) + 3
            if x0 < 0 or y0 < 0 or x1 > index.shape[1] or y1 > index.shape[0]:
                continue
            ys, xs = np.mgrid[y0:y1, x0:x1]
            inside = PolyPath(outline).contains_points(np.stack([xs.ravel(), ys.ravel()], 1)).reshape(xs.shape)
            out["mismatch"] += int((inside != (index[y0:y1, x0:x1] == m["pass_index"])).sum())
            out["pixels"] += int(inside.sum())
            out["markers"] += 1
            yi, xi = np.nonzero(index == m["pass_index"])
            if len(xi) >= min_pixels:
                c = np.array([xi.mean(), yi.mean()])
                out["centre_err"].append(float(np.linalg.norm(c - m["center_px"])))
                out["centroid_err"].append(float(np.linalg.norm(c - m["outline_centroid_px"])))
    return {k: np.array(v) if isinstance(v, list) else v for k, v in out.items()}


def _session_painted(tmp_path_factory, config_text: str) -> Path:
    """The painted dataset of ``config_text`` (a config that names no other file), painted once per
    test session: the pytest-xdist workers share the session's base folder and the first to ask
    paints it under a lock. Read it only (:func:`painted_copy` gives a private copy)."""
    base = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        base = base.parent   # <session>/popen-gwN: the workers' common folder
    key = hashlib.sha256(config_text.encode()).hexdigest()[:16]
    folder = base / "painted-once" / key
    folder.mkdir(parents=True, exist_ok=True)
    with open(folder / "lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not (folder / "done").exists():
            shutil.rmtree(folder / "ds", ignore_errors=True)
            (folder / "c.toml").write_text(config_text)
            write_painted_dataset(folder / "ds", folder / "c.toml")
            (folder / "done").touch()
    return folder / "ds"


def painted_copy(tmp_path_factory, root, config_text: str) -> Path:
    """A private copy at ``root`` (not existing yet) of the painted dataset of ``config_text``
    (:func:`_session_painted`: the same bytes :func:`write_painted_dataset` would write there)."""
    shutil.copytree(_session_painted(tmp_path_factory, config_text), root)
    return Path(root)


def painted_from_text(tmp_path_factory, name: str, config_text: str) -> Path:
    """A painted dataset of the config ``config_text`` in a fresh folder of ``tmp_path_factory``
    (module fixtures of the tests that need real 1280 x 960 frames without Blender): a copy of the
    session's one painting of that config."""
    root = tmp_path_factory.mktemp(name)
    (root / "c.toml").write_text(config_text)
    return painted_copy(tmp_path_factory, root / "ds", config_text)


def painted_config(name: str, seed: int, frames: int, train_fraction: float, val_fraction=None) -> str:
    """The TOML text of a small painted dataset at 1280 x 960: normal light only, one
    repeatability pose of 2 captures, no kept EXR (``val_fraction`` None: the default)."""
    val = "" if val_fraction is None else f"val_fraction = {val_fraction}\n"
    return (f'[dataset]\nname = "{name}"\nseed = {seed}\nframes = {frames}\ntrain_fraction = {train_fraction}\n{val}'
            "\n[conditions]\nnormal = 1\n\n[repeatability]\nposes = 1\ncaptures = 2\n\n"
            "[image]\nwidth = 1280\nheight = 960\n\n[render]\nkeep_exr = false\n")


# a painted dataset with a large val split (section offsets measured on it: eval.section_shift)
SHIFT_SPLIT_CONFIG = painted_config("shift-split", 11, 24, 0.5, 0.9)


def offset_detections(ds, frames, shift: float, rng, noise: float = 0.03) -> dict:
    """A detections document of ``frames`` of the opened dataset ``ds``: every fully visible marker
    at its exact centroid, plus one draw of a common offset of std ``shift`` px per frame and section,
    plus ``noise`` px per centre."""
    out = {}
    for fid in frames:
        offset = rng.normal(0.0, shift, (2, 2))
        out[fid] = [{"class_id": m["class_id"], "score": 1.0,
                     "center_px": (np.array(m["outline_centroid_px"]) + offset[m["class_id"]]
                                   + rng.normal(0.0, noise, 2)).tolist()}
                    for m in ds.labels[fid]["markers"] if m.get("visibility") == 2]
    return {"frames": out}
