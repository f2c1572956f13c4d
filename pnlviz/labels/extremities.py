"""Line extremities per straight class (the targets of PnLCalib's line network, line ids 1-23)."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from pnlviz.field.names import CLASS_TO_LINE_ID, STRAIGHT_CLASSES

from .fitting import fit_line
from .keypoints import annotation_to_pixels
from .leftright import mirror_annotation
from .types import LineExtremities

__all__ = ["line_extremities"]


def line_extremities(annotation: Mapping[str, np.ndarray], width: int, height: int, *,
                     mirror: bool = False, pixels: bool = False) -> dict[int, LineExtremities]:
    """``{line id: LineExtremities}`` for every straight class with >= 2 distinct points: the two
    extreme annotated points along the class's fitted direction, in pixels (``annotation`` is
    normalised SoccerNet, or pixels with ``pixels=True``). ``mirror=True`` renames the classes by
    the evaluator's mirror table first (as the left-right disambiguation does)."""
    ann = annotation_to_pixels(annotation, None, None) if pixels else annotation_to_pixels(annotation, width, height)
    if mirror:
        ann = mirror_annotation(ann)
    out: dict[int, LineExtremities] = {}
    for name in STRAIGHT_CLASSES:
        pts = ann.get(name)
        if pts is None or len(pts) < 2:
            continue
        fit = fit_line(pts)
        if fit is None:
            continue
        _, centroid, direction = fit
        t = (pts - centroid) @ direction
        order = np.argsort(t, kind="stable")
        sorted_pts = pts[order]
        a, b = sorted_pts[0], sorted_pts[-1]
        axis = 0 if abs(direction[0]) >= abs(direction[1]) else 1
        if b[axis] < a[axis]:
            a, b = b, a
            sorted_pts = sorted_pts[::-1]
        lid = CLASS_TO_LINE_ID[name]
        out[lid] = LineExtremities(lid, name, a.copy(), b.copy(), sorted_pts.copy())
    return out
