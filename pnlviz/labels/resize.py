"""Where a labelled point lands when its picture changes size: the two ways a picture can be made
smaller, and labels that follow the picture's content exactly.

Pixel ``(c, r)`` of an image is at ``x = c, y = r`` (its centre), and a normalised SoccerNet
annotation names pixel ``x (W - 1), y (H - 1)`` of the image it was made on. A picture of another
size ``W' x H'`` shows that point at

* ``"centre"`` (``cv2.resize`` and every other area or bilinear resize: pixel *edges* scale, so
  centres move by half a pixel): ``x' = (x + 0.5) W' / W - 0.5``;
* ``"index"`` (a frame rendered at ``W' x H'`` through the camera :meth:`Camera.scaled
  <pnlviz.geometry.camera.Camera.scaled>` to it, as ``pnlviz synth`` renders training frames at
  the network's input size: the projection scales): ``x' = x W' / W``.

Scaling the normalised coordinates by ``W' - 1`` instead (the annotation simply read at the new
size) is neither: it moves the labels by up to half a pixel of the smaller picture (towards its
middle for a resize, towards its top-left corner for a render: one pixel at 960x540; a model
trained on synthetic frames labelled that way detects the points of 960x540 frames 0.45 px above
where they are, docs/detector.md). The same holds for a homography made for one size and used on
a resized copy: :func:`resize_matrix` is the map to put in front of it.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from pnlviz.geometry.polylines import segment_in_image

__all__ = ["ALIGNMENTS", "clip_to_image", "resize_annotation", "resize_matrix"]

ALIGNMENTS = ("centre", "index")


def resize_matrix(source_size: tuple[float, float], size: tuple[float, float], align: str = "centre") -> np.ndarray:
    """The 3x3 pixel map from an image of ``source_size = (W, H)`` to a picture of it at ``size``
    (see the module docstring for ``align``)."""
    if align not in ALIGNMENTS:
        raise ValueError(f"align must be one of {ALIGNMENTS}, got {align!r}")
    sx, sy = size[0] / source_size[0], size[1] / source_size[1]
    ox, oy = (0.5 * sx - 0.5, 0.5 * sy - 0.5) if align == "centre" else (0.0, 0.0)
    return np.array([[sx, 0.0, ox], [0.0, sy, oy], [0.0, 0.0, 1.0]])


def clip_to_image(pts: np.ndarray, width: int, height: int) -> np.ndarray:
    """The parts of a pixel polyline inside ``[0, W-1] x [0, H-1]`` (segments clipped, in order)."""
    if len(pts) == 1:
        return pts[(pts[:, 0] >= 0) & (pts[:, 0] <= width - 1) & (pts[:, 1] >= 0) & (pts[:, 1] <= height - 1)]
    out: list[np.ndarray] = []
    for a, b in zip(pts[:-1], pts[1:]):
        inside = segment_in_image(a, b, width, height)
        if inside is not None:
            for p in (a + inside[0] * (b - a), a + inside[1] * (b - a)):
                if not out or np.hypot(*(out[-1] - p)) > 1e-6:
                    out.append(p)
    return np.array(out).reshape(-1, 2)


def resize_annotation(annotation: Mapping[str, np.ndarray], source_size: tuple[int, int], size: tuple[int, int],
                      align: str = "centre") -> dict[str, np.ndarray]:
    """A normalised annotation (``{class: (N, 2)}``) of an image of ``source_size`` as the
    normalised annotation of its picture at ``size`` (``x (W' - 1)`` is where the picture shows
    the point), clipped to that picture: a point on the border can land a fraction of a pixel
    outside it. The same dict when the sizes agree."""
    (w0, h0), (w, h) = source_size, size
    if (int(w0), int(h0)) == (int(w), int(h)):
        return dict(annotation)
    A = resize_matrix((w0, h0), (w, h), align)
    before, after = np.array([w0 - 1.0, h0 - 1.0]), np.array([w - 1.0, h - 1.0])
    out = {}
    for name, pts in annotation.items():
        px = np.asarray(pts, float).reshape(-1, 2) * before
        px = clip_to_image(px * np.diag(A)[:2] + A[:2, 2], w, h)
        if len(px):
            out[name] = px / after
    return out
