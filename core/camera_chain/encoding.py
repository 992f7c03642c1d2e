"""The encoding stage of the camera chain, last: what the camera unit's file format does to the
delivered 8-bit image (pure OpenCV).

In and out: ``(H, W, 3) uint8`` display RGB. A unit without JPEG delivers the image as it is (the
dataset stores it losslessly, PNG); a JPEG unit (``[camera_units] jpeg``) delivers the image its
JPEG of the frame's quality and the unit's chroma subsampling decodes to (OpenCV's libjpeg).
"""
from __future__ import annotations

from dockfactory.core.cv import cv2
import numpy as np

from dockfactory.core.scene import CameraModel

JPEG_SUBSAMPLING = ("420", "444")


def jpeg_round_trip(image: np.ndarray, quality: int, subsampling: str = "420") -> np.ndarray:
    """An image as a JPEG of it decodes.

    Parameters
    ----------
    image : (H, W, 3) uint8
        Display RGB.
    quality : int
        JPEG quality, 1-100.
    subsampling : str
        Chroma subsampling: "420" (half resolution in both directions, what most cameras and
        libjpeg's default write) or "444" (full resolution).

    Returns
    -------
    (H, W, 3) uint8
        The decoded JPEG, RGB (OpenCV's libjpeg).

    Raises
    ------
    ValueError
        ``subsampling`` not one of ``JPEG_SUBSAMPLING``.
    RuntimeError
        The encoder failed.
    """
    if subsampling not in JPEG_SUBSAMPLING:
        raise ValueError(f"JPEG subsampling must be one of {', '.join(JPEG_SUBSAMPLING)}, got {subsampling!r}")
    params = [cv2.IMWRITE_JPEG_QUALITY, int(quality)]
    if subsampling == "444":
        params += [cv2.IMWRITE_JPEG_SAMPLING_FACTOR, cv2.IMWRITE_JPEG_SAMPLING_FACTOR_444]
    ok, buf = cv2.imencode(".jpg", cv2.cvtColor(image, cv2.COLOR_RGB2BGR), params)
    if not ok:
        raise RuntimeError("JPEG encoding failed")
    return cv2.cvtColor(cv2.imdecode(buf, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)


def encode_frame(image: np.ndarray, cam: CameraModel) -> np.ndarray:
    """The stage: ``image`` (H, W, 3) uint8 display RGB as camera ``cam`` delivers it: its
    :func:`jpeg_round_trip` at the frame's ``jpeg_quality`` and the unit's ``jpeg_subsampling``,
    or ``image`` itself for a unit without JPEG (``jpeg_quality`` 0)."""
    if not cam.jpeg_quality:
        return image
    return jpeg_round_trip(image, cam.jpeg_quality, cam.jpeg_subsampling)
