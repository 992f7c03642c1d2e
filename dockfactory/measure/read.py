"""measure's image reading: what the user knows of the camera (:class:`CameraInput`), the checks
made before an image is decoded (what the path is, the size its header states against a limit)
and the decoding itself, whose library messages (libpng's "Read Error", OpenCV's warnings) are
captured and reported with the image instead of leaking to the terminal.

Every failure is a record ``{"ok": False, "reason": "<path>: <why>", "category": ...}``, never an
exception: categories "unreadable image" (missing, not a regular file, not a PNG/JPEG/TIFF/BMP,
truncated or damaged) and "image too large" (over ``max_pixels`` by its header).
"""
from __future__ import annotations

import contextlib
import os
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

from dockfactory.core.cv import cv2
import numpy as np

from dockfactory.core.calibration_files import Calibration
from dockfactory.core.camera_chain import develop_raw
from dockfactory.core.camera_chain.cfa import PATTERNS
from dockfactory.core.camera_chain.demosaic import DEMOSAICS
from dockfactory.core.errors import DockfactoryError
from dockfactory.measure.image_header import ImageHeaderError, ImageTooLarge, check_size, path_kind
from dockfactory.solver.options import LensPrior

DEFAULT_MAX_MEGAPIXELS = 50.0   # e.g. 8160 x 6120: decoding one costs about 0.15 GB per copy of it
MAX_MEGAPIXELS = 250.0          # the highest limit --max-megapixels accepts


@dataclass(frozen=True)
class CameraInput:
    """What the user knows of the camera behind the images. ``cfa``: its Bayer pattern (RGGB,
    BGGR, GRBG, GBRG; None: a three-chip camera or unknown): the centre refinement then fits the
    samples the sensor took, and raw frames can be read. A raw frame is a one-channel 16-bit PNG
    of the mosaic in DN (BayerRG12 and the like): ``raw_black_dn`` is subtracted, ``raw_white_dn`` is
    full scale (the sensor's white level: a 16-bit PNG does not say its ADC depth, and a level
    guessed from each frame's brightest pixel would develop a dark frame brighter; None: raw
    frames are refused), then grey-world white balance, ``demosaic`` and the sRGB curve.
    ``lens``: what is plausible for the intrinsics the camera model does not estimate
    (solver.options.LensPrior), marginalised into every pose's uncertainty; None: an uncalibrated
    camera's generic ranges (eval.solve_frames.UNCALIBRATED_LENS). ``calibration``: the camera's
    calibration (core.calibration_files.Calibration: ``measure --calibration FILE``): its
    principal point and distortion are then known (the detected centres are taken to the ideal
    pinhole camera before the solve, nothing marginalised); the focal is still solved and
    reported beside the calibrated one."""
    cfa: str | None = None
    raw_black_dn: float = 0.0
    raw_white_dn: float | None = None
    demosaic: str = "mhc"
    lens: LensPrior | None = None
    calibration: Calibration | None = None

    def __post_init__(self):
        if self.cfa is not None and self.cfa not in PATTERNS:
            raise DockfactoryError(f"--cfa: expected one of {', '.join(PATTERNS)}, got {self.cfa!r}")
        if self.demosaic not in DEMOSAICS:
            raise DockfactoryError(f"--demosaic: expected one of {', '.join(DEMOSAICS)}, got {self.demosaic!r}")
        if not (np.isfinite(self.raw_black_dn) and 0 <= self.raw_black_dn < 65535):
            raise DockfactoryError(f"--raw-black: expected a level in [0, 65535) DN, got {self.raw_black_dn}")
        if self.raw_white_dn is not None and not (np.isfinite(self.raw_white_dn)
                                                  and self.raw_black_dn < self.raw_white_dn <= 65535):
            raise DockfactoryError(f"--raw-white: expected a level above --raw-black and at most 65535 DN, "
                                   f"got {self.raw_white_dn}")

    def develop(self, raw: np.ndarray) -> np.ndarray:
        """A raw frame (H, W) uint16 as 8-bit sRGB (core.camera_chain.develop_raw)."""
        return develop_raw(raw, self.cfa, self.raw_black_dn, self.raw_white_dn, self.demosaic)


def max_pixels_of(megapixels: float) -> int:
    return int(megapixels * 1e6)


def unreadable(path: Path, why: str, category: str = "unreadable image") -> dict:
    """The failure record of an image that could not be read."""
    return {"ok": False, "reason": f"{path}: {why}", "category": category}


def probe_image(path: Path, max_pixels: int) -> tuple[tuple[str, int, int] | None, dict | None]:
    """((format, width, height), None) of an image that may be decoded, or (None, failure record): not a
    regular file (a FIFO is named as such and never opened), not a PNG/JPEG/TIFF/BMP, or larger
    than ``max_pixels`` by its header. Reads at most the file's first megabyte."""
    kind = path_kind(path)
    if kind is not None:
        return None, unreadable(path, "no such image file" if kind == "no such file" else f"{kind}, not an image file")
    try:
        return check_size(path, max_pixels), None
    except ImageHeaderError as exc:
        category = "image too large" if isinstance(exc, ImageTooLarge) else "unreadable image"
        return None, unreadable(path, str(exc), category)
    except OSError as exc:
        return None, unreadable(path, f"cannot be read ({exc.strerror})")


@contextlib.contextmanager
def captured_stderr(lines: list):
    """Collect what native code (libpng, OpenCV's log) writes to file descriptor 2 during the
    block into ``lines`` instead of the terminal. Not for threads that print meanwhile."""
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile() as sink:
        os.dup2(sink.fileno(), 2)
        try:
            yield lines
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            sink.seek(0)
            text = sink.read(4096).decode("utf-8", "replace")
            lines.extend(ln.strip() for ln in text.splitlines() if ln.strip())


def read_image(path: Path, camera: CameraInput = CameraInput(), max_pixels: int = max_pixels_of(DEFAULT_MAX_MEGAPIXELS),
               notes: list | None = None) -> tuple[np.ndarray | None, dict | None]:
    """(RGB image (H, W, 3) uint8, None) or (None, failure record). The path and header are
    checked first (:func:`probe_image`), then the file's bytes are read once (at most 8 bytes a
    pixel of the limit) and their own header checked again before they are decoded, so no image
    over ``max_pixels`` is ever decoded (and OpenCV never sees the path: a file name that is not
    UTF-8 crashed it). A one-channel 16-bit PNG is a raw frame, developed with ``camera`` (its
    Bayer pattern and white level are needed). Decoder messages go to ``notes`` (or into the
    failure's reason)."""
    data, failed = _read_bytes(path, max_pixels)
    if failed is not None:
        return None, failed
    messages: list = []
    image, failed = _decode(path, data, camera, messages)
    if failed is not None and messages:
        failed["reason"] += f" ({'; '.join(messages)[:300]})"
    elif notes is not None:
        notes.extend(messages)
    return image, failed


def _read_bytes(path: Path, max_pixels: int) -> tuple[bytes | None, dict | None]:
    """The file's bytes, checked (kind, size, header) before and after they are read."""
    header, failed = probe_image(path, max_pixels)
    if failed is not None:
        return None, failed
    limit = 8 * max_pixels + (1 << 20)   # 16-bit RGBA stored raw, and room for metadata
    try:
        with open(path, "rb") as fh:
            data = fh.read(limit + 1)
        if len(data) > limit:
            return None, unreadable(path, f"a file of more than {limit / 1e6:.0f} MB: more than any image within "
                                          "the limit needs (--max-megapixels)", "image too large")
        check_size(path, max_pixels, data)
    except ImageHeaderError as exc:   # the file changed since it was probed
        category = "image too large" if isinstance(exc, ImageTooLarge) else "unreadable image"
        return None, unreadable(path, str(exc), category)
    except OSError as exc:
        return None, unreadable(path, f"cannot be read ({exc.strerror})")
    return data, None


def _decode(path: Path, data: bytes, camera: CameraInput, messages: list) -> tuple[np.ndarray | None, dict | None]:
    """Decode ``data`` once (twice for a PNG that is neither raw nor 8-bit colour)."""
    buf = np.frombuffer(data, np.uint8)
    try:
        with captured_stderr(messages):
            if data.startswith(b"\x89PNG"):   # a raw frame is a one-channel 16-bit PNG; a PNG has no orientation tag
                img = cv2.imdecode(buf, cv2.IMREAD_UNCHANGED)
                if img is None:
                    return None, unreadable(path, "not a readable image (truncated or damaged)")
                if img.ndim == 2 and img.dtype == np.uint16:
                    return _raw(path, img, camera)
                if img.ndim == 3 and img.shape[2] == 3 and img.dtype == np.uint8:
                    return cv2.cvtColor(img, cv2.COLOR_BGR2RGB, dst=img), None
                del img
            bgr = cv2.imdecode(buf, cv2.IMREAD_COLOR)   # JPEG orientation, depth and channels as OpenCV does
            if bgr is None:
                return None, unreadable(path, "not a readable image (truncated or damaged)")
            return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB, dst=bgr), None
    except (cv2.error, MemoryError) as exc:
        last = (str(exc).strip().splitlines() or ["no message"])[-1][:200]
        return None, unreadable(path, f"cannot be decoded ({type(exc).__name__}: {last})")


def _raw(path: Path, data: np.ndarray, camera: CameraInput) -> tuple[np.ndarray | None, dict | None]:
    if camera.cfa is None:
        return None, unreadable(path, "a raw frame (one 16-bit channel): give its Bayer pattern with --cfa")
    if camera.raw_white_dn is None:
        return None, unreadable(path, "a raw frame: give the sensor's white level with --raw-white "
                                      "(e.g. 4095 for 12 bit)")
    if data.shape[0] % 2 or data.shape[1] % 2 or min(data.shape) < 4:
        return None, unreadable(path, f"a raw frame must have an even size of at least 4x4, "
                                      f"got {data.shape[1]}x{data.shape[0]}")
    try:
        return camera.develop(data), None
    except ValueError as exc:   # e.g. a colour channel without signal
        return None, unreadable(path, f"a raw frame that cannot be developed ({exc})")
