"""``[camera_units] calibration = "cam.yaml"``: render the camera of a calibration file.

A config names a calibration file (OpenCV YAML / JSON, ROS camera_info, COLMAP cameras.txt;
:mod:`dockfactory.core.calibration_files`), relative to the config's folder. Loading the config resolves it
into the keys the factory already has, so everything downstream (the plan, the labels, the version id) is the
same code: ``[image]`` width and height are the file's, ``[camera] focal_px`` is ``[fx, fx]`` (every frame at the
calibrated focal; the working distance and the pose still vary), and every unit's ``pixel_aspect`` (fy / fx),
principal offset and Brown-Conrady coefficients are the file's (ranges of one value). The dataset stores the
resolved config, which reproduces it without the file.

A file whose fy / fx is further than ``MAX_PIXEL_ASPECT_DIFF`` (core.geometry) from 1 is refused; a key the file
sets may not be set in the config too (one line naming both).

Why and how: docs/configuration.md, "A calibration file in a config".
"""
from __future__ import annotations

from dockfactory.core.calibration_files import CalibrationError, read_calibration
from dockfactory.core.geometry import MAX_PIXEL_ASPECT_DIFF
from dockfactory.core.user_files import beside_config, short_digest

LENS_KEYS = ("principal_offset_x_px", "principal_offset_y_px", "k1", "k2", "k3", "p1", "p2", "pixel_aspect")


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


def pixel_aspect(cal, where: str) -> float:
    """fy / fx of calibration ``cal`` (read from file ``where``); CalibrationError (one line: the
    file, its camera_matrix, fx and fy) when it is further than MAX_PIXEL_ASPECT_DIFF from 1."""
    aspect = cal.fy / cal.fx
    if not 1.0 - MAX_PIXEL_ASPECT_DIFF <= aspect <= 1.0 + MAX_PIXEL_ASPECT_DIFF:
        raise CalibrationError(f"{where}: camera_matrix: fx {cal.fx:g} and fy {cal.fy:g} px: fy / fx = {aspect:.6g} is "
                               f"{100 * abs(aspect - 1.0):.3g} % from 1, beyond the {100 * MAX_PIXEL_ASPECT_DIFF:g} % "
                               f"the factory renders (MAX_PIXEL_ASPECT_DIFF): not a square-pixel camera's calibration")
    return aspect


def resolve_calibration(data: dict, config_path) -> tuple[dict, str | None]:
    """(data, note): the config's TOML tables ``data`` with ``[camera_units] calibration``
    replaced by the file's camera (module docstring), and a one-line note naming the file and its
    sha256 (None, and ``data`` unchanged, when the config names no calibration). CalibrationError
    (one line: config, key, file) on a missing or bad file, a pixel aspect beyond
    MAX_PIXEL_ASPECT_DIFF or a clash."""
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
        aspect = pixel_aspect(cal, str(path))
    except CalibrationError as exc:
        raise CalibrationError(f"{source}: [camera_units] calibration: {exc}") from None
    _check_free(data, source, name, cal)
    out = {t: (dict(v) if isinstance(v, dict) else v) for t, v in data.items()}
    out["camera_units"] = {k: v for k, v in units.items() if k != "calibration"}
    out["camera_units"].update({
        "principal_offset_x_px": [cal.cx - (cal.width - 1) / 2.0] * 2,
        "principal_offset_y_px": [cal.cy - (cal.height - 1) / 2.0] * 2,
        "pixel_aspect": [aspect, aspect],
        **{k: [float(v)] * 2 for k, v in zip(("k1", "k2", "p1", "p2", "k3"), cal.dist)}})
    out["image"] = {**out.get("image", {}), "width": cal.width, "height": cal.height}
    out["camera"] = {**out.get("camera", {}), "focal_px": [float(cal.fx), float(cal.fx)]}
    digest = short_digest(path)
    return out, f"[camera_units] calibration = {name!r} (sha256 {digest}...) resolved"
