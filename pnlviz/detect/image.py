"""Detection of one image for the Python API (``pnlviz.detect(image)``): checked input, the light
default model (or a given one), pixels out in the form :func:`pnlviz.calibrate` takes."""

from __future__ import annotations

import functools
from collections.abc import Callable
from pathlib import Path

import numpy as np

from pnlviz.data.errors import ArgumentError
from pnlviz.detect.default import DEFAULT_MODEL, torch_missing
from pnlviz.field.names import LINE_ID_TO_CLASS


def detect_image(image: np.ndarray, weights: str | Path | None = None, *, threshold: float = 0.1,
                 look: Callable | None = None) -> dict:
    """Keypoints and lines of one BGR image (H, W, 3) uint8 found by the light default model (or
    the light model in ``weights``): ``{"keypoints": {id: (x, y, score)}, "lines": {class name:
    [(x1, y1), (x2, y2)]}}`` in the image's pixels, those scoring ``threshold`` or more. ``look``:
    :func:`pnlviz.calib.looks.take_look`, which keeps the model's second reading where the first
    gives no camera (none: the first). Needs PyTorch (``pip install 'pnlviz[detect]'``): an
    ImportError that says so without it."""
    if (missing := torch_missing()) is not None:
        raise ImportError(missing)
    arr = np.asarray(image)
    if arr.ndim != 3 or arr.shape[2] != 3 or arr.dtype != np.uint8 or min(arr.shape[:2]) < 16:
        raise ArgumentError(f"image: expected a BGR uint8 image (H, W, 3) of 16 px or more, got "
                            f"{arr.dtype} {arr.shape}")
    if isinstance(threshold, bool) or not (isinstance(threshold, (int, float)) and 0 <= threshold <= 1):
        raise ArgumentError(f"threshold: expected a score in [0, 1], got {threshold!r}")
    path = DEFAULT_MODEL if weights is None else Path(weights).resolve()
    stamp = (path.stat().st_size, path.stat().st_mtime_ns) if path.is_file() else None
    det = _detector(None if weights is None else str(path), stamp)
    pred = det.detect([arr])[0]
    h, w = arr.shape[:2]
    if look is not None:
        pred = look(pred, (w, h), det.calibration)[0]
    kps = {int(k): (float(x), float(y), float(p)) for k, (x, y, p) in pred.keypoints_px(w, h).items() if p >= threshold}
    lines = {LINE_ID_TO_CLASS[int(k)]: [(float(x1), float(y1)), (float(x2), float(y2))]
             for k, (x1, y1, p1, x2, y2, p2) in pred.lines_px(w, h).items() if min(p1, p2) >= threshold}
    return {"keypoints": kps, "lines": lines}


@functools.lru_cache(maxsize=2)
def _detector(weights: str | None, stamp: tuple | None):
    """The detector of ``weights`` (None: the light default model), loaded once per process and
    again when the file changes (``stamp``: its size and modification time)."""
    from pnlviz.detect.run import Detector

    return Detector.from_weights(None, None, light=None if weights is None else Path(weights))
