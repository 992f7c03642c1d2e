"""YOLO-pose export: ultralytics' pose layout, the YOLO export's boxes plus one keypoint per marker.

exports/yolo-pose/
  data.yaml          as the YOLO export's (no ``path:`` key), plus ``kpt_shape: [1, 3]``,
                     ``flip_idx: [0]`` (one keypoint: a horizontal flip maps it to itself) and
                     ``kpt_names`` (``centre`` for each class)
  images/{train,val,test,repeat}/<id>.png   hard links to the dataset's images (else copies)
  labels/{train,val,test,repeat}/<id>.txt   one line per marker: class cx cy w h kx ky v

Why and how: docs/datasets.md, "The YOLO-pose keypoints".
"""
from __future__ import annotations

from pathlib import Path

from dockfactory.core.layout import CLASS_NAMES
from dockfactory.generator.exports.coco import KEYPOINTS, centre_in_image
from dockfactory.generator.exports.yolo import box_fields, exported_markers, write_yolo_layout
from dockfactory.generator.exports.registry import ExportFormat

KEYPOINT_DECIMALS = 10   # normalised: 1e-10 of a 10,000 px image is 1e-6 px


def keypoint_fields(m: dict, w: int, h: int) -> str:
    """``kx ky v`` of marker record ``m`` in a ``w`` x ``h`` image (module docstring)."""
    if not centre_in_image(m, w, h):
        return "0 0 0"
    u, v = m["center_px"]
    vis = 2 if m.get("visibility", 2) == 2 else 1
    return f"{(u + 0.5) / w:.{KEYPOINT_DECIMALS}f} {(v + 0.5) / h:.{KEYPOINT_DECIMALS}f} {vis}"


def pose_lines(label: dict, visible_threshold: float) -> list[str]:
    """One ``class cx cy w h kx ky v`` line per exported marker of ``label``."""
    w, h = label["image"]["width"], label["image"]["height"]
    return [f"{box_fields(m, w, h)} {keypoint_fields(m, w, h)}" for m in exported_markers(label, visible_threshold)]


def parse_pose_keypoint(line: str, w: int, h: int) -> tuple[float, float, int]:
    """The keypoint of one pose line in the labels' OpenCV pixels: (u, v, visibility)."""
    kx, ky, vis = line.split()[5:8]
    return float(kx) * w - 0.5, float(ky) * h - 0.5, int(vis)


def pose_yaml_keys() -> str:
    names = "".join(f"  {i}: [{', '.join(KEYPOINTS)}]\n" for i in range(len(CLASS_NAMES)))
    return (f"# one keypoint per marker (its centre): x, y normalised continuous, visibility 0/1/2\n"
            f"kpt_shape: [{len(KEYPOINTS)}, 3]\nflip_idx: [0]\nkpt_names:\n{names}")


def export_yolo_pose(root, out) -> Path:
    """Write the YOLO-pose export of dataset ``root`` into ``out``.

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
    return write_yolo_layout(root, out, pose_lines, pose_yaml_keys())


FORMATS = (
    ExportFormat("yolo-pose", export_yolo_pose, "YOLO boxes plus each marker's centre as a keypoint"),
)
