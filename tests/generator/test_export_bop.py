"""The BOP export's masks, depth, scene_gt_info and models, against the labels and the kept EXR.

Datasets without Blender: the painted smoke dataset (conftest ``painted``: [render] keep_exr, so
depth and index passes are kept; sections and markers painted into them) and test_exports'
painted dataset (no EXR kept: masks from geometry only). bop_toolkit's own loaders run on the
export when bop_toolkit_lib can be imported (it is not on PyPI: see docs/datasets.md).
"""
import importlib
import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
from bop_toolkit_check import RENDERER_MISSING
from test_exports import write_dataset

from dockfactory.generator.datasets import tools as dt
from dockfactory.generator.exports import bop as export_bop
from dockfactory.generator.bop_images import NO_HIT_MM, bop_box, depth_png, label_box, section_outlines
from dockfactory.generator.bop_models import SEGMENTS, read_ply, section_mesh, write_ply
from dockfactory.generator.datasets.folder import DatasetError
from dockfactory.generator.datasets.reader import Dataset
from dockfactory.generator.exr import RenderPasses, read_compact
from dockfactory.generator.random_draws import static_scene

HERE = Path(__file__).resolve().parent
INFO_KEYS = {"bbox_obj", "bbox_visib", "px_count_all", "px_count_valid", "px_count_visib", "visib_fract"}


ROLLING = "\n[motion]\nenabled = true\nvelocity_mm_s = [40, 80]\nrolling_shutter_ms = 25\n"


@pytest.fixture(scope="module", params=["smoke", "lens", "rolling"])
def with_exr(request, tmp_path_factory):
    """A painted dataset with kept EXRs, exported to BOP: the smoke config (pinhole), the lens
    check config (two units with strong distortion) and the smoke config with B moving under a
    rolling shutter (B's silhouette at its row times)."""
    from pipeline_data import LENS_CHECK, painted_from_text

    from dockfactory.core.resources import shipped_config
    smoke = shipped_config("smoke").read_text()
    text = {"smoke": smoke, "lens": LENS_CHECK, "rolling": smoke + ROLLING}[request.param]
    root = painted_from_text(tmp_path_factory, f"bop-{request.param}", text)
    dt.export(root, "bop")
    return root


def read_png(path):
    im = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    assert im is not None, path
    return im


def scenes(root):
    """(scene dir, image id, frame id) of every image of a BOP export."""
    for frame_ids in sorted((root / "exports" / "bop").glob("*/000000/frame_ids.json")):
        for im, fid in json.loads(frame_ids.read_text()).items():
            yield frame_ids.parent, int(im), fid


def test_masks_depth_and_gt_info_match_the_labels_and_passes(with_exr):
    from pipeline_data import fill_exact
    ds = Dataset.open(with_exr)
    static = static_scene(ds.config)
    n = 0
    for d, im, fid in scenes(with_exr):
        lab, passes = ds.labels[fid], read_compact(with_exr / "exr" / f"{fid}.exr")
        cam = json.loads((d / "scene_camera.json").read_text())[str(im)]
        infos = json.loads((d / "scene_gt_info.json").read_text())[str(im)]
        depth = read_png(d / "depth" / f"{im:06d}.png")
        assert depth.dtype == np.uint16 and depth.shape == passes.depth_mm.shape
        hit = np.isfinite(passes.depth_mm) & (passes.depth_mm < NO_HIT_MM)
        err = np.abs(depth[hit] * cam["depth_scale"] - passes.depth_mm[hit])
        assert err.max() <= cam["depth_scale"] / 2 + 1e-3 and not depth[~hit].any()
        for gt, (srec, info) in enumerate(zip(lab["sections"], infos)):
            assert set(info) == INFO_KEYS
            mask = read_png(d / "mask" / f"{im:06d}_{gt:06d}.png")
            visib = read_png(d / "mask_visib" / f"{im:06d}_{gt:06d}.png")
            assert mask.dtype == np.uint8 and set(np.unique(mask)) <= {0, 255} and set(np.unique(visib)) <= {0, 255}
            mask, visib = mask > 0, visib > 0
            # the full mask: exactly the pixel centres inside the flange or the body (matplotlib's test)
            outlines = section_outlines(lab, static, srec["section"])
            assert len(outlines) == 2
            assert (mask == (fill_exact(mask.shape, outlines[0]) | fill_exact(mask.shape, outlines[1]))).all()
            # the label's silhouette: the same pixels (count and box)
            assert info["px_count_all"] == mask.sum() == srec["pixels_all"]
            # the visible mask: the index pass's pixels of the section, within the silhouette
            index = passes.index
            ids = [srec["pass_index"]] + [m["pass_index"] for m in lab["markers"] if m["section"] == srec["section"]]
            assert (visib == (mask & np.isin(index, ids))).all()
            assert info["px_count_visib"] == visib.sum() <= srec["pixels_visible"]
            assert info["visib_fract"] == pytest.approx(visib.sum() / mask.sum(), abs=1e-12)
            assert info["px_count_valid"] == (mask & (depth > 0)).sum()
            assert info["bbox_visib"] == bop_box(visib) and info["bbox_obj"] == bop_box(mask)
            assert info["bbox_obj"] == label_box(srec["bbox_obj_px"])
            n += 1
    assert n >= 8


def test_visible_masks_keep_nearly_all_the_index_pass(with_exr):
    """What the cut to the silhouette drops: index-pass pixels outside the pixel-centre silhouette
    (edge pixels; marker discs standing proud of the body)."""
    ds = Dataset.open(with_exr)
    kept = total = 0
    for d, im, fid in scenes(with_exr):
        for gt, srec in enumerate(ds.labels[fid]["sections"]):
            kept += int((read_png(d / "mask_visib" / f"{im:06d}_{gt:06d}.png") > 0).sum())
            total += srec["pixels_visible"]
    assert total > 0 and kept / total > 0.97


def test_without_kept_exr_masks_come_from_geometry_only(tmp_path):
    root = write_dataset(tmp_path / "ds")
    dt.export(root, "bop")
    ds = Dataset.open(root)
    bop = root / "exports" / "bop"
    assert not list(bop.rglob("depth")) and not list(bop.rglob("mask_visib"))
    for d, im, fid in scenes(root):
        infos = json.loads((d / "scene_gt_info.json").read_text())[str(im)]
        assert json.loads((d / "scene_camera.json").read_text())[str(im)]["depth_scale"] == 1.0
        for gt, (srec, info) in enumerate(zip(ds.labels[fid]["sections"], infos)):
            mask = read_png(d / "mask" / f"{im:06d}_{gt:06d}.png") > 0
            assert info["px_count_all"] == mask.sum() == info["px_count_valid"] == srec["pixels_all"]
            assert info["px_count_visib"] == srec["pixels_visible"]
            assert info["bbox_visib"] == label_box(srec["bbox_visible_px"])


def test_an_exr_of_another_size_is_refused(tmp_path, monkeypatch):
    """A kept EXR whose passes are not the image's size stops the export, naming the file."""
    import dataclasses
    ds = Dataset.open(write_dataset(tmp_path / "ds"))
    ds.config = dataclasses.replace(ds.config, render=dataclasses.replace(ds.config.render, keep_exr=True))
    small = RenderPasses(rgb=np.zeros((3, 4, 3), np.float32), depth_mm=np.zeros((3, 4), np.float32),
                         index=np.zeros((3, 4), np.int32))
    monkeypatch.setattr(export_bop, "read_compact", lambda path: small)
    monkeypatch.setattr(export_bop, "source_exr", lambda root, fid: root / "exr" / f"{fid}.exr")
    with pytest.raises(DatasetError, match=r"exr/\d+\.exr is 4x3, its image 320x240"):
        export_bop.export_bop(ds, tmp_path / "bop")


def test_depth_scale_is_the_finest_that_holds_the_frame():
    d = np.array([[500.0, np.inf], [6553.0, 0.0]])
    img, scale = depth_png(d)
    assert scale == 0.1 and img.tolist() == [[5000, 0], [65530, 0]]
    img, scale = depth_png(np.array([[500.0, 20000.0]]))
    assert scale == 1.0 and img.tolist() == [[500, 20000]]
    assert depth_png(np.array([[np.inf, 2e6]]))[0].tolist() == [[0, 0]]   # no hit: 0
    with pytest.raises(ValueError, match="beyond the BOP depth range"):
        depth_png(np.array([[700000.0]]))


@pytest.mark.parametrize("section", ["A", "B"])
def test_models_have_outward_unit_normals_and_enclose_the_section(section, tmp_path):
    radius, length, fw, fh = 300.0, 1200.0, 40.0, 8.0
    verts, normals, faces = section_mesh(radius, length, fw, fh, section)
    assert np.allclose(np.linalg.norm(normals, axis=1), 1.0)
    a, b, c = (verts[faces[:, i]] for i in range(3))
    face_n = np.cross(b - a, c - a)
    face_n /= np.linalg.norm(face_n, axis=1, keepdims=True)
    # every vertex normal within one segment's angle of its faces' normals (flat faces: equal)
    cos = np.einsum("ij,ij->i", np.repeat(face_n, 3, axis=0), normals[faces.ravel()])
    assert cos.min() > np.cos(2 * np.pi / SEGMENTS) - 1e-9
    # outward winding: the divergence theorem gives the solid's (polygonal) volume, positive
    volume = np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6
    polygon = SEGMENTS / 2 * np.sin(2 * np.pi / SEGMENTS)
    assert volume == pytest.approx(polygon * ((radius + fh) ** 2 * fw + radius ** 2 * (length - fw)), rel=1e-9)
    xs = verts[:, 0] * (-1 if section == "A" else 1)      # A extends toward -X, B toward +X
    assert xs.min() == 0 and xs.max() == pytest.approx(length)
    write_ply(tmp_path / "m.ply", verts, normals, faces)
    back = read_ply(tmp_path / "m.ply")
    assert np.allclose(back["pts"], verts, atol=1e-4) and np.allclose(back["normals"], normals, atol=1e-6)
    assert (back["faces"] == faces).all()


# ----------------------------------------------------------------------------- bop_toolkit's own code

@pytest.fixture
def bop_toolkit(monkeypatch):
    """bop_toolkit_lib made importable: installed, or the checkout named by DOCKFACTORY_BOP_TOOLKIT
    (bop_toolkit is not on PyPI: docs/datasets.md)."""
    folder = os.environ.get("DOCKFACTORY_BOP_TOOLKIT")
    if folder and (Path(folder) / "bop_toolkit_lib" / "inout.py").is_file():
        monkeypatch.syspath_prepend(folder)
    elif importlib.util.find_spec("bop_toolkit_lib") is None:
        pytest.skip("bop_toolkit_lib absent (not on PyPI: set DOCKFACTORY_BOP_TOOLKIT to a bop_toolkit checkout)")
    try:
        return importlib.import_module("bop_toolkit_lib.inout")
    except ImportError as exc:   # its own dependencies (imageio, pypng, scipy)
        pytest.skip(f"bop_toolkit_lib does not import here: {exc}")


def test_bop_toolkit_reads_the_export(with_exr, bop_toolkit):
    inout = bop_toolkit
    bop = with_exr / "exports" / "bop"
    model = inout.load_ply(str(bop / "models" / "obj_000002.ply"))
    mine = read_ply(bop / "models" / "obj_000002.ply")
    assert np.allclose(model["pts"], mine["pts"]) and np.allclose(model["normals"], mine["normals"])
    assert (model["faces"] == mine["faces"]).all()
    for d, im, fid in scenes(with_exr):
        cams = inout.load_scene_camera(str(d / "scene_camera.json"))
        gts = inout.load_scene_gt(str(d / "scene_gt.json"))
        infos = inout.load_json(str(d / "scene_gt_info.json"), keys_to_int=True)
        depth = inout.load_depth(str(d / "depth" / f"{im:06d}.png")) * cams[im]["depth_scale"]
        passes = read_compact(with_exr / "exr" / f"{fid}.exr")
        hit = depth > 0
        assert np.abs(depth[hit] - passes.depth_mm[hit]).max() <= cams[im]["depth_scale"] / 2 + 1e-3
        assert [g["obj_id"] for g in gts[im]] == [1, 2] and len(infos[im]) == 2
        mask = inout.load_im(str(d / "mask_visib" / f"{im:06d}_{1:06d}.png"))
        assert int((mask > 0).sum()) == infos[im][1]["px_count_visib"]


@pytest.mark.slow   # bop_toolkit's calc_gt_info and renderer (software OpenGL) on 10 images: about 5 s
def test_bop_toolkit_calc_gt_info_and_renderer_agree_with_the_export(with_exr, bop_toolkit, tmp_path, request):
    if request.node.callspec.params["with_exr"] != "smoke":
        pytest.skip("bop_toolkit renders pinhole cameras and rigid poses: the smoke (pinhole) dataset only")
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (env.get("DOCKFACTORY_BOP_TOOLKIT"), env.get("PYTHONPATH")) if p)
    proc = subprocess.run([sys.executable, str(HERE / "bop_toolkit_check.py"), str(with_exr / "exports" / "bop"),
                           str(tmp_path), "320", "240"], capture_output=True, text=True, env=env, timeout=600)
    if proc.returncode == RENDERER_MISSING:
        pytest.skip(proc.stderr.strip())
    assert proc.returncode == 0, proc.stderr[-3000:]
    res = json.loads(proc.stdout.strip().splitlines()[-1])
    n = 0
    for d, im, _ in scenes(with_exr):
        split = d.parent.name
        ours = json.loads((d / "scene_gt_info.json").read_text())[str(im)]
        theirs = res["gt_info"][split][str(im)]
        for mine, calc, (render_only, mask_only) in zip(ours, theirs, res["masks"][split][str(im)]):
            # their render of the model in the exported pose is the exported mask, to the pixels
            # whose centre lies on an edge (measured: at most 2 per object)
            assert render_only + mask_only <= 3
            # calc_gt_info's in-image silhouette with depth: the mask (the painted depth covers it)
            assert abs(calc["px_count_valid"] - mine["px_count_all"]) <= 3
            n += 1
    assert n == 2 * len(list(scenes(with_exr)))
    if res["vis_poses"] is not None:   # an overlay and a depth difference per test image
        test_ims = json.loads((with_exr / "exports" / "bop" / "test" / "000000" / "frame_ids.json").read_text())
        assert res["vis_poses"] == sorted(f"{int(im):06d}_{kind}.jpg" for im in test_ims for kind in ("depth_diff", "overlay"))


def test_models_eval_and_test_targets(with_exr):
    bop = with_exr / "exports" / "bop"
    for name in ("obj_000001.ply", "obj_000002.ply", "models_info.json"):
        assert (bop / "models_eval" / name).read_bytes() == (bop / "models" / name).read_bytes()
    targets = json.loads((bop / "test_targets_bop19.json").read_text())
    infos = json.loads((bop / "test" / "000000" / "scene_gt_info.json").read_text())
    expected = [(int(im), gt + 1) for im, recs in infos.items() for gt, r in enumerate(recs) if r["visib_fract"] >= 0.1]
    assert [(t["im_id"], t["obj_id"]) for t in targets] == expected and expected
    assert all(t["scene_id"] == 0 and t["inst_count"] == 1 for t in targets)
