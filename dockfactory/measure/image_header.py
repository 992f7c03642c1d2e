"""What a path given as an image is, and an image's size read from its file header, before any
decoding (a 1 MB PNG can claim 20000 x 20000 px: decoding it first costs 12 GB).

``path_kind(path)``: None for a regular file (symlinks followed), else what the path is instead
("a folder", "a named pipe (FIFO)", ...): a FIFO is never opened (opening one blocks).
``image_size(path)``: (format, width, height) from the header of a PNG, JPEG, TIFF or BMP file;
:class:`ImageHeaderError` (a DockfactoryError) says why not for anything else. At most
``MAX_HEADER_BYTES`` of the file are read (and a TIFF's directory). ``check_size(path,
max_pixels)`` adds the limit (:class:`ImageTooLarge`).
"""
from __future__ import annotations

import os
import stat
import struct

from dockfactory.core.errors import DockfactoryError

MAX_HEADER_BYTES = 1 << 20   # a JPEG's frame header may follow up to 1 MB of EXIF / ICC segments
FORMATS = "PNG, JPEG, TIFF or BMP"
_KINDS = ((stat.S_ISDIR, "a folder"), (stat.S_ISFIFO, "a named pipe (FIFO)"), (stat.S_ISSOCK, "a socket"),
          (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"))
# JPEG start-of-frame markers (baseline, extended, progressive, lossless; not DHT/JPG/DAC)
_SOF = {0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF}


class ImageHeaderError(DockfactoryError):
    """The file is not an image whose size its header states (the message says what it is): bad
    input, so the CLI reports it in one line with exit status 2; still a ValueError."""


class ImageTooLarge(ImageHeaderError):
    """The header states more pixels than the limit."""


def path_kind(path) -> str | None:
    """None when ``path`` is a regular file (after symlinks), else a phrase naming what it is."""
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        return "a broken symbolic link" if os.path.islink(path) else "no such file"
    except OSError as exc:
        return f"not accessible ({exc.strerror})"
    if stat.S_ISREG(mode):
        return None
    return next((name for test, name in _KINDS if test(mode)), "not a regular file")


def image_size(path) -> tuple[str, int, int]:
    """(format, width, height) in pixels from the header of the regular file ``path``."""
    with open(path, "rb") as fh:
        head = fh.read(MAX_HEADER_BYTES)

        def read_at(offset: int, n: int) -> bytes:   # a TIFF's directory may be anywhere in the file
            if offset + n <= len(head):
                return head[offset:offset + n]
            fh.seek(offset)
            return fh.read(n)
        return header_size(head, read_at)


def header_size(head: bytes, read_at=None) -> tuple[str, int, int]:
    """(format, width, height) from ``head``, the first bytes of a file (or all of them);
    ``read_at(offset, n)`` reads elsewhere in the file (default: within ``head``)."""
    read_at = read_at or (lambda offset, n: head[offset:offset + n])
    if head.startswith(b"\x89PNG\r\n\x1a\n"):
        return _png(head)
    if head.startswith(b"\xff\xd8"):
        return _jpeg(head[:MAX_HEADER_BYTES])
    if head[:4] in (b"II*\x00", b"MM\x00*"):
        return _tiff(head, read_at)
    if head.startswith(b"BM"):
        return _bmp(head)
    if head[:4] in (b"II+\x00", b"MM\x00+"):
        raise ImageHeaderError("a BigTIFF file: not supported (save it as a PNG, JPEG, TIFF or BMP)")
    raise ImageHeaderError(f"not a {FORMATS} file (its first bytes are {head[:8]!r})")


def _png(head: bytes) -> tuple[str, int, int]:
    if len(head) < 24 or head[12:16] != b"IHDR":
        raise ImageHeaderError("a PNG file without its header (IHDR): truncated or damaged")
    w, h = struct.unpack(">II", head[16:24])
    return "PNG", w, h


def _jpeg(head: bytes) -> tuple[str, int, int]:
    """The size in the first start-of-frame segment, walking the segments from the start."""
    i = 2
    while i + 4 <= len(head):
        if head[i] != 0xFF:
            raise ImageHeaderError(f"a JPEG file with a damaged segment at byte {i}")
        marker = head[i + 1]
        if marker == 0xFF:          # fill byte
            i += 1
            continue
        if marker in (0x01, *range(0xD0, 0xD8)):   # stand-alone markers
            i += 2
            continue
        if marker in (0xD9, 0xDA):
            break
        (length,) = struct.unpack(">H", head[i + 2:i + 4])
        if marker in _SOF and i + 9 <= len(head):
            h, w = struct.unpack(">HH", head[i + 5:i + 9])
            if h == 0:
                raise ImageHeaderError("a JPEG file whose height is given after the image data (DNL): not supported")
            return "JPEG", w, h
        i += 2 + length
    raise ImageHeaderError(f"a JPEG file without a frame header in its first {MAX_HEADER_BYTES} bytes: "
                           "truncated or damaged")


def _tiff(head: bytes, read_at) -> tuple[str, int, int]:
    """ImageWidth (256) and ImageLength (257) of the first image file directory."""
    end = "<" if head[:2] == b"II" else ">"
    try:
        (ifd,) = struct.unpack(end + "I", head[4:8])
        (n,) = struct.unpack(end + "H", read_at(ifd, 2))
        entries = read_at(ifd + 2, 12 * n)
        size = {}
        for k in range(n):
            tag, typ, _count = struct.unpack(end + "HHI", entries[12 * k:12 * k + 8])
            if tag in (256, 257):   # the value field: a SHORT sits in its first two bytes
                fmt, n_bytes = ("H", 2) if typ == 3 else ("I", 4)
                size[tag] = struct.unpack(end + fmt, entries[12 * k + 8:12 * k + 8 + n_bytes])[0]
    except struct.error:
        raise ImageHeaderError("a TIFF file with a truncated or damaged directory") from None
    if 256 not in size or 257 not in size:
        raise ImageHeaderError("a TIFF file whose directory does not state its size")
    return "TIFF", size[256], size[257]


def _bmp(head: bytes) -> tuple[str, int, int]:
    try:
        (dib,) = struct.unpack("<I", head[14:18])
        if dib == 12:   # OS/2 BITMAPCOREHEADER: unsigned 16-bit sizes
            w, h = struct.unpack("<HH", head[18:22])
        else:           # BITMAPINFOHEADER and later: signed, a negative height is top-down
            w, h = struct.unpack("<ii", head[18:26])
    except struct.error:
        raise ImageHeaderError("a BMP file with a truncated header") from None
    return "BMP", abs(w), abs(h)


def check_size(path, max_pixels: int, data: bytes | None = None) -> tuple[str, int, int]:
    """(format, width, height) of the image at ``path`` (or of its bytes ``data``) when it has at
    least one pixel and at most ``max_pixels``; ImageHeaderError otherwise (nothing is decoded)."""
    fmt, w, h = image_size(path) if data is None else header_size(data)
    if w < 1 or h < 1:
        raise ImageHeaderError(f"a {fmt} file whose header says {w}x{h} px: no pixels")
    if w * h > max_pixels:
        raise ImageTooLarge(f"a {fmt} image of {w}x{h} px ({w * h / 1e6:.1f} megapixels) is over the limit of "
                               f"{max_pixels / 1e6:g} megapixels (--max-megapixels)")
    return fmt, w, h
