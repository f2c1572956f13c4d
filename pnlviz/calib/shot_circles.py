"""The circle terms of a shot's problem (:mod:`pnlviz.calib.shot`), all frames at once.

Each observed point of a circle class is measured against the class projected by its frame's
camera as a dense polyline (the frame problem's term, :func:`pnlviz.calib.residuals.polyline_block`,
:meth:`pnlviz.calib.problem.Problem._circle`). A class has the same world samples on every frame,
so the frames that see it form one :class:`CircleGroup`: its samples projected through every
frame's rotation and focal length in one call, every point's closest segment found in one pass.
(One call per frame and class cost 0.1 ms each, and a shot of 250 frames with two circles
spent most of its solve there.) A frame whose arc runs behind its camera is measured on its own.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from pnlviz.geometry.camera import MIN_DEPTH
from pnlviz.geometry.projection import camera_to_pixels, to_camera

from .problem import BEHIND
from .residuals import Block, polyline_block

__all__ = ["CircleGroup", "circle_block", "circle_residuals", "group_circles"]


@dataclass
class CircleGroup:
    """The observed points of one circle class on the frames of a shot that see it: the class's
    world samples (S, 3); per item (a frame's view of it) its frame and weight; the points (M, 2)
    in item order with the item of each."""

    name: str
    world: np.ndarray
    frames: np.ndarray
    weights: np.ndarray
    pts: np.ndarray
    item: np.ndarray

    @property
    def row_frames(self) -> np.ndarray:
        """The frame of each point (each residual row)."""
        return self.frames[self.item]


def group_circles(items: Sequence[tuple[int, np.ndarray, np.ndarray, float, str]]) -> list[CircleGroup]:
    """``(frame, world samples, observed pixels, weight, class)`` per frame and class, grouped by
    class (in the order classes first appear; items in the order given)."""
    by_class: dict[str, list[tuple[int, np.ndarray, np.ndarray, float, str]]] = {}
    for it in items:
        by_class.setdefault(it[4], []).append(it)
    out = []
    for name, its in by_class.items():
        out.append(CircleGroup(name, its[0][1], np.array([t for t, *_ in its], int),
                               np.array([w for _, _, _, w, _ in its], float),
                               np.concatenate([p for _, _, p, _, _ in its]).reshape(-1, 2),
                               np.concatenate([np.full(len(p), i) for i, (_, _, p, _, _) in enumerate(its)]).astype(int)))
    return out


def circle_block(world: np.ndarray, pts: np.ndarray, R: np.ndarray, C: np.ndarray, f: float, k1: float,
                 cx: float, cy: float, jac: bool) -> Block:
    """One frame's view of a circle: its observed points against its projected arc."""
    Xc = to_camera(world, R, C)
    front = Xc[:, 2] > MIN_DEPTH
    if front.sum() < 2:
        return Block(np.full(len(pts), BEHIND), np.zeros((len(pts), 8)) if jac else None)
    Xc = Xc[front]
    poly, _ = camera_to_pixels(Xc, R, f, 1.0, cx, cy, k1)
    if not jac:
        return polyline_block(poly, pts)

    def vertex_jacobian(idx: np.ndarray) -> np.ndarray:
        J = camera_to_pixels(Xc[idx], R, f, 1.0, cx, cy, k1, True)[1]
        assert J is not None
        return J

    return polyline_block(poly, pts, vertex_jacobian)


def circle_residuals(g: CircleGroup, R: np.ndarray, C: np.ndarray, f: np.ndarray, k1: float, cx: float, cy: float,
                     jac: bool) -> Block:
    """The distance of each point of group ``g`` to its frame's projected arc (``R`` (T, 3, 3) and
    ``f`` (T,) of every frame of the shot), and with ``jac`` its derivative with respect to its
    frame's camera (M, 8)."""
    Rf, ff = R[g.frames], f[g.frames]
    n, S = len(g.frames), len(g.world)
    Xc = np.einsum("nij,sj->nsi", Rf, g.world - C)
    whole = np.all(Xc[..., 2] > MIN_DEPTH, axis=1)  # items whose arc is in front of the camera
    r = np.empty(len(g.pts))
    J = np.zeros((len(g.pts), 8)) if jac else None
    for i in np.flatnonzero(~whole):  # an arc running behind the camera: measured on its own
        rows = g.item == i
        b = circle_block(g.world, g.pts[rows], Rf[i], C, float(ff[i]), k1, cx, cy, jac)
        r[rows] = b.r
        if J is not None and b.J is not None:
            J[rows] = b.J
    rows = whole[g.item]
    if not rows.any():
        return Block(r, J)
    item, pts = g.item[rows], g.pts[rows]
    flat = Xc.reshape(-1, 3)
    uv, _ = camera_to_pixels(flat, np.repeat(Rf, S, 0), np.repeat(ff, S), 1.0, cx, cy, k1)
    poly = uv.reshape(n, S, 2)
    j, tj, off = _closest_segments(poly, item, pts)
    dist = np.hypot(off[:, 0], off[:, 1])
    r[rows] = dist
    if J is not None:
        ends = np.concatenate([item * S + j, item * S + j + 1])  # the closest segment's two vertices
        _, Jv = camera_to_pixels(flat[ends], np.repeat(Rf, S, 0)[ends], np.repeat(ff, S)[ends], 1.0, cx, cy, k1,
                                 True)
        assert Jv is not None
        Ja, Jb = Jv[:len(pts)], Jv[len(pts):]
        unit = off / np.maximum(dist, 1e-12)[:, None]  # d(distance)/d(closest point) = -unit
        Jc = (1 - tj)[:, None, None] * Ja + tj[:, None, None] * Jb
        J[rows] = -np.einsum("nk,nkj->nj", unit, Jc)
    return Block(r, J)


#: the coarse stride of the closest-segment search (samples)
_STRIDE = 8


def _distances(poly: np.ndarray, item: np.ndarray, pts: np.ndarray, start: np.ndarray, n: int):
    """Each point against the ``n`` segments from vertex ``start`` of its item's polyline:
    (t (m, n), offsets x and y (m, n) each, squared distances (m, n)). Written per coordinate:
    the solve of a long shot calls it for thousands of points at every step."""
    idx = (item[:, None], start[:, None] + np.arange(n + 1))
    vx, vy = poly[..., 0][idx], poly[..., 1][idx]  # (m, n + 1)
    ax, ay = vx[:, :-1], vy[:, :-1]
    bx, by = vx[:, 1:] - ax, vy[:, 1:] - ay
    px, py = pts[:, :1] - ax, pts[:, 1:] - ay
    t = np.clip((px * bx + py * by) / np.maximum(bx * bx + by * by, 1e-18), 0.0, 1.0)
    dx, dy = px - t * bx, py - t * by
    return t, dx, dy, dx * dx + dy * dy


def _closest_segments(poly: np.ndarray, item: np.ndarray, pts: np.ndarray):
    """The closest segment ``j`` of each point on its item's polyline (``poly`` (n, S, 2)), where
    on it (``t``) and the point minus that closest point. Coarse to fine (a shot has thousands of
    circle points, and M x S pairs were most of its solve): the two closest chords of every
    ``_STRIDE``-th vertex, then the ``3 _STRIDE`` segments around each (two, for the two sides of
    a thin far ellipse and the seam of a closed circle; the same segments as a full search on
    random views of the centre circle, points 1-30 px off it: tests/test_calib_unmarked.py)."""
    S, m = poly.shape[1], len(pts)
    rows = np.arange(m)
    if S <= 6 * _STRIDE:
        t, dx, dy, d2 = _distances(poly, item, pts, np.zeros(m, int), S - 1)
        k = np.argmin(d2, axis=1)
        return k, t[rows, k], np.column_stack([dx[rows, k], dy[rows, k]])
    every = np.r_[np.arange(0, S - 1, _STRIDE), S - 1]
    dc = _distances(poly[:, every], item, pts, np.zeros(m, int), len(every) - 1)[3]
    width = 3 * _STRIDE
    starts = np.clip(every[np.argsort(dc, axis=1)[:, :2]] - _STRIDE, 0, S - 1 - width)  # (m, 2)
    t, dx, dy, d2 = (np.concatenate(x, axis=1) for x in zip(*(_distances(poly, item, pts, starts[:, i], width)
                                                              for i in range(2))))
    k = np.argmin(d2, axis=1)
    return starts[rows, k // width] + k % width, t[rows, k], np.column_stack([dx[rows, k], dy[rows, k]])
