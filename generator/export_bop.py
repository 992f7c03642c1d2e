"""BOP export (the layout the BOP toolkit reads). Objects: 1 = section A, 2 = section B.

exports/bop/
  camera.json                     nominal camera (focal varies per frame: see scene_camera.json)
  models/obj_000001.ply, obj_000002.ply, models_info.json   (mm)
  <split>/000000/rgb/<im>.png, scene_camera.json, scene_gt.json, scene_gt_info.json
     (one BOP scene per split; image ids are frame order; frame ids in frame_ids.json)
cam_R_w2c / cam_t_w2c use D as the world; model frames are the section frames (A: D; B: B's
frame); translations in mm. bbox_obj / bbox_visib are [x, y, w, h] in BOP's pixel frame (pixel
corners), counted on pixel centres; px_count_all is the section's silhouette (its convex body and
flange, unoccluded), px_count_visib the pixels of the section in the index pass.
cam_K is the label's K (its principal point, + 0.5 for BOP's pixel corners). BOP has no place
for lens distortion: scene_camera_lens.json beside scene_camera.json holds, per image id, the
camera unit and its distortion coefficients in OpenCV's order (k1, k2, p1, p2, k3), which map
the pinhole image of cam_K to the delivered one (undistort the images or keypoints with them
before using cam_K as a pinhole camera).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from dockfactory.core.io import write_json_atomic, write_text_atomic
from dockfactory.core.layout import SECTIONS
from dockfactory.generator.dataset_open import Dataset
from dockfactory.generator.export_files import place_file, source_image

OBJ_ID = {"A": 1, "B": 2}


def section_mesh(radius: float, length: float, flange_w: float, flange_h: float, section: str, n: int = 96):
    """Vertices (V, 3) and triangles (F, 3) of a section's body and flange, section frame, mm."""
    sign = -1.0 if section == "A" else 1.0
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    rings = [(0.0, radius + flange_h), (sign * flange_w, radius + flange_h), (sign * flange_w, radius),
             (sign * length, radius)]
    verts = np.concatenate([np.stack([np.full(n, x), r * np.sin(a), r * np.cos(a)], 1) for x, r in rings])
    faces = []
    for k in range(len(rings) - 1):
        for i in range(n):
            p, q = k * n + i, k * n + (i + 1) % n
            faces += [(p, q, q + n), (p, q + n, p + n)]
    c0, c1 = len(verts), len(verts) + 1
    verts = np.vstack([verts, [[0.0, 0, 0], [sign * length, 0, 0]]])
    last = (len(rings) - 1) * n
    for i in range(n):
        faces += [(c0, (i + 1) % n, i), (c1, last + i, last + (i + 1) % n)]
    return verts, np.array(faces)


def write_ply(path: Path, verts: np.ndarray, faces: np.ndarray) -> None:
    head = (f"ply\nformat ascii 1.0\ncomment dockfactory section model, mm\nelement vertex {len(verts)}\n"
            f"property float x\nproperty float y\nproperty float z\nelement face {len(faces)}\n"
            f"property list uchar int vertex_indices\nend_header\n")
    body = "".join(f"{x:.4f} {y:.4f} {z:.4f}\n" for x, y, z in verts)
    body += "".join(f"3 {a} {b} {c}\n" for a, b, c in faces)
    write_text_atomic(path, head + body)


def read_ply_vertices(path: Path) -> np.ndarray:
    lines = Path(path).read_text().splitlines()
    n = int(next(l for l in lines if l.startswith("element vertex")).split()[-1])
    start = lines.index("end_header") + 1
    return np.array([[float(v) for v in l.split()] for l in lines[start:start + n]])


def _xywh(box):
    if box is None:
        return [-1, -1, -1, -1]
    x0, y0, x1, y1 = box
    return [round(x0 + 0.5), round(y0 + 0.5), round(x1 - x0), round(y1 - y0)]


def lens_record(cam: dict) -> dict:
    """A label camera's lens for the BOP sidecar (OpenCV's distortion model and order)."""
    return {"camera_unit": cam.get("unit", 0), "dist_coeffs": cam.get("distortion", [0.0] * 5),
            "dist_coeff_names": ["k1", "k2", "p1", "p2", "k3"], "model": "opencv",
            "aberration_px": cam.get("aberration_px"), "depth_of_field": cam.get("depth_of_field")}


def export_bop(root, out) -> Path:
    """The BOP layout of the dataset ``root`` (a folder, or an opened Dataset) under ``out``: the
    two sections' models, a camera.json, and per split one scene with its cameras, ground truth
    and frame ids (module docstring for the conventions)."""
    out = Path(out)
    # intact and complete (opened here, or by the caller that exports several formats): its
    # frames are the plan's, ids and splits checked
    ds = root if isinstance(root, Dataset) else Dataset.open(root)
    cfg = ds.identity["config"]
    _write_models(cfg["sections"], out)
    w, h = cfg["image"]["width"], cfg["image"]["height"]
    write_json_atomic(out / "camera.json", {"width": w, "height": h, "cx": (w - 1) / 2 + 0.5, "cy": (h - 1) / 2 + 0.5,
                                            "fx": float(np.mean(cfg["camera"]["focal_px"])),
                                            "fy": float(np.mean(cfg["camera"]["focal_px"])), "depth_scale": 1.0})
    scenes: dict[str, dict] = {}
    for label in ds.labels_of():
        split = label["spec"]["split"]
        sc = scenes.setdefault(split, {"camera": {}, "gt": {}, "info": {}, "ids": {}, "lens": {}})
        im = str(len(sc["ids"]))
        sc["ids"][im] = label["frame_id"]
        place_file(source_image(ds.root, label["frame_id"]), out / split / "000000" / "rgb" / f"{int(im):06d}.png")
        sc["camera"][im], sc["gt"][im], sc["info"][im] = _frame_records(label)
        sc["lens"][im] = lens_record(label["camera"])
    for split, sc in scenes.items():
        d = out / split / "000000"
        for name, key in (("scene_camera", "camera"), ("scene_gt", "gt"), ("scene_gt_info", "info"),
                          ("frame_ids", "ids"), ("scene_camera_lens", "lens")):
            write_json_atomic(d / f"{name}.json", sc[key])
    return out


def _write_models(sec: dict, out: Path) -> None:
    """models/obj_*.ply of both sections and models_info.json (extents, bounding-box diagonal)."""
    info = {}
    for s in SECTIONS:
        v, f = section_mesh(sec["radius_mm"], sec["length_mm"], sec["flange_width_mm"], sec["flange_height_mm"], s)
        write_ply(out / "models" / f"obj_{OBJ_ID[s]:06d}.ply", v, f)
        lo, hi = v.min(0), v.max(0)
        diameter = float(np.sqrt(((hi - lo) ** 2).sum()))  # bounding-box diagonal >= true diameter
        info[str(OBJ_ID[s])] = {"diameter": diameter, "min_x": lo[0], "min_y": lo[1], "min_z": lo[2],
                                "size_x": hi[0] - lo[0], "size_y": hi[1] - lo[1], "size_z": hi[2] - lo[2]}
    write_json_atomic(out / "models" / "models_info.json", {k: {a: float(b) for a, b in d.items()} for k, d in info.items()})


def _frame_records(label: dict) -> tuple[dict, list, list]:
    """(scene_camera record, scene_gt records, scene_gt_info records) of one frame's label."""
    k = np.array(label["camera"]["K"], dtype=float)
    k[0, 2] += 0.5   # BOP/OpenGL-style pixel corners, like COCO
    k[1, 2] += 0.5
    cam_from_d = np.array(label["camera"]["cam_from_d"])
    camera = {"cam_K": k.ravel().tolist(), "depth_scale": 1.0,
              "cam_R_w2c": cam_from_d[:3, :3].ravel().tolist(), "cam_t_w2c": cam_from_d[:3, 3].tolist()}
    d_from_b = np.array(label["d_from_b"])
    gts, infos = [], []
    for srec in label["sections"]:
        m2c = cam_from_d @ (d_from_b if srec["section"] == "B" else np.eye(4))
        gts.append({"obj_id": OBJ_ID[srec["section"]], "cam_R_m2c": m2c[:3, :3].ravel().tolist(),
                    "cam_t_m2c": m2c[:3, 3].tolist()})
        infos.append({"bbox_obj": _xywh(srec.get("bbox_obj_px")), "bbox_visib": _xywh(srec.get("bbox_visible_px")),
                      "px_count_all": srec.get("pixels_all", 0), "px_count_valid": srec.get("pixels_all", 0),
                      "px_count_visib": srec.get("pixels_visible", 0), "visib_fract": srec.get("visible_fraction", 0.0)})
    return camera, gts, infos
