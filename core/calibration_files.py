"""Camera calibration files in and out: OpenCV (YAML / JSON), ROS ``camera_info`` (YAML) and
COLMAP ``cameras.txt``.

One in-memory form, :class:`Calibration`: image size, focal lengths and principal point in
pixels with OpenCV's pixel convention (the centre of the top-left pixel at (0, 0): what the
factory's labels and solver use, conventions.md), and the Brown-Conrady distortion in OpenCV's
order (k1, k2, p1, p2, k3). COLMAP's principal point (the top-left pixel's centre at (0.5, 0.5))
is converted both ways; OpenCV's ``std_deviations_intrinsics`` are read into ``Calibration.std``.

Files are parsed as data (``cv2.FileStorage`` for YAML / JSON, a line reader for COLMAP), at most
MAX_BYTES; every problem is a one-line CalibrationError naming the file and the key.

Why and how: docs/configuration.md, "Calibration files".
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from dockfactory.core.cv import cv2
import numpy as np

from dockfactory.core.errors import DockfactoryError
from dockfactory.core.io import write_text_atomic
from dockfactory.core.user_files import check_regular_file

MAX_BYTES = 1 << 20
FORMATS = ("opencv-yaml", "opencv-json", "ros", "colmap")
COLMAP_PARAMS = {"SIMPLE_PINHOLE": ("f", "cx", "cy"), "PINHOLE": ("fx", "fy", "cx", "cy"),
                 "SIMPLE_RADIAL": ("f", "cx", "cy", "k1"), "RADIAL": ("f", "cx", "cy", "k1", "k2"),
                 "OPENCV": ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2"),
                 "FULL_OPENCV": ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6")}
COLMAP_CENTRE = 0.5   # COLMAP's coordinate of the top-left pixel's centre (OpenCV's: 0)
STD_KEY = "std_deviations_intrinsics"   # optional, OpenCV YAML / JSON: calibrateCameraExtended's layout


class CalibrationError(DockfactoryError):
    """A calibration file that cannot be used; the message names the file and the key."""


@dataclass(frozen=True)
class Calibration:
    """A calibrated camera: ``width`` x ``height`` px, ``fx``, ``fy``, ``cx``, ``cy`` px (OpenCV's
    pixel convention), ``dist`` (k1, k2, p1, p2, k3); ``std``: their 1-sigma uncertainties
    (fx, fy, cx, cy, k1, k2, p1, p2, k3) when the file states them, else None."""
    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    dist: tuple = (0.0, 0.0, 0.0, 0.0, 0.0)
    std: tuple | None = None

    @property
    def K(self) -> np.ndarray:
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])


def _checked(cal: Calibration, where: str) -> Calibration:
    """``cal`` if its numbers are a camera's: finite, positive focal lengths and size."""
    values = (cal.fx, cal.fy, cal.cx, cal.cy, *cal.dist)
    if not all(math.isfinite(v) for v in values):
        raise CalibrationError(f"{where}: a non-finite number among the intrinsics {values}")
    if not (cal.width > 0 and cal.height > 0 and cal.fx > 0 and cal.fy > 0):
        raise CalibrationError(f"{where}: expected a positive image size and focal lengths, got "
                               f"{cal.width} x {cal.height}, fx {cal.fx:g}, fy {cal.fy:g}")
    if len(cal.dist) != 5:
        raise CalibrationError(f"{where}: expected 5 distortion coefficients (k1, k2, p1, p2, k3)")
    if cal.std is not None and (len(cal.std) != 9 or not all(math.isfinite(v) and v >= 0 for v in cal.std)):
        raise CalibrationError(f"{where}: std_deviations_intrinsics: expected 9 finite values >= 0 (fx, fy, cx, cy, "
                               f"k1, k2, p1, p2, k3), got {cal.std}")
    return cal


def _five(coeffs, where: str) -> tuple:
    """OpenCV's k1, k2, p1, p2, k3 of a distortion vector of 4, 5, 8, 12 or 14 values (the
    rational and thin-prism terms must be 0: the factory's lens model has none)."""
    c = [float(v) for v in coeffs]
    if len(c) not in (4, 5, 8, 12, 14):
        raise CalibrationError(f"{where}: distortion_coefficients: expected 4, 5, 8, 12 or 14 values, got {len(c)}")
    if any(v != 0.0 for v in c[5:]):
        raise CalibrationError(f"{where}: distortion_coefficients: terms beyond k3 (rational, thin prism) are not "
                               f"supported, got {c[5:]}")
    return tuple((c + [0.0])[:5])


def _text(path: Path) -> str:
    check_regular_file(path, "calibration file")
    try:
        if path.stat().st_size > MAX_BYTES:
            raise CalibrationError(f"{path}: {path.stat().st_size} bytes: not a calibration file (at most {MAX_BYTES})")
        return path.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise CalibrationError(f"{path}: calibration file not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise CalibrationError(f"{path}: unreadable calibration file ({type(exc).__name__})") from None


def _numbers(fs, key: str, where: str) -> list[float]:
    """The numbers of node ``key``: an OpenCV matrix, a ROS ``{rows, cols, data}`` or a list."""
    node = fs.getNode(key)
    if node.empty():
        raise CalibrationError(f"{where}: {key}: missing")
    seq = node.getNode("data") if node.isMap() else node
    if not seq.isSeq():
        raise CalibrationError(f"{where}: {key}: expected a matrix or a list of numbers")
    items = [seq.at(i) for i in range(seq.size())]
    if not all(it.isReal() or it.isInt() for it in items):
        raise CalibrationError(f"{where}: {key}: expected numbers only")
    return [float(it.real()) for it in items]


def _stds(fs, where: str) -> tuple | None:
    """The optional ``std_deviations_intrinsics`` (fx, fy, cx, cy, then 4, 5, 8, 12 or 14
    distortion terms, those beyond k3 0 or absent) as 9 values, or None."""
    if fs.getNode(STD_KEY).empty():
        return None
    values = _numbers(fs, STD_KEY, where)
    if len(values) < 8:
        raise CalibrationError(f"{where}: {STD_KEY}: expected fx, fy, cx, cy and the distortion terms, "
                               f"got {len(values)} values")
    return tuple(values[:4]) + _five(values[4:], f"{where}: {STD_KEY}")


def _size(fs, key: str, where: str) -> int:
    node = fs.getNode(key)
    if node.empty() or not (node.isInt() or node.isReal()) or node.real() != int(node.real()) or node.real() < 1:
        raise CalibrationError(f"{where}: {key}: expected an integer number of pixels >= 1")
    return int(node.real())


def _read_filestorage(path: Path, text: str) -> Calibration:
    """OpenCV YAML / JSON or ROS camera_info YAML (module docstring)."""
    where = str(path)
    if path.suffix.lower() in (".yaml", ".yml") and not text.lstrip().startswith("%YAML"):
        text = "%YAML:1.0\n---\n" + text          # ROS writes plain YAML; OpenCV's reader wants the directive
    try:
        fs = cv2.FileStorage(text, cv2.FILE_STORAGE_READ | cv2.FILE_STORAGE_MEMORY)
    except (cv2.error, SystemError):
        raise CalibrationError(f"{where}: not an OpenCV or ROS calibration file (unparsable YAML / JSON)") from None
    try:
        model = fs.getNode("distortion_model")
        if not model.empty() and model.string() not in ("plumb_bob", "rational_polynomial", ""):
            raise CalibrationError(f"{where}: distortion_model: {model.string()!r} is not plumb_bob (Brown-Conrady)")
        k = _numbers(fs, "camera_matrix", where)
        if len(k) != 9 or k[1] != 0.0 or k[3] != 0.0 or k[6:] != [0.0, 0.0, 1.0]:
            raise CalibrationError(f"{where}: camera_matrix: expected [[fx, 0, cx], [0, fy, cy], [0, 0, 1]], got {k}")
        dist = _five(_numbers(fs, "distortion_coefficients", where), where)
        cal = Calibration(_size(fs, "image_width", where), _size(fs, "image_height", where), k[0], k[4], k[2], k[5], dist,
                          _stds(fs, where))
    finally:
        fs.release()
    return _checked(cal, where)


def _read_colmap(path: Path, text: str) -> Calibration:
    """The first camera of a COLMAP ``cameras.txt`` (module docstring)."""
    lines = [(i, ln.split()) for i, ln in enumerate(text.splitlines(), 1) if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        raise CalibrationError(f"{path}: no camera line (CAMERA_ID MODEL WIDTH HEIGHT PARAMS...)")
    i, parts = lines[0]
    where = f"{path}:{i}"
    if len(parts) < 4 or parts[1] not in COLMAP_PARAMS:
        raise CalibrationError(f"{where}: expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS with MODEL one of "
                               f"{', '.join(COLMAP_PARAMS)}, got {' '.join(parts[:2])!r}")
    names = COLMAP_PARAMS[parts[1]]
    try:
        w, h = int(parts[2]), int(parts[3])
        values = [float(v) for v in parts[4:]]
    except ValueError:
        raise CalibrationError(f"{where}: width, height and parameters must be numbers") from None
    if len(values) != len(names):
        raise CalibrationError(f"{where}: {parts[1]} has {len(names)} parameters ({', '.join(names)}), got {len(values)}")
    p = dict(zip(names, values))
    if any(p.get(k, 0.0) != 0.0 for k in ("k4", "k5", "k6")):
        raise CalibrationError(f"{where}: FULL_OPENCV's k4-k6 (the rational terms) are not supported")
    fx, fy = p.get("fx", p.get("f")), p.get("fy", p.get("f"))
    dist = tuple(p.get(k, 0.0) for k in ("k1", "k2", "p1", "p2", "k3"))
    return _checked(Calibration(w, h, fx, fy, p["cx"] - COLMAP_CENTRE, p["cy"] - COLMAP_CENTRE, dist), where)


def read_calibration(path) -> Calibration:
    """The camera of calibration file ``path``: COLMAP for ``.txt``, OpenCV or ROS for ``.yaml``,
    ``.yml`` and ``.json``. One-line CalibrationError on any problem."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".txt", ".yaml", ".yml", ".json"):
        raise CalibrationError(f"{path}: expected a .yaml / .yml / .json (OpenCV, ROS camera_info) or .txt "
                               "(COLMAP cameras.txt) calibration file")
    text = _text(path)
    return _read_colmap(path, text) if suffix == ".txt" else _read_filestorage(path, text)


def _ros_matrix(name: str, rows: int, cols: int, data) -> str:
    """A camera_info matrix entry: ``name: {rows, cols, data}`` (block style, as ROS writes it)."""
    return f"{name}:\n  rows: {rows}\n  cols: {cols}\n  data: [" + ", ".join(repr(float(v)) for v in data) + "]\n"


def calibration_text(cal: Calibration, fmt: str) -> str:
    """``cal`` written in ``fmt`` (one of FORMATS)."""
    if fmt in ("opencv-yaml", "opencv-json"):
        flags = cv2.FILE_STORAGE_WRITE | cv2.FILE_STORAGE_MEMORY
        fs = cv2.FileStorage(".json" if fmt == "opencv-json" else ".yaml",
                             flags | (cv2.FILE_STORAGE_FORMAT_JSON if fmt == "opencv-json" else 0))
        fs.write("image_width", int(cal.width))
        fs.write("image_height", int(cal.height))
        fs.write("camera_matrix", cal.K)
        fs.write("distortion_coefficients", np.array([cal.dist], dtype=np.float64))
        if cal.std is not None:
            fs.write(STD_KEY, np.array([cal.std], dtype=np.float64))
        return fs.releaseAndGetString()
    if fmt == "ros":
        p = [cal.fx, 0, cal.cx, 0, 0, cal.fy, cal.cy, 0, 0, 0, 1, 0]
        return (f"image_width: {cal.width}\nimage_height: {cal.height}\ncamera_name: dockfactory\n"
                + _ros_matrix("camera_matrix", 3, 3, cal.K.ravel()) + "distortion_model: plumb_bob\n"
                + _ros_matrix("distortion_coefficients", 1, 5, cal.dist)
                + _ros_matrix("rectification_matrix", 3, 3, np.eye(3).ravel()) + _ros_matrix("projection_matrix", 3, 4, p))
    if fmt == "colmap":
        return ("# Camera list with one line of data per camera:\n#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n"
                + colmap_line(cal, 1))
    raise CalibrationError(f"format: expected one of {', '.join(FORMATS)}, got {fmt!r}")


def colmap_line(cal: Calibration, camera_id: int) -> str:
    """One ``cameras.txt`` line of ``cal`` (OPENCV, or FULL_OPENCV with k3; COLMAP's principal
    point is OpenCV's + 0.5 px), newline-terminated."""
    model = "FULL_OPENCV" if cal.dist[4] != 0.0 else "OPENCV"
    params = [cal.fx, cal.fy, cal.cx + COLMAP_CENTRE, cal.cy + COLMAP_CENTRE, *cal.dist[:4]] \
        + ([cal.dist[4], 0.0, 0.0, 0.0] if model == "FULL_OPENCV" else [])
    return f"{camera_id} {model} {cal.width} {cal.height} " + " ".join(repr(float(v)) for v in params) + "\n"


def write_calibration(cal: Calibration, path, fmt: str) -> None:
    """Write ``cal`` to ``path`` in ``fmt`` (atomically)."""
    write_text_atomic(path, calibration_text(cal, fmt))


def ideal_pixels(cal: Calibration, uv) -> tuple[np.ndarray, float]:
    """(uv', f): image points ``uv`` (n, 2) px of the calibrated camera ``cal`` as the ideal
    pinhole camera with square pixels of focal ``f`` = sqrt(fx fy) px and principal point (cx, cy)
    sees them: the lens's distortion taken out (cv2.undistortPoints) and fx / fy made one. What a
    pinhole solver with that principal point takes for the calibrated camera's image."""
    f = math.sqrt(cal.fx * cal.fy)
    uv = np.asarray(uv, dtype=np.float64).reshape(-1, 1, 2)
    if uv.shape[0] == 0:
        return uv.reshape(0, 2), f
    p = np.array([[f, 0.0, cal.cx], [0.0, f, cal.cy], [0.0, 0.0, 1.0]])
    out = cv2.undistortPoints(uv, cal.K, np.array(cal.dist, dtype=np.float64), P=p)
    return out.reshape(-1, 2), f
