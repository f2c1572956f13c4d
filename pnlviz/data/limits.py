"""Resource caps on input files, checked before anything is read, decompressed or decoded.

A file over a cap is a one-line :class:`~pnlviz.data.errors.DataError` naming it and the limit.
"""

from __future__ import annotations

__all__ = ["MAX_DATASET_JSON_BYTES", "MAX_JSON_BYTES", "MAX_IMAGE_BYTES", "MAX_IMAGE_PIXELS", "MIN_IMAGE_SIDE",
           "format_bytes"]

#: Largest JSON file (camera, predictions, homographies, match info, an edit record with its
#: history) read, in bytes.
MAX_JSON_BYTES = 64 * 2**20
#: Largest JSON file of a dataset's frame (its annotation) read, in bytes: SoccerNet's are 2-20 KB;
#: a 31 MB one, parsed, took 2 GB in ``qa`` and 2.5 GB in ``serve``
MAX_DATASET_JSON_BYTES = 4 * 2**20
#: Largest encoded image file read, in bytes.
MAX_IMAGE_BYTES = 256 * 2**20
#: Largest image decoded, in pixels (an 8K UHD frame is 33 megapixels).
MAX_IMAGE_PIXELS = 50_000_000
#: Smallest image side, in pixels: the rule of a frame the calibration accepts
#: (:class:`pnlviz.calib.frame.FrameSettings`), so that ``validate`` refuses what calibrate would.
MIN_IMAGE_SIDE = 2


def format_bytes(n: int) -> str:
    """``67108864`` -> ``"64 MiB"``; ``2147483648`` -> ``"2.0 GiB"``."""
    if n >= 2**30:
        return f"{n / 2**30:.1f} GiB"
    if n >= 2**20:
        return f"{n / 2**20:.0f} MiB"
    return f"{n} bytes"
