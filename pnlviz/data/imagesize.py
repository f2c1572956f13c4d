"""Image size from the file header, without decoding: PNG (``IHDR``) and JPEG (``SOFn`` marker).

The format is recognised by its signature, not by the file name (PNG bytes under a ``.jpg``
name are read as PNG). Anything else, or a header that ends early or makes no sense, is a
``DataError("<file>", "corrupt image: ...")``. :func:`check_pixels` refuses images above
:data:`~pnlviz.data.limits.MAX_IMAGE_PIXELS` before they are decoded.
"""

from __future__ import annotations

import struct
from collections.abc import Callable

from .errors import DataError
from .limits import MAX_IMAGE_PIXELS, MIN_IMAGE_SIDE

__all__ = ["header_size", "check_pixels"]

Reader = Callable[[int], bytes]

_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
#: Start-of-frame markers (baseline, progressive, lossless, arithmetic...): all but DHT, JPG, DAC.
_SOF_MARKERS = frozenset(range(0xC0, 0xD0)) - {0xC4, 0xC8, 0xCC}
#: Markers without a length field: TEM, RST0-7, SOI.
_STANDALONE = frozenset({0x01, *range(0xD0, 0xD8), 0xD8})
_EOI, _SOS = 0xD9, 0xDA


def _corrupt(source: str, why: str) -> DataError:
    return DataError(source, f"corrupt image: {why}")


def _exact(read: Reader, n: int, source: str) -> bytes:
    data = read(n)
    if len(data) != n:
        raise _corrupt(source, "the header ends before the image size")
    return data


def _png_size(read: Reader, source: str) -> tuple[int, int]:
    length, kind, width, height = struct.unpack(">I4sII", _exact(read, 16, source))
    if kind != b"IHDR" or length != 13:
        raise _corrupt(source, "PNG without an IHDR header chunk")
    return width, height


def _jpeg_size(read: Reader, source: str) -> tuple[int, int]:
    while True:
        if _exact(read, 1, source) != b"\xff":
            raise _corrupt(source, "JPEG marker expected")
        marker = _exact(read, 1, source)[0]
        while marker == 0xFF:  # fill bytes
            marker = _exact(read, 1, source)[0]
        if marker in _STANDALONE:
            continue
        if marker in (_EOI, _SOS):
            raise _corrupt(source, "JPEG without a frame header (SOF) before its image data")
        (length,) = struct.unpack(">H", _exact(read, 2, source))
        if length < 2:
            raise _corrupt(source, f"JPEG segment length {length}")
        if marker in _SOF_MARKERS:
            _precision, height, width = struct.unpack(">BHH", _exact(read, 5, source))
            return width, height
        _exact(read, length - 2, source)  # skip the segment


def header_size(read: Reader, source: str) -> tuple[int, int]:
    """``(width, height)`` from the header of a PNG or JPEG file; ``read(n)`` reads its next bytes.

    Also checks the size against the pixel cap (:func:`check_pixels`).
    """
    head = read(2)
    if not head:
        raise _corrupt(source, "the file is empty")
    if head == b"\xff\xd8":
        width, height = _jpeg_size(read, source)
    elif head + read(6) == _PNG_SIGNATURE:
        width, height = _png_size(read, source)
    else:
        raise _corrupt(source, "neither a PNG nor a JPEG file")
    if width <= 0 or height <= 0:
        raise _corrupt(source, f"the header says {width}x{height} pixels")
    check_pixels(width, height, source)
    return width, height


def check_pixels(width: int, height: int, source: str, limit: int = MAX_IMAGE_PIXELS) -> None:
    """DataError when a ``width`` x ``height`` image is above ``limit`` pixels (not decoded), or
    has a side below :data:`~pnlviz.data.limits.MIN_IMAGE_SIDE`."""
    if width < MIN_IMAGE_SIDE or height < MIN_IMAGE_SIDE:
        raise DataError(source, f"image too small: {width}x{height} pixels (a frame needs at least "
                                f"{MIN_IMAGE_SIDE}x{MIN_IMAGE_SIDE})")
    if width * height > limit:
        raise DataError(source, f"image too large: {width}x{height} pixels ({width * height / 1e6:.0f} megapixels; "
                                f"the limit is {limit / 1e6:.0f} megapixels)")
