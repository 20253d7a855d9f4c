"""The size an image file declares, read from its header before anything is decoded.

OpenCV decodes first and lets the caller look afterwards; a 20000 x 20000 RGB PNG of a few
hundred kilobytes is 1.2 GB once decoded. :func:`declared_size` reads only the header of the
formats :mod:`wavestack.pipeline.formats.images` accepts, so the reader can refuse an image
larger than the memory budget before OpenCV allocates it.

References
----------
.. [1] W3C, *Portable Network Graphics (PNG) Specification*, 2nd ed. (2003), 11.2.2 IHDR.
.. [2] ITU-T T.81 (JPEG), annex B.2.2, frame header (SOFn).
.. [3] Adobe, *TIFF Revision 6.0* (1992), section 2 (image file header, IFD) and tags 256-258, 277.
.. [4] Microsoft, BITMAPINFOHEADER structure (BMP).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

__all__ = ["DeclaredSize", "declared_size"]

_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
# PNG colour type -> channels OpenCV decodes (a palette becomes BGR)
_PNG_CHANNELS = {0: 1, 2: 3, 3: 3, 4: 2, 6: 4}
# JPEG start-of-frame markers (C0-CF except DHT C4, JPG C8, DAC CC)
_JPEG_SOF = frozenset(range(0xC0, 0xD0)) - {0xC4, 0xC8, 0xCC}
_TIFF_TYPES = {3: ("H", 2), 4: ("I", 4)}  # SHORT, LONG
_TIFF_TAGS = {256: "width", 257: "height", 258: "bits", 277: "samples"}
_TIFF_MAX_ENTRIES = 4096


@dataclass(frozen=True)
class DeclaredSize:
    """What an image header says the decoded frame will be.

    Attributes
    ----------
    width, height : int
        Pixels.
    channels : int
        Samples per pixel as OpenCV decodes them (at least 1).
    bytes_per_sample : int
        1, 2, 4 or 8.
    """

    width: int
    height: int
    channels: int
    bytes_per_sample: int

    @property
    def decoded_bytes(self) -> int:
        """Bytes of the decoded array."""
        return self.width * self.height * self.channels * self.bytes_per_sample


def declared_size(data: bytes) -> DeclaredSize | None:
    """The size a PNG, JPEG, TIFF or BMP header declares; None if the header is not understood.

    Parameters
    ----------
    data : bytes
        The file's first bytes (the whole file for a JPEG, whose frame header may come late).
    """
    try:
        if data.startswith(_PNG_SIGNATURE):
            return _png(data)
        if data.startswith(b"\xff\xd8"):
            return _jpeg(data)
        if data[:4] in (b"II*\x00", b"MM\x00*"):
            return _tiff(data)
        if data.startswith(b"BM"):
            return _bmp(data)
    except (struct.error, IndexError, ValueError):
        return None
    return None


def _png(data: bytes) -> DeclaredSize | None:
    if data[12:16] != b"IHDR":
        return None
    width, height, depth, colour = struct.unpack_from(">IIBB", data, 16)
    return DeclaredSize(width, height, _PNG_CHANNELS.get(colour, 4), 2 if depth == 16 else 1)


def _jpeg(data: bytes) -> DeclaredSize | None:
    offset = 2
    while offset + 4 <= len(data):
        if data[offset] != 0xFF:
            return None
        marker = data[offset + 1]
        if marker == 0xFF:  # fill byte
            offset += 1
            continue
        if marker in (0x01, *range(0xD0, 0xD8)):  # markers without a length
            offset += 2
            continue
        (length,) = struct.unpack_from(">H", data, offset + 2)
        if marker in _JPEG_SOF:
            precision, height, width, components = struct.unpack_from(">BHHB", data, offset + 4)
            return DeclaredSize(width, height, max(1, components), 2 if precision > 8 else 1)
        if length < 2:
            return None
        offset += 2 + length
    return None


def _tiff(data: bytes) -> DeclaredSize | None:
    order = "<" if data[:2] == b"II" else ">"
    (ifd,) = struct.unpack_from(order + "I", data, 4)
    (count,) = struct.unpack_from(order + "H", data, ifd)
    if count > _TIFF_MAX_ENTRIES:
        return None
    found: dict[str, int] = {}
    for index in range(count):
        tag, kind, count, _ = struct.unpack_from(order + "HHI4s", data, ifd + 2 + 12 * index)
        if tag in _TIFF_TAGS and kind in _TIFF_TYPES:
            code, width = _TIFF_TYPES[kind]
            where = ifd + 2 + 12 * index + 8
            if count * width > 4:  # the values do not fit in the entry: it holds their offset
                (where,) = struct.unpack_from(order + "I", data, where)
            (found[_TIFF_TAGS[tag]],) = struct.unpack_from(order + code, data, where)
    if "width" not in found or "height" not in found:
        return None
    bits = found.get("bits", 8)
    return DeclaredSize(found["width"], found["height"], max(1, found.get("samples", 1)),
                        8 if bits > 32 else 4 if bits > 16 else 2 if bits > 8 else 1)


def _bmp(data: bytes) -> DeclaredSize | None:
    width, height = struct.unpack_from("<ii", data, 18)
    (bits,) = struct.unpack_from("<H", data, 28)
    return DeclaredSize(abs(width), abs(height), 4 if bits == 32 else 3, 1)
