"""Per-image BOP data of one frame: the sections' masks, the depth image and scene_gt_info records.

BOP boxes (``bbox_obj``, ``bbox_visib``) follow bop_toolkit's ``misc.calc_2d_bbox`` on the masks'
pixel indices: ``[x_min, y_min, x_max - x_min, y_max - y_min]``, ``[-1, -1, -1, -1]`` for an empty
mask. Without the kept EXR, ``px_count_visib`` and ``bbox_visib`` are the label's (counted on the
index pass at render time, not cut to ``mask``), and ``px_count_valid`` is ``px_count_all``.

Why and how: docs/datasets.md, "BOP masks and depth".
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dockfactory.core.geometry import transform_points
from dockfactory.core.layout import SECTION_PASS_INDEX
from dockfactory.core.scene import StaticScene
from dockfactory.generator.labels import part_outlines
from dockfactory.generator.motion import label_rolling_view
from dockfactory.generator.silhouette import outlines_mask, silhouette_parts

DEPTH_SCALES = (0.1, 1.0, 10.0)   # mm per depth unit, the first that holds the frame's farthest hit
NO_HIT_MM = 1e6                   # depth at or beyond this (or not finite) is background: value 0


@dataclass(frozen=True)
class LabelLens:
    """The camera of a label record in the shape generator.labels.distorted_region reads."""
    k_matrix: np.ndarray
    distortion: tuple
    canvas_box: tuple

    @classmethod
    def of(cls, cam: dict) -> LabelLens:
        c = cam["render_canvas"]
        return cls(np.asarray(cam["K"], dtype=np.float64), tuple(cam.get("distortion", (0.0,) * 5)),
                   (c["offset_px"][0], c["offset_px"][1], c["width"], c["height"]))

    def k(self) -> np.ndarray:
        return self.k_matrix

    def canvas(self) -> tuple:
        return self.canvas_box


def pinhole_px(label: dict, pts: np.ndarray, sec: str) -> np.ndarray | None:
    """Points ``pts`` (M, 3) mm of section ``sec`` in pinhole pixels (M, 2) of the label's camera
    (B's at their row times under a rolling shutter); None when one is behind the camera. The
    projection of generator.labels ``_silhouette_uv``, on the label's record."""
    rolling = label_rolling_view(label) if sec == "B" else None
    if rolling is not None:
        uv, z, _ = rolling.project(pts)
        return uv if np.all(z > 0) else None
    cam = label["camera"]
    d_from_s = np.asarray(label["d_from_b"], dtype=np.float64) if sec == "B" else np.eye(4)
    cam_pts = transform_points(np.asarray(cam["cam_from_d"], dtype=np.float64) @ d_from_s, pts)
    if not np.all(cam_pts[:, 2] > 0):
        return None
    return cam_pts[:, :2] / cam_pts[:, 2:] * cam["focal_px"] + np.asarray(cam["principal_point"])


def section_outlines(label: dict, static: StaticScene, sec: str) -> list[np.ndarray]:
    """The outlines (M, 2) in the delivered image, OpenCV px, of the section's flange and body
    (generator.silhouette): each part's pinhole hull, distorted by the unit's lens; none when part
    of the section is behind the camera."""
    parts_uv = [pinhole_px(label, pts, sec) for pts in silhouette_parts(static, sec)]
    if any(uv is None for uv in parts_uv):
        return []
    return part_outlines(parts_uv, LabelLens.of(label["camera"]))


def section_mask(label: dict, static: StaticScene, sec: str) -> np.ndarray:
    """(H, W) bool: the section's silhouette in the delivered image (module docstring)."""
    w, h = label["image"]["width"], label["image"]["height"]
    return outlines_mask(section_outlines(label, static, sec), w, h)


def visible_mask(index: np.ndarray, mask: np.ndarray, static: StaticScene, sec: str) -> np.ndarray:
    """(H, W) bool: the pixels of ``mask`` (H, W) whose index pass ``index`` (H, W) shows the
    section's body or one of its markers."""
    ids = [SECTION_PASS_INDEX[sec]] + [m.pass_index for m in static.markers if m.section == sec]
    return mask & np.isin(index, ids)


def bop_box(mask: np.ndarray) -> list[int]:
    """bop_toolkit's calc_2d_bbox of a mask's pixels: [x, y, x_max - x, y_max - y] (indices)."""
    ys, xs = np.nonzero(mask)
    if len(xs) == 0:
        return [-1, -1, -1, -1]
    return [int(xs.min()), int(ys.min()), int(xs.max() - xs.min()), int(ys.max() - ys.min())]


def depth_png(depth_mm: np.ndarray) -> tuple[np.ndarray, float]:
    """(uint16 (H, W) depth image, depth_scale): ``depth_mm`` (H, W) in units of the first of
    DEPTH_SCALES that holds its farthest hit, rounded; 0 where nothing was hit. ValueError when
    even the coarsest scale cannot hold it."""
    d = np.asarray(depth_mm, dtype=np.float64)
    hit = np.isfinite(d) & (d > 0) & (d < NO_HIT_MM)
    far = float(d[hit].max()) if hit.any() else 0.0
    scale = next((s for s in DEPTH_SCALES if far / s <= np.iinfo(np.uint16).max - 0.5), None)
    if scale is None:
        raise ValueError(f"depth {far:.0f} mm is beyond the BOP depth range ({DEPTH_SCALES[-1]} mm units)")
    out = np.zeros(d.shape, np.uint16)
    out[hit] = np.maximum(1, np.round(d[hit] / scale)).astype(np.uint16)
    return out, scale


def gt_info(mask: np.ndarray, visib: np.ndarray | None, depth: np.ndarray | None, srec: dict) -> dict:
    """One scene_gt_info record from the section's ``mask`` (H, W) bool, its visible mask and the
    depth image (None without the kept EXR: then the visible figures are the label's ``srec``,
    which the render counted on its index pass, and every mask pixel counts as valid)."""
    all_px = int(mask.sum())
    if visib is not None:
        n_visib, box_visib = int(visib.sum()), bop_box(visib)
    else:
        n_visib = int(srec.get("pixels_visible", 0))
        box_visib = label_box(srec.get("bbox_visible_px"))
    valid = all_px if depth is None else int((mask & (depth > 0)).sum())
    return {"bbox_obj": bop_box(mask), "bbox_visib": box_visib, "px_count_all": all_px,
            "px_count_valid": valid, "px_count_visib": n_visib,
            "visib_fract": min(1.0, n_visib / all_px) if all_px else 0.0}


def label_box(box) -> list[int]:
    """A label's pixel-edge box [x0, y0, x1, y1] (OpenCV, pixel centres at integers) as calc_2d_bbox gives
    it for the pixels it spans."""
    if box is None:
        return [-1, -1, -1, -1]
    x0, y0, x1, y1 = (round(v + 0.5) for v in box)
    return [x0, y0, x1 - x0 - 1, y1 - y0 - 1]
