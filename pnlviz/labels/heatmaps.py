"""Heatmap targets in PnLCalib's training layout (paper Sec. III-B).

* keypoints ``(58, H/2, W/2)`` float32: channel ``k - 1`` holds a Gaussian (sigma 2 px at the
  output resolution, the paper's "2-pixel Gaussian peak sigma") at keypoint id ``k`` = 1..57 when
  it is labelled and inside the image; channel 57 is the background, ``1 - max`` of the 57 others,
  so that every pixel is a distribution over the 58 channels;
* keypoint mask ``(58,)``: 0 for channels left out of the loss (paper, "Keypoints Mask"): when no
  homography was available, the Kp1 / Kp2 / Kp3 channels of points whose class is annotated (the
  point may be in view but could not be labelled), and the Kp2 pairs whose external Kp point is
  missing; 1 elsewhere;
* lines ``(24, H/2, W/2)`` float32: channel ``k - 1`` holds two Gaussians at the extremities of line
  id ``k`` = 1..23, channel 23 (the "boundary" channel) Gaussians along every annotated straight
  line (the Gaussian of the distance to its polyline: dense sampling taken to the limit);
* line mask ``(24,)``: ones (every line channel is supervised).

Image pixel ``(x, y)`` sits at ``(x, y) / downsample`` in the output grid (pixel indices), so the
argmax of a keypoint channel is ``round(x / 2), round(y / 2)``. Everything is vectorised: each
keypoint channel is an outer product of two 1-D Gaussians; the boundary channel is computed in a
window around each polyline segment.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from pnlviz.field.model import FieldModel

from .catalogue import NETWORK_KEYPOINT_IDS, get_catalogue
from .extremities import line_extremities
from .keypoints import keypoints_from_annotation
from .types import KeypointLabels, LabelParams, LineExtremities

__all__ = ["HeatmapTargets", "N_KEYPOINT_CHANNELS", "N_LINE_CHANNELS", "heatmap_targets", "keypoint_mask",
           "training_targets"]

N_KEYPOINT_CHANNELS = 58
N_LINE_CHANNELS = 24


@dataclass
class HeatmapTargets:
    keypoints: np.ndarray  # (58, h, w) float32
    keypoint_mask: np.ndarray  # (58,) float32
    lines: np.ndarray  # (24, h, w) float32
    line_mask: np.ndarray  # (24,) float32
    downsample: int = 2


def _gauss_1d(centres: np.ndarray, n: int, sigma: float) -> np.ndarray:
    grid = np.arange(n, dtype=np.float32)
    d = grid[None, :] - np.asarray(centres, np.float32)[:, None]
    return np.exp(-(d * d) / np.float32(2 * sigma * sigma))


def _gaussians(points: np.ndarray, h: int, w: int, sigma: float) -> np.ndarray:
    """(K, h, w) float32: one isotropic Gaussian per point (K, 2) in output pixels."""
    points = np.asarray(points, np.float32).reshape(-1, 2)
    gx = _gauss_1d(points[:, 0], w, sigma)
    gy = _gauss_1d(points[:, 1], h, sigma)
    return gy[:, :, None] * gx[:, None, :]


def _draw_polyline(canvas: np.ndarray, pts: np.ndarray, sigma: float, radius: float) -> None:
    """canvas = max(canvas, exp(-d^2 / 2 sigma^2)) with d the distance to the polyline ``pts``."""
    h, w = canvas.shape
    pts = np.asarray(pts, np.float64).reshape(-1, 2)
    if len(pts) == 1:
        pts = np.vstack([pts, pts])
    for a, b in zip(pts[:-1], pts[1:]):
        x0 = int(np.floor(max(min(a[0], b[0]) - radius, 0)))
        x1 = int(np.ceil(min(max(a[0], b[0]) + radius, w - 1)))
        y0 = int(np.floor(max(min(a[1], b[1]) - radius, 0)))
        y1 = int(np.ceil(min(max(a[1], b[1]) + radius, h - 1)))
        if x0 > x1 or y0 > y1:
            continue
        xs = np.arange(x0, x1 + 1, dtype=np.float64)[None, :]
        ys = np.arange(y0, y1 + 1, dtype=np.float64)[:, None]
        ab = b - a
        L2 = float(ab @ ab)
        if L2 > 0:
            t = np.clip(((xs - a[0]) * ab[0] + (ys - a[1]) * ab[1]) / L2, 0.0, 1.0)
        else:
            t = np.zeros((1, 1))
        dx = xs - (a[0] + t * ab[0])
        dy = ys - (a[1] + t * ab[1])
        g = np.exp(-(dx * dx + dy * dy) / (2 * sigma * sigma)).astype(np.float32)
        view = canvas[y0:y1 + 1, x0:x1 + 1]
        np.maximum(view, g, out=view)


def keypoint_mask(labels: KeypointLabels, *, model: FieldModel | None = None) -> np.ndarray:
    """The (58,) loss mask of the paper's "Keypoints Mask" (see the module docstring)."""
    cat = get_catalogue(model)
    mask = np.ones(N_KEYPOINT_CHANNELS, np.float32)
    annotated = labels.annotated_classes
    groups = {k: cat.model.keypoints[k].group for k in NETWORK_KEYPOINT_IDS}
    for kid in NETWORK_KEYPOINT_IDS:
        if kid in labels.keypoints:
            continue
        group = groups[kid]
        if labels.homography is None and group in ("Kp1", "Kp2", "Kp3"):
            if any(c in annotated for c in cat.belongs_to.get(kid, ())):
                mask[kid - 1] = 0.0
        if group == "Kp2":
            ext = int(cat.model.keypoints[kid].definition["from_keypoint"])
            ext_label = labels.keypoints.get(ext)
            if ext_label is None or ext_label.set != "Kp":
                mask[kid - 1] = 0.0
    return mask


def heatmap_targets(labels: KeypointLabels, extremities: Mapping[int, LineExtremities], width: int, height: int,
                    *, sigma: float = 2.0, downsample: int = 2, model: FieldModel | None = None,
                    boundary: bool = True) -> HeatmapTargets:
    """Keypoint and line heatmaps (output resolution ``height // downsample`` x ``width //
    downsample``) with their loss masks; see the module docstring for the layout. ``boundary=False``
    leaves the boundary channel empty (for callers that mask it out of the loss)."""
    h, w = int(height) // downsample, int(width) // downsample
    kp = np.zeros((N_KEYPOINT_CHANNELS, h, w), np.float32)
    ids = [k for k in NETWORK_KEYPOINT_IDS if k in labels.keypoints and labels.keypoints[k].visible]
    if ids:
        g = _gaussians(labels.xy(ids) / downsample, h, w, sigma)
        kp[np.array(ids) - 1] = g
        kp[N_KEYPOINT_CHANNELS - 1] = 1.0 - g.max(axis=0)  # the other channels are 0
    else:
        kp[N_KEYPOINT_CHANNELS - 1] = 1.0
    lines = np.zeros((N_LINE_CHANNELS, h, w), np.float32)
    ext = [e for lid, e in sorted(extremities.items()) if 1 <= lid <= N_LINE_CHANNELS - 1]
    if ext:
        ends = np.vstack([np.vstack([e.p1, e.p2]) for e in ext]) / downsample
        g = _gaussians(ends, h, w, sigma).reshape(len(ext), 2, h, w).max(axis=1)
        lines[np.array([e.line_id for e in ext]) - 1] = g
        for e in ext if boundary else ():
            _draw_polyline(lines[N_LINE_CHANNELS - 1], e.points / downsample, sigma, radius=4 * sigma)
    return HeatmapTargets(kp, keypoint_mask(labels, model=model), lines, np.ones(N_LINE_CHANNELS, np.float32),
                          downsample)


def training_targets(annotation: Mapping[str, np.ndarray], width: int, height: int, *,
                     params: LabelParams | None = None, sigma: float = 2.0, downsample: int = 2,
                     model: FieldModel | None = None):
    """Labels, extremities and heatmap targets of one frame for training, with the left-right
    disambiguation on (unless ``params`` says otherwise): ``(labels, extremities, targets)``."""
    params = params or LabelParams(lr_disambiguation=True)
    labels = keypoints_from_annotation(annotation, width, height, params, model=model)
    ext = line_extremities(annotation, width, height, mirror=labels.mirrored)
    return labels, ext, heatmap_targets(labels, ext, width, height, sigma=sigma, downsample=downsample, model=model)
