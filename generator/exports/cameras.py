"""Cameras export: every frame's true intrinsics as calibration files the user's own tools read
(OpenCV YAML, ROS camera_info, COLMAP cameras.txt; :mod:`dockfactory.core.calibration_files`).

The intrinsics are the pinhole K and Brown-Conrady lens the frame was rendered through: the
labels' marker centres are these cameras' projections of the markers (tests hold it to
cv2.projectPoints), fx and fy as the unit's pixel aspect makes them.

Why and how: docs/datasets.md, "The cameras export's files".
"""
from __future__ import annotations

import json
from pathlib import Path

from dockfactory.core.calibration_files import Calibration, calibration_text, colmap_line
from dockfactory.core.io import write_text_atomic
from dockfactory.generator.datasets.reader import Dataset
from dockfactory.generator.exports.registry import ExportFormat

UNIT_FILES = (("opencv-yaml", "unit_{unit:02d}.yaml"), ("ros", "unit_{unit:02d}.ros.yaml"),
              ("colmap", "unit_{unit:02d}.cameras.txt"))


def label_calibration(label: dict) -> Calibration:
    """The camera of one frame's label: image size, K's focal and principal point (px, OpenCV's
    convention) and the unit's distortion (k1, k2, p1, p2, k3)."""
    k, cam = label["camera"]["K"], label["camera"]
    return Calibration(int(label["image"]["width"]), int(label["image"]["height"]), float(k[0][0]),
                       float(k[1][1]), float(k[0][2]), float(k[1][2]), tuple(float(v) for v in cam["distortion"]))


def _write_units(out: Path, cameras: dict[int, set]) -> None:
    """The unit files of every unit whose frames share one camera."""
    for unit, cals in sorted(cameras.items()):
        if len(cals) == 1:
            cal = next(iter(cals))
            for fmt, name in UNIT_FILES:
                write_text_atomic(out / "units" / name.format(unit=unit), calibration_text(cal, fmt))


def export_cameras(root, out) -> Path:
    """Write the cameras export of dataset ``root`` into ``out`` (module docstring).

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
    ds = root if isinstance(root, Dataset) else Dataset.open(root)
    lines, ids, cameras = [], {}, {}
    for index, label in enumerate(ds.labels_of()):
        fid, cal = label["frame_id"], label_calibration(label)
        for fmt, sub in (("opencv-yaml", "opencv"), ("ros", "ros")):
            write_text_atomic(out / sub / f"{fid}.yaml", calibration_text(cal, fmt))
        lines.append(colmap_line(cal, index + 1))
        ids[str(index + 1)] = fid
        cameras.setdefault(int(label["camera"]["unit"]), set()).add(cal)
    header = "# Camera list with one line of data per camera:\n#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n"
    write_text_atomic(out / "colmap" / "cameras.txt", header + "".join(lines))
    write_text_atomic(out / "colmap" / "frame_ids.json", json.dumps(ids, indent=1) + "\n")
    _write_units(out, cameras)
    return out


FORMATS = (
    ExportFormat("cameras", export_cameras, "every frame's camera as OpenCV / ROS / COLMAP calibration files"),
)
