"""The clip timeline of the app (no GUI here): which frames form a clip, each frame's calibration
error, the error strip drawn under the frame slider, and the worst frames to jump to.

A dataset is a video when its stems name clips, by the one rule of
:func:`pnlviz.data.layout.video_clips` (a named clip of at least three frames that follow each
other). Plain numbered frames (``00001``), a dataset's splits and named picks of separate pictures
(``wc14_3``, ``wc14_8``, ``wc14_11``) are not clips.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from pnlviz.data.layout import video_clips

__all__ = ["STRIP_SCALE_PX", "clip_index", "frame_error", "strip_image", "worst_frames"]
#: the error (px) drawn fully red in the strip
STRIP_SCALE_PX = 10.0


def clip_index(stems: Sequence[str]) -> dict[str, list[int]]:
    """``{clip: [dataset indices in frame order]}`` of the dataset's clips
    (:func:`pnlviz.data.layout.video_clips`)."""
    pos = {s: i for i, s in enumerate(stems)}
    return {name: [pos[s] for s in members] for name, members in video_clips(stems).items()}


def frame_error(view) -> float:
    """A frame's calibration error for the strip: the median residual (px) of its keypoints and
    lines under its camera; ``inf`` when it has no camera, NaN when it is not calibrated yet
    (``view`` None)."""
    if view is None:
        return float("nan")
    result = view.result
    if result is None or not result.ok:
        return float("inf")
    r = list(result.point_residuals.values()) + list(result.line_residuals.values())
    return float(np.median(r)) if r else 0.0


def strip_image(errors: Sequence[float], current: int | None, width: int = 320, height: int = 26,
                scale: float = STRIP_SCALE_PX, cuts: Sequence[int] = (), keyframes: Sequence[int] = ()) -> np.ndarray:
    """An RGB strip, one band per frame in order: green (0 px) through yellow to red (``scale`` px
    and more), dark red for no camera, grey for not calibrated yet; the current frame framed in
    white; a cut (before frame t, a shot's first frame) a black line across the strip with a
    white tick above and below; a keyframe (corrected by hand) a cyan mark along the top."""
    e = np.asarray(errors, float).reshape(-1)
    n = max(len(e), 1)
    img = np.zeros((height, width, 3), np.uint8)
    edges = np.linspace(0, width, n + 1).round().astype(int)
    if len(e):
        # frame i spans columns edges[i] .. max(edges[i + 1], edges[i] + 1); where more frames than
        # columns share one, the last of them shows: a column's frame is the last one starting at
        # or before it
        share = np.clip(np.where(np.isfinite(e), e, 0.0) / scale, 0.0, 1.0)
        colours = np.stack([255 * np.minimum(1.0, 2 * share), 255 * np.minimum(1.0, 2 * (1 - share)),
                            np.full(len(e), 40.0)], axis=1).astype(np.uint8)  # truncated, as int() does
        colours[np.isinf(e)] = (120, 0, 0)
        colours[np.isnan(e)] = (90, 90, 90)
        owner = np.searchsorted(edges[:len(e)], np.arange(width), side="right") - 1
        img[3:height - 3] = colours[owner][None]
    for t in keyframes:
        if 0 <= t < n:
            a, b = edges[t], max(edges[t + 1], edges[t] + 1)
            img[3:8, a:b] = (0, 220, 255)
    for t in cuts:
        if 0 < t < n:
            x = min(width - 2, edges[t])
            img[:, max(0, x - 1):x + 1] = 0
            img[:3, max(0, x - 1):x + 1] = 255
            img[-3:, max(0, x - 1):x + 1] = 255
    if current is not None and 0 <= current < n:
        a, b = edges[current], max(edges[current + 1], edges[current] + 1)
        img[:, max(0, a - 1):min(width, b + 1)][[0, 1, 2, -3, -2, -1]] = 255
        img[:, max(0, a - 1)] = 255
        img[:, min(width - 1, b)] = 255
    return img


def worst_frames(errors: Sequence[float], k: int | None = None) -> list[int]:
    """Positions of the frames by decreasing error (no camera first; not calibrated yet left out)."""
    e = np.asarray(errors, float)
    known = [i for i in range(len(e)) if not np.isnan(e[i])]
    known.sort(key=lambda i: (-e[i], i))
    return known if k is None else known[:k]
