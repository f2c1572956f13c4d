"""Distances of image points to polylines (the projected pitch markings)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from pnlviz.errors import ArgumentError
from pnlviz.geometry.shapes import as_points


class Closest(NamedTuple):
    """Where each of M points is closest to a polyline of S vertices."""

    distance: np.ndarray  #: (M,) Euclidean distance
    segment: np.ndarray  #: (M,) index j of the segment (vertices j, j + 1)
    t: np.ndarray  #: (M,) position along that segment, 0 at vertex j, 1 at vertex j + 1
    offset: np.ndarray  #: (M, 2) the point minus its closest point on the polyline


def closest_on_polyline(pts: np.ndarray, poly: np.ndarray) -> Closest:
    """For each point (M, 2), its closest point on the polyline (S, 2), S >= 2; vectorised over
    M x S segments.

    >>> c = closest_on_polyline(np.array([[1.0, 2.0]]), np.array([[0.0, 0.0], [4.0, 0.0]]))
    >>> float(c.distance[0]), int(c.segment[0]), float(c.t[0])
    (2.0, 0, 0.25)
    """
    pts, poly = as_points(pts, 2, "pts"), as_points(poly, 2, "poly", "a polyline")
    if len(poly) < 2:
        raise ArgumentError(f"poly: expected a polyline of 2 vertices or more, got {len(poly)}")
    return closest(pts, poly)


def closest(pts: np.ndarray, poly: np.ndarray) -> Closest:
    """:func:`closest_on_polyline` without the checks (for the refinements' inner loop)."""
    a, b = poly[:-1], poly[1:]
    ab = b - a
    L2 = np.maximum(np.sum(ab * ab, axis=1), 1e-18)
    ap = pts[:, None, :] - a[None]
    t = np.minimum(np.maximum(np.einsum("msk,sk->ms", ap, ab) / L2, 0.0), 1.0)  # np.clip: slower on small arrays
    d = ap - t[..., None] * ab[None]
    d2 = np.einsum("msk,msk->ms", d, d)
    j = np.argmin(d2, axis=1)
    m = np.arange(len(pts))
    return Closest(np.sqrt(d2[m, j]), j, t[m, j], d[m, j])
