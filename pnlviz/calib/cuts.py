"""Where a broadcast clip cuts from one shot to the next: a large image change between
consecutive frames (when the caller measured one, see :func:`pnlviz.calib.temporal.image_change`),
or per-frame cameras whose centres and views jump (a different camera position), confirmed by the
next frame.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from pnlviz.field.model import pitch_grid
from pnlviz.geometry.camera import Camera

from .shot import TemporalParams

__all__ = ["segment_shots"]

_GRID = pitch_grid(5.0)


def _view_change(a: Camera, b: Camera) -> float:
    """Median displacement (pixels of ``a``) of the pitch grid points both cameras see (inf when
    they see none in common)."""
    pa, _ = a.project(_GRID)
    pb, _ = b.scaled(a.width, a.height).project(_GRID)
    seen = a.in_image(pa) & np.all(np.isfinite(pb), 1)
    return float(np.median(np.linalg.norm(pa[seen] - pb[seen], axis=1))) if seen.any() else math.inf


def segment_shots(cameras: Sequence[Camera | None], changes: Sequence[float | None] | None = None,
                  params: TemporalParams = TemporalParams()) -> list[range]:
    """Cut a clip into shots: ``range`` objects covering ``0 .. len(cameras) - 1`` in order. A cut
    falls before frame t when ``changes[t - 1]`` (the image change from t - 1 to t) exceeds
    ``cut_image``, or when frame t's per-frame camera is apart from the current shot (its centre
    farther than ``cut_centre_m`` from the median of the shot's last five centres, and its view of
    the pitch moved by more than ``cut_view`` of the image width from the shot's latest camera)
    *and* so is the next calibrated frame (one wrong per-frame camera is an outlier, not a cut).
    Frames without a camera never cut."""
    T = len(cameras)
    if T == 0:
        return []
    calibrated = [t for t in range(T) if cameras[t] is not None]
    cuts: list[int] = []
    centres: list[np.ndarray] = []
    last: Camera | None = None  # the shot's latest camera that was not an outlier

    def apart(a: Camera, b: Camera, ref: np.ndarray) -> bool:
        return (float(np.linalg.norm(a.C - ref)) > params.cut_centre_m
                and _view_change(a, b) > params.cut_view * a.width)

    for t in range(T):
        if t > 0 and changes is not None and (change := changes[t - 1]) is not None and change > params.cut_image:
            cuts.append(t)
            centres = []
        cam = cameras[t]
        if cam is None:
            continue
        C = np.asarray(cam.C, float)
        if centres and last is not None:
            ref = np.median(np.array(centres[-5:]), axis=0)
            if apart(cam, last, ref):
                later = next((cameras[u] for u in calibrated if u > t), None)
                confirmed = later is not None and apart(later, last, ref)
                if not confirmed:
                    continue  # an outlier frame: it neither cuts nor moves the reference
                if not cuts or cuts[-1] != t:
                    cuts.append(t)
                centres = []
        centres.append(C)
        last = cam
    bounds = [0, *sorted(set(c for c in cuts if 0 < c < T)), T]
    return [range(a, b) for a, b in zip(bounds[:-1], bounds[1:]) if b > a]
