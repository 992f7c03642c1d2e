"""``[camera_units] calibration = "cam.yaml"``: render the camera of a calibration file.

A config names a calibration file (OpenCV YAML / JSON, ROS camera_info, COLMAP cameras.txt;
:mod:`dockfactory.core.calibration_files`), relative to the config's folder. Loading the config resolves it
into the keys the factory already has, so everything downstream (the plan, the labels, the version id) is the
same code: ``[image]`` width and height are the file's, ``[camera] focal_px`` is ``[f, f]`` (every frame at the
calibrated focal; the working distance and the pose still vary), and every unit's principal offset and
Brown-Conrady coefficients are the file's (ranges of one value). The dataset stores the resolved config, which
reproduces it without the file.

Square pixels only: a file whose ``fx`` and ``fy`` differ by more than ``MAX_ASPECT_DIFF`` (relative) is refused
(``f`` is sqrt(fx fy)); a key the file sets may not be set in the config too (one line naming both).

Why and how: docs/configuration.md, "A calibration file in a config".
"""
from __future__ import annotations

import math

from dockfactory.core.calibration_files import CalibrationError, read_calibration
from dockfactory.core.user_files import beside_config, short_digest

MAX_ASPECT_DIFF = 1e-5   # |fx - fy| / sqrt(fx fy) the square-pixel renderer accepts (0.07 % moved X 0.45 mm)
LENS_KEYS = ("principal_offset_x_px", "principal_offset_y_px", "k1", "k2", "k3", "p1", "p2")


def _clash(source: str, table: str, key: str, name: str) -> CalibrationError:
    return CalibrationError(f"{source}: [{table}] {key}: set by [camera_units] calibration = {name!r} too; "
                            f"leave it out (the file's value is used)")


def _check_free(data: dict, source: str, name: str, cal) -> None:
    """CalibrationError when the config sets a key the calibration file sets (an equal image size
    is allowed: a config may state the size it expects)."""
    for table in ("image", "camera"):
        if not isinstance(data.get(table, {}), dict):
            raise CalibrationError(f"{source}: [{table}]: expected a table, got {data[table]!r}")
    units, image, camera = data["camera_units"], data.get("image", {}), data.get("camera", {})
    for key in LENS_KEYS:
        if key in units:
            raise _clash(source, "camera_units", key, name)
    if "focal_px" in camera:
        raise _clash(source, "camera", "focal_px", name)
    for key, value in (("width", cal.width), ("height", cal.height)):
        if key in image and image[key] != value:
            raise CalibrationError(f"{source}: [image] {key}: {image[key]!r}, but the calibration file {name!r} is "
                                   f"{cal.width} x {cal.height} px; leave [image] out or make them agree")


def square_focal(cal, where: str) -> float:
    """sqrt(fx fy) px of calibration ``cal``; CalibrationError when its pixels are not square
    within MAX_ASPECT_DIFF (the renderer's pixels are)."""
    f = math.sqrt(cal.fx * cal.fy)
    if abs(cal.fx - cal.fy) / f > MAX_ASPECT_DIFF:
        raise CalibrationError(f"{where}: fx {cal.fx:g} and fy {cal.fy:g} px differ by "
                               f"{100 * abs(cal.fx - cal.fy) / f:.3f} %: the factory renders square pixels (at most "
                               f"{100 * MAX_ASPECT_DIFF:g} % apart), and frames of another camera than the file's "
                               f"would be measured with a bias; calibrate with fx = fy (CALIB_FIX_ASPECT_RATIO) "
                               f"or give both one value")
    return f


def resolve_calibration(data: dict, config_path) -> tuple[dict, str | None]:
    """(data, note): the config's TOML tables ``data`` with ``[camera_units] calibration``
    replaced by the file's camera (module docstring), and a one-line note naming the file and its
    sha256 (None, and ``data`` unchanged, when the config names no calibration). CalibrationError
    (one line: config, key, file) on a missing or bad file, non-square pixels or a clash."""
    units = data.get("camera_units")
    if not isinstance(units, dict) or "calibration" not in units:
        return data, None
    source, name = str(config_path), units["calibration"]
    if not isinstance(name, str):
        raise CalibrationError(f"{source}: [camera_units] calibration: expected a file name, got {name!r}")
    if name == "":
        return data, None
    path = beside_config(name, config_path)
    try:
        cal = read_calibration(path)
        f = square_focal(cal, str(path))
    except CalibrationError as exc:
        raise CalibrationError(f"{source}: [camera_units] calibration: {exc}") from None
    _check_free(data, source, name, cal)
    out = {t: (dict(v) if isinstance(v, dict) else v) for t, v in data.items()}
    out["camera_units"] = {k: v for k, v in units.items() if k != "calibration"}
    out["camera_units"].update({
        "principal_offset_x_px": [cal.cx - (cal.width - 1) / 2.0] * 2,
        "principal_offset_y_px": [cal.cy - (cal.height - 1) / 2.0] * 2,
        **{k: [float(v)] * 2 for k, v in zip(("k1", "k2", "p1", "p2", "k3"), cal.dist)}})
    out["image"] = {**out.get("image", {}), "width": cal.width, "height": cal.height}
    out["camera"] = {**out.get("camera", {}), "focal_px": [f, f]}
    digest = short_digest(path)
    return out, f"[camera_units] calibration = {name!r} (sha256 {digest}...) resolved"
