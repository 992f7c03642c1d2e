"""What a stream's source says of its colour resolution (dockfactory.measure.chroma): a lossy
codec or a subsampled camera format is measured as a JPEG is (the edge fitted on the luma)."""
import cv2
import numpy as np
import pytest

from dockfactory.measure.chroma import SUBSAMPLED_FOURCC, fourcc_text, source_chroma


class FakeCapture:
    """A capture that reports ``code`` as its FourCC."""

    def __init__(self, code: str):
        self.code = code

    def get(self, prop):
        assert prop == cv2.CAP_PROP_FOURCC
        return float(cv2.VideoWriter_fourcc(*self.code)) if self.code else 0.0


@pytest.mark.parametrize("code, subsampled", [("mp4v", True), ("FMP4", True), ("avc1", True), ("H264", True),
                                             ("MJPG", True), ("YUYV", True), ("ffv1", False), ("MPNG", False),
                                             ("RGB3", False), ("", False)])
def test_a_source_is_subsampled_by_its_fourcc(code, subsampled):
    got = source_chroma(FakeCapture(code), video=None if code in ("MJPG", "YUYV", "RGB3") else "run.mp4")
    assert got.subsampled is subsampled and got.fourcc.strip() == code
    assert ("subsampled" in got.why) is subsampled


def test_an_image_sequence_goes_by_its_files_suffix():
    assert source_chroma(FakeCapture("MPNG"), "frames/%06d.png").subsampled is False
    assert source_chroma(FakeCapture("MJPG"), "frames/%06d.jpg").subsampled is True
    assert source_chroma(FakeCapture(""), "frames/%06d.JPEG").why == "JPEG image sequence"


def test_fourcc_text_is_printable_or_empty():
    assert fourcc_text(cv2.VideoWriter_fourcc(*"mp4v")) == "mp4v"
    assert fourcc_text(0) == "" and fourcc_text(-1.0) == "" and fourcc_text(2.0 ** 40) == ""
    assert fourcc_text(float(int.from_bytes(b"\x01\x02ab", "little"))) == ""
    assert all(code == code.upper() and len(code) == 4 for code in SUBSAMPLED_FOURCC)


def test_real_files_report_their_codec(tmp_path):
    """OpenCV's own writers: mp4v is subsampled, FFV1 (as `dataset export --format video_lossless`
    writes it) is not."""
    frame = np.zeros((64, 64, 3), np.uint8)
    for name, code, subsampled in (("a.mp4", "mp4v", True), ("a.mkv", "FFV1", False)):
        writer = cv2.VideoWriter(str(tmp_path / name), cv2.VideoWriter_fourcc(*code), 10.0, (64, 64))
        if not writer.isOpened():
            pytest.skip(f"this OpenCV cannot write {code}")
        writer.write(frame)
        writer.release()
        cap = cv2.VideoCapture(str(tmp_path / name))
        assert source_chroma(cap, tmp_path / name).subsampled is subsampled, name
        cap.release()
