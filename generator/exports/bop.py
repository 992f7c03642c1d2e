"""BOP export (the layout bop_toolkit reads). Objects: 1 = section A, 2 = section B.

Why and how: docs/datasets.md, "The BOP export's files".
"""
from __future__ import annotations

from pathlib import Path

from dockfactory.core.cv import cv2
import numpy as np

from dockfactory.core.io import write_bytes_atomic, write_json_atomic
from dockfactory.core.layout import SECTIONS
from dockfactory.generator.bop_images import depth_png, gt_info, section_mask, visible_mask
from dockfactory.generator.bop_models import part_model, section_mesh, write_ply
from dockfactory.generator.datasets.folder import DatasetError
from dockfactory.generator.datasets.reader import Dataset
from dockfactory.generator.exr import read_compact
from dockfactory.generator.exports.files import place_file, source_exr, source_image
from dockfactory.generator.exports.registry import ExportFormat
from dockfactory.generator.random_draws import static_scene

OBJ_ID = {"A": 1, "B": 2}
TARGET_VISIB_MIN = 0.1   # BOP 19's rule for target instances: visible at least this fraction
SCENE_FILES = (("scene_camera", "camera"), ("scene_gt", "gt"), ("scene_gt_info", "info"), ("frame_ids", "ids"),
               ("scene_camera_lens", "lens"))


def lens_record(cam: dict) -> dict:
    """A label camera's lens for the BOP sidecar (OpenCV's distortion model and order)."""
    return {"camera_unit": cam.get("unit", 0), "dist_coeffs": cam.get("distortion", [0.0] * 5),
            "dist_coeff_names": ["k1", "k2", "p1", "p2", "k3"], "model": "opencv",
            "aberration_px": cam.get("aberration_px"), "depth_of_field": cam.get("depth_of_field")}


def _write_nominal_camera(cfg: dict, out: Path) -> None:
    """camera.json from the dataset's config ``cfg`` (its identity's dict): the image centre (BOP's
    pixel corners), the mean focal as fx and fx times the mean pixel aspect as fy."""
    w, h = cfg["image"]["width"], cfg["image"]["height"]
    fx = float(np.mean(cfg["camera"]["focal_px"]))
    aspect = float(np.mean(cfg["camera_units"].get("pixel_aspect", [1.0, 1.0])))
    write_json_atomic(out / "camera.json", {"width": w, "height": h, "cx": (w - 1) / 2 + 0.5, "cy": (h - 1) / 2 + 0.5,
                                            "fx": fx, "fy": fx * aspect, "depth_scale": 1.0})


def export_bop(root, out) -> Path:
    """The BOP layout of the dataset ``root`` under ``out``: the two sections' models, a camera.json,
    and per split one scene with its images, masks (and with the kept EXR depth and visible masks),
    cameras, ground truth and frame ids (module docstring for the conventions).

    Parameters
    ----------
    root : path or Dataset
        The dataset: its folder, or a Dataset already opened (by a caller writing several formats).
    out : path
        The export's folder (created; files in it are replaced).

    Returns
    -------
    Path
        ``out``.

    Raises
    ------
    DatasetError
        When the dataset is not intact and complete, or a file of it cannot be read.
    """
    out = Path(out)
    # intact and complete (opened here, or by the caller that exports several formats): its
    # frames are the plan's, ids and splits checked
    ds = root if isinstance(root, Dataset) else Dataset.open(root)
    cfg = ds.identity["config"]
    static = static_scene(ds.config)
    _write_models(cfg["sections"], out)
    _write_nominal_camera(cfg, out)
    scenes: dict[str, dict] = {}
    for label in ds.labels_of():
        split = label["spec"]["split"]
        sc = scenes.setdefault(split, {"camera": {}, "gt": {}, "info": {}, "ids": {}, "lens": {}})
        im = str(len(sc["ids"]))
        sc["ids"][im] = label["frame_id"]
        d = out / split / "000000"
        place_file(source_image(ds.root, label["frame_id"]), d / "rgb" / f"{int(im):06d}.png")
        sc["camera"][im], sc["gt"][im] = _frame_records(label)
        sc["info"][im] = _frame_images(ds, label, static, d, int(im), sc["camera"][im])
        sc["lens"][im] = lens_record(label["camera"])
    for split, sc in scenes.items():
        for name, key in SCENE_FILES:
            write_json_atomic(out / split / "000000" / f"{name}.json", sc[key])
    if "test" in scenes:
        write_json_atomic(out / "test_targets_bop19.json", test_targets(scenes["test"]["gt"], scenes["test"]["info"]))
    return out


def test_targets(gts: dict, infos: dict) -> list[dict]:
    """BOP's target list of the test scene (what its evaluation scripts and vis_poses read): each
    object instance at least TARGET_VISIB_MIN visible (``scene_gt_info``'s ``visib_fract``)."""
    return [{"im_id": int(im), "obj_id": gt["obj_id"], "inst_count": 1, "scene_id": 0}
            for im in gts for gt, info in zip(gts[im], infos[im]) if info["visib_fract"] >= TARGET_VISIB_MIN]


def _write_models(sec: dict, out: Path) -> None:
    """models/obj_*.ply of both sections and models_info.json (extents, bounding-box diagonal)."""
    info = {}
    for s in SECTIONS:
        part = sec.get(f"mesh_{s.lower()}_triangles")
        v, n, f = (part_model(sec[f"mesh_{s.lower()}_vertices"], part) if part else
                   section_mesh(sec["radius_mm"], sec["length_mm"], sec["flange_width_mm"], sec["flange_height_mm"], s))
        write_ply(out / "models" / f"obj_{OBJ_ID[s]:06d}.ply", v, n, f)
        # models_eval/: where bop_toolkit's evaluation and vis_poses look by default; the same mesh
        place_file(out / "models" / f"obj_{OBJ_ID[s]:06d}.ply", out / "models_eval" / f"obj_{OBJ_ID[s]:06d}.ply")
        lo, hi = v.min(0), v.max(0)
        diameter = float(np.sqrt(((hi - lo) ** 2).sum()))  # bounding-box diagonal >= true diameter
        info[str(OBJ_ID[s])] = {"diameter": diameter, "min_x": lo[0], "min_y": lo[1], "min_z": lo[2],
                                "size_x": hi[0] - lo[0], "size_y": hi[1] - lo[1], "size_z": hi[2] - lo[2]}
    for folder in ("models", "models_eval"):
        write_json_atomic(out / folder / "models_info.json", {k: {a: float(b) for a, b in d.items()} for k, d in info.items()})


def _png(path: Path, image: np.ndarray) -> None:
    ok, data = cv2.imencode(".png", image)
    if not ok:
        raise RuntimeError(f"{path}: PNG encoding failed")
    write_bytes_atomic(path, data.tobytes())


def _frame_images(ds: Dataset, label: dict, static, d: Path, im: int, camera: dict) -> list[dict]:
    """Write image ``im``'s masks (and with the kept EXR its visible masks and depth, setting
    ``camera['depth_scale']``); returns its scene_gt_info records, in scene_gt's order."""
    index = depth = None
    if ds.config.render.keep_exr:
        passes = read_compact(source_exr(ds.root, label["frame_id"]))
        if passes.index.shape != (label["image"]["height"], label["image"]["width"]):
            raise DatasetError(f"{ds.root}: exr/{label['frame_id']}.exr is {passes.index.shape[1]}x"
                               f"{passes.index.shape[0]}, its image {label['image']['width']}x{label['image']['height']}")
        index = passes.index
        depth, camera["depth_scale"] = depth_png(passes.depth_mm)
        _png(d / "depth" / f"{im:06d}.png", depth)
    infos = []
    for gt, srec in enumerate(label["sections"]):
        mask = section_mask(label, static, srec["section"])
        _png(d / "mask" / f"{im:06d}_{gt:06d}.png", mask.astype(np.uint8) * 255)
        visib = None if index is None else visible_mask(index, mask, static, srec["section"])
        if visib is not None:
            _png(d / "mask_visib" / f"{im:06d}_{gt:06d}.png", visib.astype(np.uint8) * 255)
        infos.append(gt_info(mask, visib, depth, srec))
    return infos


def _frame_records(label: dict) -> tuple[dict, list]:
    """(scene_camera record, scene_gt records) of one frame's label."""
    k = np.array(label["camera"]["K"], dtype=float)
    k[0, 2] += 0.5   # BOP/OpenGL-style pixel corners, like COCO
    k[1, 2] += 0.5
    cam_from_d = np.array(label["camera"]["cam_from_d"])
    camera = {"cam_K": k.ravel().tolist(), "depth_scale": 1.0,
              "cam_R_w2c": cam_from_d[:3, :3].ravel().tolist(), "cam_t_w2c": cam_from_d[:3, 3].tolist()}
    d_from_b = np.array(label["d_from_b"])
    gts = []
    for srec in label["sections"]:
        m2c = cam_from_d @ (d_from_b if srec["section"] == "B" else np.eye(4))
        gts.append({"obj_id": OBJ_ID[srec["section"]], "cam_R_m2c": m2c[:3, :3].ravel().tolist(),
                    "cam_t_m2c": m2c[:3, 3].tolist()})
    return camera, gts


FORMATS = (
    ExportFormat("bop", export_bop, "the BOP layout with masks, depth and the sections' models"),
)
