"""A section from a CAD part rendered by Cycles (configs/octagon_part.toml: an octagonal body with
a flange and a raised rib, A from a glTF binary, B from an STL): the markers cast onto it agree with
the index pass (their pixels are the exact rasterisation of their outlines, their centroids within
0.25 px of the labels' centres), and every pixel the index pass gives a section (its body or its
markers' rings) lies inside the label's silhouette of that section, which covers it (the part's
own triangles, projected and filled)."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from dockfactory.core.config_text import load_config_text
from dockfactory.core.layout import SECTION_PASS_INDEX
from dockfactory.generator.exr import read_compact
from dockfactory.generator.labels import frame_labels
from dockfactory.generator.random_draws import static_scene
from dockfactory.generator.render_job import JobOptions, run_render
from dockfactory.generator.sampler import frame_plan, sample_frame
from dockfactory.generator.silhouette import outlines_mask

pytestmark = pytest.mark.render

SETS = ("dataset.frames=2", "image.width=640", "image.height=480", "camera.focal_px=[600, 1500]",
        "camera.margin_px=24", "render.keep_exr=true", "render.marker_samples=0", "export.formats=[]",
        "conditions.low_light=0", "conditions.occlusion=0", "conditions.glare=0", "repeatability.poses=0")


@pytest.fixture(scope="module")
def part_dataset(repo_root, tmp_path_factory):
    cfg, text = load_config_text(repo_root / "configs" / "octagon_part.toml", SETS)
    root = tmp_path_factory.mktemp("part") / "ds"
    summary = run_render(cfg, root, text, JobOptions(progress=False))
    assert summary.ok and summary.complete, summary.text()
    return cfg, root


def test_markers_on_the_part_agree_with_the_index_pass(part_dataset):
    from pipeline_data import label_vs_index
    cfg, root = part_dataset
    got = label_vs_index(root, cfg, min_pixels=80)
    assert got["markers"] >= 20 and len(got["centre_err"]) >= 10
    assert got["mismatch"] <= 0.005 * got["pixels"], f"{got['mismatch']} of {got['pixels']} marker pixels differ"
    assert got["centre_err"].max() < 0.25, f"median {np.median(got['centre_err']):.3f} max {got['centre_err'].max():.3f}"


def test_the_parts_silhouette_covers_its_rendered_pixels(part_dataset):
    cfg, root = part_dataset
    static = static_scene(cfg)
    for label_path in sorted((Path(root) / "labels").glob("*.json")):
        label = json.loads(label_path.read_text())
        index = read_compact(Path(root) / "exr" / f"{label['frame_id']}.exr").index
        frame = sample_frame(cfg, next(s for s in frame_plan(cfg) if s.frame_id == label["frame_id"]))
        for rec in frame_labels(frame, static, None, 0.5)["sections"]:
            sec = rec["section"]
            ids = [SECTION_PASS_INDEX[sec]] + [m.pass_index for m in static.markers if m.section == sec]
            seen = np.isin(index, ids)
            mask = _silhouette(frame, static, sec)
            outside = seen & ~mask
            assert outside.sum() <= 0.002 * seen.sum() + 20, f"{label['frame_id']} {sec}: {outside.sum()} of {seen.sum()}"
            assert rec["pixels_all"] == int(mask.sum()) >= seen.sum() * 0.98


def _silhouette(frame, static, sec):
    from dockfactory.generator.labels import part_outlines, section_uv
    from dockfactory.generator.silhouette import silhouette_parts
    cam = frame.camera
    parts = [section_uv(p, sec, cam, cam.cam_from_d_array(), frame.d_from_b_array(), None)
             for p in silhouette_parts(static, sec)]
    return outlines_mask(part_outlines(parts, cam), cam.width, cam.height)


def test_the_bop_models_are_the_parts(part_dataset):
    from dockfactory.core.mesh_files import read_mesh
    from dockfactory.generator.datasets import tools as dt
    cfg, root = part_dataset
    out = dt.export(root, "bop")
    for obj, sec in ((1, "a"), (2, "b")):
        model = read_mesh(out / "models" / f"obj_{obj:06d}.ply")
        s = cfg.sections
        want = np.asarray(getattr(s, f"mesh_{sec}_vertices"))[np.asarray(getattr(s, f"mesh_{sec}_triangles"))]
        assert np.abs(model.corners() - want).max() < 1e-4   # written with 4 decimals (mm)


def test_a_part_renders_in_its_files_materials(repo_root, tmp_path):
    """``[sections] materials = "file"``: A's part in a saturated green and B's in a saturated red
    (their glTF materials) come out of Cycles and the camera model in those colours on every pixel
    the index pass gives each section's body (the factory's paint would be a random colour)."""
    import cv2

    from dockfactory.core.mesh_base import TriMesh
    from dockfactory.core.mesh_files import read_mesh, write_mesh
    parts = tmp_path / "parts"
    parts.mkdir()
    colours = {"a": (0.03, 0.5, 0.03, 0.0, 0.6), "b": (0.5, 0.03, 0.03, 0.0, 0.6)}
    for sec, name in (("a", "octagon_a.glb"), ("b", "octagon_b.stl")):
        m = read_mesh(repo_root / "configs" / "parts" / name)
        write_mesh(TriMesh(m.vertices, m.triangles, np.array([colours[sec]]), np.zeros(len(m.triangles), int)),
                   parts / f"c_{sec}.glb")
    text = (repo_root / "configs" / "octagon_part.toml").read_text().replace("octagon_a.glb", "c_a.glb")
    (tmp_path / "c.toml").write_text(text.replace("octagon_b.stl", "c_b.glb").replace(
        "[sections]\n", '[sections]\nmaterials = "file"\n'))
    sets = ("dataset.frames=1", "image.width=320", "image.height=240", "camera.focal_px=[300, 750]",
            "camera.margin_px=12", *SETS[5:])
    cfg, text = load_config_text(tmp_path / "c.toml", sets)
    summary = run_render(cfg, tmp_path / "ds", text, JobOptions(progress=False))
    assert summary.ok and summary.complete, summary.text()
    fid = frame_plan(cfg)[0].frame_id
    index = read_compact(tmp_path / "ds" / "exr" / f"{fid}.exr").index
    rgb = cv2.cvtColor(cv2.imread(str(tmp_path / "ds" / "images" / f"{fid}.png")), cv2.COLOR_BGR2RGB).astype(float)
    for sec, channel in (("A", 1), ("B", 0)):
        body = index == SECTION_PASS_INDEX[sec]
        assert body.sum() > 500, f"{sec}: {body.sum()} pixels"
        mean = rgb[body].mean(axis=0)
        others = [mean[c] for c in range(3) if c != channel]
        assert mean[channel] > 1.4 * max(others), f"section {sec}: mean RGB {mean.round(1)}"
