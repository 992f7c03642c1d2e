"""Is a stream's colour subsampled? What its source says, so that the centre refinement fits the
edge where the source kept it.

A lossy video codec (MPEG-4, H.264, HEVC, VP8/9, AV1) and a camera streaming MJPEG or YUV 4:2:2 /
4:2:0 keep the luma at full resolution and the colour at half: the markers' colour score, made
of colour, loses the disc's edge (on a 4:2:0 stream half of the edge fits were refused and the
centres were 3x worse; bench/results/centre_quality/README.md). Such a source is measured as a
JPEG is (``detector.centre_camera``, ``jpeg``: the edge fitted on the luma). A lossless codec
(FFV1, PNG, raw RGB) or a source that names no format keeps the colour: measured as it is.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from dockfactory.core.cv import cv2

# FourCC codes (upper case) of formats whose colour is sampled below the luma's resolution
SUBSAMPLED_FOURCC = frozenset({
    "MJPG", "JPEG", "YUYV", "YUY2", "UYVY", "YVYU", "NV12", "NV21", "I420", "IYUV", "YV12",
    "H264", "AVC1", "X264", "HEVC", "H265", "HVC1", "HEV1", "MP4V", "FMP4", "XVID", "DIVX", "DX50",
    "MPG1", "MPG2", "MPEG", "VP80", "VP90", "AV01", "WMV3", "THEO"})
JPEG_SUFFIXES = (".jpg", ".jpeg")


@dataclass(frozen=True)
class SourceChroma:
    """``subsampled``: the source's colour is at a lower resolution than its luma; ``fourcc``: the
    format code the source reported ("" for none), ``why``: one phrase for the stream's summary."""
    subsampled: bool
    fourcc: str
    why: str


def fourcc_text(code: float) -> str:
    """The four characters of a ``CAP_PROP_FOURCC`` value ("" for 0 or unprintable codes)."""
    raw = int(code).to_bytes(4, "little", signed=False) if 0 < int(code) < 2 ** 32 else b""
    text = raw.decode("ascii", "replace")
    return text if text.isprintable() else ""


def source_chroma(cap, video=None) -> SourceChroma:
    """What the opened ``cap`` (a ``cv2.VideoCapture``) of ``video`` (a path or image-sequence
    pattern; None for a camera) says of its colour resolution: an image sequence by its files'
    suffix (JPEG subsampled), any other source by its FourCC (:data:`SUBSAMPLED_FOURCC`)."""
    code = fourcc_text(cap.get(cv2.CAP_PROP_FOURCC))
    if video is not None and "%" in str(video):
        jpeg = Path(str(video)).suffix.lower() in JPEG_SUFFIXES
        return SourceChroma(jpeg, code, "JPEG image sequence" if jpeg else "image sequence")
    if code.strip().upper() in SUBSAMPLED_FOURCC:
        return SourceChroma(True, code, f"{code.strip()}: colour subsampled")
    return SourceChroma(False, code, f"{code.strip()}: full colour" if code.strip() else "no format reported")
