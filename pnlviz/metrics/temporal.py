"""Frame-to-frame stability of a clip's cameras.

**Jitter** of frame t (issue #14): the median, over the points of a 5 m grid on the pitch that
all three cameras of frames t - 1, t, t + 1 put inside the image, of ``|p(t+1) - 2 p(t) + p(t-1)|``
(pixels at the evaluation size, 960x540 by default): the acceleration of the projected pitch. A
broadcast camera moves smoothly, so most of it is estimation noise. Frames whose neighbours lack a
camera have no jitter.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from pnlviz.conventions import EVAL_SIZE
from pnlviz.field.model import pitch_grid
from pnlviz.geometry.camera import Camera

__all__ = ["jitter"]


def jitter(cameras: Sequence[Camera | None], size: tuple[int, int] = EVAL_SIZE, spacing: float = 5.0
           ) -> np.ndarray:
    """Per frame, the jitter in pixels at ``size`` (NaN where it is undefined: first and last frame,
    a missing camera in the triple, or no grid point seen by all three)."""
    W, H = size
    grid = pitch_grid(spacing)
    proj: list[tuple[np.ndarray, np.ndarray] | None] = []
    for cam in cameras:
        if cam is None:
            proj.append(None)
            continue
        cam = cam.scaled(W, H)
        uv = cam.project(grid)
        proj.append((uv, cam.in_image(uv)))  # NaN (behind the camera) is never inside
    out = np.full(len(cameras), np.nan)
    for t in range(1, len(cameras) - 1):
        a, b, c = proj[t - 1], proj[t], proj[t + 1]
        if a is None or b is None or c is None:
            continue
        m = a[1] & b[1] & c[1]
        if m.any():
            out[t] = float(np.median(np.linalg.norm(c[0][m] - 2 * b[0][m] + a[0][m], axis=1)))
    return out
