"""Where a camera sees the ground: its footprint on the pitch plane, as one polygon.

The image border is walked round (``samples`` pixels per side); each border pixel's ray meets the
ground (z = 0) somewhere in front of the camera, or, above the horizon, never. The footprint is
the polygon of those ground points, each taken no farther than ``reach`` metres from the point
under the camera; a ray above the horizon (or meeting the ground beyond ``reach``) stands for the
ground seen up to ``reach`` in its direction. Inside that distance the polygon is the set of
ground points whose projection lies in the image, to the sampling of the border (lens distortion
included: the rays are undistorted).
"""

from __future__ import annotations

import numpy as np

from pnlviz.errors import ArgumentError
from pnlviz.geometry.camera import Camera

#: how far (metres) a footprint reaches towards the horizon
FOOTPRINT_REACH_M = 1000.0


def image_border(width: float, height: float, samples: int = 64) -> np.ndarray:
    """(4 * samples, 2) pixels walking round the image's border once, clockwise from the top-left
    corner (corners included once)."""
    t = np.arange(samples) / samples
    w, h = float(width), float(height)
    return np.vstack([np.column_stack([t * w, np.zeros(samples)]),
                      np.column_stack([np.full(samples, w), t * h]),
                      np.column_stack([w - t * w, np.full(samples, h)]),
                      np.column_stack([np.zeros(samples), h - t * h])])


def ground_footprint(camera: Camera, samples: int = 64, reach: float = FOOTPRINT_REACH_M) -> np.ndarray:
    """The ground the camera sees, as a polygon (M, 2) in pitch metres (M <= 4 * ``samples``;
    (0, 2) when it sees no ground: every ray above the horizon). See the module's note."""
    border = image_border(camera.width, camera.height, samples)
    border = border[camera.lens_inverts(border)]
    if not len(border):
        return np.zeros((0, 2))
    d = camera.pixel_rays(border)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = -camera.C[2] / d[:, 2]  # the ray's length to z = 0
    foot = camera.C[:2]
    flat = np.linalg.norm(d[:, :2], axis=1)  # the ray's horizontal extent per unit length
    hits = np.isfinite(s) & (s > 0)
    if not hits.any():
        return np.zeros((0, 2))
    distance = np.where(hits, s * flat, np.inf)  # from the point under the camera, on the ground
    keep = flat > 1e-12  # a ray straight down is the point under the camera itself
    direction = np.zeros_like(d[:, :2])
    direction[keep] = d[keep, :2] / flat[keep, None]
    return foot + np.minimum(distance, reach)[:, None] * direction


__all__ = ["FOOTPRINT_REACH_M", "ground_footprint", "image_border"]


def boxes_on_pitch(camera: Camera, boxes: np.ndarray) -> np.ndarray:
    """Where boxes ``boxes`` (N, 4: left, top, width, height, in this camera's image pixels)
    stand on the pitch: (N, 3, 2), the ground points (metres) under the bottom-left,
    bottom-middle and bottom-right corners of each box, lens distortion undone (NaN where the
    pixel has no ground point, :meth:`Camera.image_to_pitch`). A player's position is the bottom
    middle."""
    b = np.asarray(boxes, float)
    if b.ndim != 2 or b.shape[1] != 4:
        raise ArgumentError(f"boxes: expected (N, 4) left, top, width, height, got an array of shape {b.shape}")
    bottom = b[:, 1] + b[:, 3]
    uv = np.stack([np.stack([b[:, 0], bottom], 1), np.stack([b[:, 0] + b[:, 2] / 2, bottom], 1),
                   np.stack([b[:, 0] + b[:, 2], bottom], 1)], 1)
    return camera.image_to_pitch(uv.reshape(-1, 2)).reshape(-1, 3, 2)
