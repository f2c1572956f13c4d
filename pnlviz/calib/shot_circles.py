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


#: segments per block of the closest-segment search
_BLOCK = 4


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
    on it (``t``) and the point minus that closest point: what a search of every segment finds
    (the first of equally close ones), without measuring every segment (a shot has thousands of
    circle points, and M x S pairs were most of its solve).

    The segments are taken ``_BLOCK`` at a time, each block inside a disc around its vertices. A
    point is measured against the segments of the block whose disc is nearest, and then only
    against the blocks whose disc comes closer than that: a block farther away cannot hold a
    closer segment."""
    S, m = poly.shape[1], len(pts)
    n_seg = S - 1
    nb = -(-n_seg // _BLOCK)
    # padded with the last vertex to whole blocks (the padding's segments are never chosen)
    padded = np.concatenate([poly, np.repeat(poly[:, -1:], nb * _BLOCK + 1 - S, axis=1)], axis=1)
    # each block's disc: the centre of its vertices' bounding box, out to its farthest vertex
    # (elementwise over the blocks' k-th vertices: reductions over a few items cost more)
    verts = [padded[:, k::_BLOCK][:, :nb] for k in range(_BLOCK + 1)]  # (n, nb, 2) each
    lo, hi = verts[0], verts[0]
    for v in verts[1:]:
        lo, hi = np.minimum(lo, v), np.maximum(hi, v)
    centre = (lo + hi) / 2
    r2 = np.zeros(centre.shape[:2])
    for v in verts:
        r2 = np.maximum(r2, np.square(v - centre).sum(axis=2))
    radius = np.sqrt(r2) * (1 + 1e-9) + 1e-9  # a hair wider: rounding never prunes a segment
    c = centre[item]  # (m, nb, 2)
    away = np.square(pts[:, None, 0] - c[..., 0]) + np.square(pts[:, None, 1] - c[..., 1])  # squared
    first = np.argmin(away, axis=1)
    rows = np.arange(m)

    def measure(at, blocks):
        t, dx, dy, d2 = _distances(padded, item[at], pts[at], blocks * _BLOCK, _BLOCK)
        seg = blocks[:, None] * _BLOCK + np.arange(_BLOCK)
        d2 = np.where(seg < n_seg, d2, np.inf)
        k = np.argmin(d2, axis=1)  # the first of equally close ones
        i = np.arange(len(at))
        return seg[i, k], t[i, k], dx[i, k], dy[i, k], d2[i, k]

    j, t, dx, dy, d2 = found = measure(rows, first)
    reach = np.sqrt(d2)[:, None] + radius[item]  # a block whose disc is farther holds no closer segment
    away[rows, first] = np.inf
    at, blocks = np.nonzero(away < reach * reach)
    if len(at):
        more = measure(at, blocks)
        order = np.lexsort((more[0], more[4], at))  # per point: the closest, then the first
        keep = order[np.r_[True, at[order][1:] != at[order][:-1]]]
        p = at[keep]
        better = (more[4][keep] < d2[p]) | ((more[4][keep] == d2[p]) & (more[0][keep] < j[p]))
        for mine, theirs in zip(found, more):
            mine[p[better]] = theirs[keep][better]
    return j, t, np.column_stack([dx, dy])
