"""A frame's observations laid out once for the residual blocks (:class:`FrameData`), and the
weighted least-squares problem of a model against them (:class:`Problem`), the same for the camera
and the homography.

Residuals, all in pixels, in this order: keypoints (2 per point), the perpendicular distance of
every observed line point, its overshoot beyond the segment's ends, and the distance of every
observed circle point to the projected arc (a dense polyline). Line and circle terms are weighted
``sqrt(alpha)`` and keypoints ``sqrt(1 - alpha)`` (the paper's cost, in squares); when only one
kind is present its weight is 1. Pinned keypoints (placed by hand) may be weighted above the
others with a bounded robust loss of their own (``pin_weight``, ``pin_scale``: :func:`pin_block`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pnlviz.calib.observations import Observations
from pnlviz.calib.residuals import Block, point_block, polyline_block, segment_block
from pnlviz.conventions import DEFAULT_ALPHA, EVAL_WIDTH
from pnlviz.field.model import FieldModel

#: the residual of each point of a circle seen from behind (no arc in front to measure against)
BEHIND = 1e3


def aim_inside(points: np.ndarray, width: int, height: int, inset: float) -> np.ndarray:
    """Line points ``(N, 2)`` (pixels) on the border of a ``width`` x ``height`` image (within
    1.5 px at 960 px width of its first or last pixel row or column) moved ``inset`` px inside,
    ``(N, 2)``, a copy. A line leaving the image is drawn, and scored by the SoccerNet evaluator,
    only as far as its projection stays inside the image: one grazing the border a pixel outside
    leaves the image early, and an annotated point at the border ends up far along the line (on
    SN22, 39 of the line points beyond 5 px after a fit; 17 when aimed). Aimed a little inside, the
    fitted line reaches the border at the point; a line crossing the border steeply only moves
    along itself."""
    p = np.array(points, dtype=float).reshape(-1, 2)
    near = 1.5 * width / EVAL_WIDTH
    for axis, last in ((0, width - 1), (1, height - 1)):
        v = p[:, axis]
        v[v <= near] += inset
        v[v >= last - near] -= inset
    return p


@dataclass
class FrameData:
    """One frame's observations with the model geometry they are compared with. Built once per
    frame: every candidate, vote and refinement of the frame reads it."""

    obs: Observations
    line_names: list[str]
    line_a: np.ndarray  #: (L, 3) world start of the class of each observed line point
    line_b: np.ndarray  #: (L, 3) world end
    line_pts: np.ndarray  #: (L, 2) observed pixels
    line_rows: list[slice]  #: the rows of each class in line_a, line_b and line_pts
    line_ground: list[bool]  #: each class lies on the ground plane
    model: FieldModel
    _arcs: dict = field(default_factory=dict)
    _layouts: dict = field(default_factory=dict)

    @classmethod
    def build(cls, obs: Observations, model: FieldModel) -> FrameData:
        names = list(obs.lines)
        ends_a, ends_b, pts = [], [], []
        for name in names:
            seg, p = model.lines[name], np.asarray(obs.lines[name], float).reshape(-1, 2)
            ends_a.append(np.repeat(seg.start[None], len(p), 0))
            ends_b.append(np.repeat(seg.end[None], len(p), 0))
            pts.append(p)
        stack = (lambda parts, k: np.vstack(parts) if parts else np.zeros((0, k)))
        ground = [model.lines[n].plane == "ground" for n in names]
        bounds = np.cumsum([0] + [len(p) for p in pts])
        rows = [slice(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:])]
        return cls(obs, names, stack(ends_a, 3), stack(ends_b, 3), stack(pts, 2), rows, ground, model)

    def aimed_inside(self, inset: float) -> FrameData:
        """This frame with its line points on the image border aimed ``inset`` px inside
        (:func:`aim_inside`), a new FrameData sharing everything else (its own caches)."""
        return FrameData(self.obs, self.line_names, self.line_a, self.line_b,
                         aim_inside(self.line_pts, self.obs.width, self.obs.height, inset), self.line_rows,
                         self.line_ground, self.model)

    def layout(self, lift, keypoints=None, lines=None, circles=None, ground_only: bool = False,
               circle_step: float = 0.5) -> Layout:
        """The rows of a problem on this frame (see :class:`Problem`), built once per selection."""
        key = (lift, None if keypoints is None else np.asarray(keypoints, bool).tobytes(),
               None if lines is None else tuple(lines), None if circles is None else tuple(circles), ground_only,
               circle_step)
        if key not in self._layouts:
            self._layouts[key] = _layout(self, lift, keypoints, lines, circles, ground_only, circle_step)
        return self._layouts[key]

    def arcs(self, step: float) -> list[tuple[str, np.ndarray, np.ndarray]]:
        """``(class, world samples (S, 3) every ``step`` metres, observed pixels (M, 2))`` of
        each observed circle."""
        if step not in self._arcs:
            out = []
            for name, p in self.obs.circles.items():
                arc = self.model.circles[name]
                k = max(8, int(np.radians(arc.end_deg - arc.start_deg) * arc.radius / step))
                world = arc.point_at(np.linspace(np.radians(arc.start_deg), np.radians(arc.end_deg), k + 1))
                out.append((name, world, np.asarray(p, float).reshape(-1, 2)))
            self._arcs[step] = out
        return self._arcs[step]


@dataclass
class Layout:
    """The rows of a problem: which keypoints, line points and circle points it uses, with every
    model point (keypoints, segment ends, circle samples) in one array (``world``), lifted for the
    model, so that one product per evaluation transforms them all."""

    kp_mask: np.ndarray  #: (N,) the frame's keypoints used
    kp_ids: np.ndarray
    kp_xy: np.ndarray
    line_pts: np.ndarray
    line_slices: dict[str, slice]  #: class -> its observed points' rows (consecutive)
    world: np.ndarray
    K: int  #: keypoints: world[:K]
    L: int  #: line points: starts world[K:K+L], ends world[K+L:K+2L]
    circle_items: list  #: (class, its samples' rows in world, observed pixels (M, 2))
    #: the rows of ``world`` projected to pixels, in one call per evaluation: the keypoints, then
    #: the circles' samples (a circle's rows in ``world`` less ``2 L``: its rows among these)
    pixel_rows: np.ndarray

    @property
    def n_res(self) -> int:
        return 2 * self.K + 2 * self.L + sum(len(p) for _, _, p in self.circle_items)


def _layout(data: FrameData, lift, keypoints, lines, circles, ground_only: bool, circle_step: float) -> Layout:
    obs = data.obs
    mask = np.ones(obs.n_keypoints, bool) if keypoints is None else np.asarray(keypoints, bool).copy()
    if ground_only:
        mask &= obs.ground
    names = data.line_names
    use = [lines is None or name in lines for name in names]
    if ground_only:
        use = [u and g for u, g in zip(use, data.line_ground)]
    slices, parts_a, parts_b, parts_q, at = {}, [], [], [], 0
    for name, used, rows in zip(names, use, data.line_rows):
        if used:  # observed points of a class are consecutive
            n = rows.stop - rows.start
            slices[name] = slice(at, at + n)
            parts_a.append(data.line_a[rows])
            parts_b.append(data.line_b[rows])
            parts_q.append(data.line_pts[rows])
            at += n
    arcs = [(name, world, pts) for name, world, pts in data.arcs(circle_step)
            if (circles is None or name in circles) and (not ground_only or abs(world[0, 2]) < 1e-9)]
    K, L = int(mask.sum()), at
    world = lift(np.concatenate([obs.kp_xyz[mask]] + parts_a + parts_b + [w for _, w, _ in arcs]))
    items, start = [], K + 2 * L
    for name, w, pts in arcs:
        items.append((name, slice(start, start + len(w)), pts))
        start += len(w)
    line_pts = np.concatenate(parts_q) if parts_q else np.zeros((0, 2))
    pixel_rows = np.r_[0:K, K + 2 * L:len(world)]
    return Layout(mask, obs.kp_ids[mask], obs.kp_xy[mask], line_pts, slices, world, K, L, items, pixel_rows)


class Problem:
    """The residuals of ``model`` (see :mod:`pnlviz.calib.models`) against ``data``.

    ``keypoints``: mask (N,) of the keypoints used (default all); ``lines`` / ``circles``: the
    classes used (default all observed ones); ``ground_only``: keypoints, lines and circles on
    the ground plane only (the homography). The layout of a selection is built once per frame
    (see :meth:`FrameData.layout`): every candidate camera of a vote shares it.
    """

    def __init__(self, model, data: FrameData, alpha: float = DEFAULT_ALPHA, *, keypoints: np.ndarray | None = None,
                 lines=None, circles=None, ground_only: bool = False, circle_step: float = 0.5,
                 pin_weight: float = 1.0, pin_scale: float = 0.0):
        self.model, self.data = model, data
        lay = data.layout(model.lift, keypoints, lines, circles, ground_only, circle_step)
        self.kp_mask, self.kp_ids, self.kp_xy = lay.kp_mask, lay.kp_ids, lay.kp_xy
        self.line_pts, self.line_slices = lay.line_pts, lay.line_slices
        self.world, self.circle_items, self.n_res = lay.world, lay.circle_items, lay.n_res
        self.kp_X = self.world[:lay.K]
        self.line_a, self.line_b = self.world[lay.K:lay.K + lay.L], self.world[lay.K + lay.L:lay.K + 2 * lay.L]
        self._pixel_rows, self._circle_shift = lay.pixel_rows, 2 * lay.L
        self.w_pt, self.w_ln = (float(w) for w in pnl_weights(alpha, lay.K > 0, lay.n_res > 2 * lay.K))
        pins = data.obs.pins[lay.kp_mask]
        self.pins = pins if pins.any() and (pin_weight != 1.0 or pin_scale > 0) else None
        self.pin_weight, self.pin_scale = pin_weight, pin_scale

    @property
    def n_free(self) -> int:
        return len(self.model.free)

    def evaluate(self, state, jac: bool = False) -> tuple[np.ndarray, np.ndarray | None]:
        """Weighted residuals (n,) at ``state`` and, with ``jac``, their Jacobian (n, free)."""
        m = self.model
        T = m.transform(self.world, state)
        r = np.empty(self.n_res)
        J = np.empty((self.n_res, m.n_params)) if jac else None
        K, L = len(self.kp_xy), len(self.line_pts)
        at = 0
        uv, Juv = np.zeros((0, 2)), None
        if len(self._pixel_rows):
            uv, Juv = m.pixels(T[self._pixel_rows], state, jac, self.world[self._pixel_rows])
        if K:
            block = point_block(uv[:K], None if Juv is None else Juv[:K], self.kp_xy)
            if self.pins is not None:
                block = pin_block(block, self.pins, self.pin_weight, self.pin_scale)
            at = self._put(r, J, at, self.w_pt, block)
        if L:
            A, B = T[K:K + L], T[K + L:K + 2 * L]
            q, dq = m.observed(self.line_pts, state, jac)
            sj = m.segment_jacobian(A, B, dq, state, self.line_a, self.line_b) if jac else None
            for block in segment_block(A, B, q, m.scale(state), m.min_depth, sj):
                at = self._put(r, J, at, self.w_ln, block)
        for _, rows, pts in self.circle_items:
            px = slice(rows.start - self._circle_shift, rows.stop - self._circle_shift)
            weight, block = self._circle(T[rows], uv[px], None if Juv is None else Juv[px], pts)
            at = self._put(r, J, at, weight, block)
        return r, (None if J is None else J[:, m.free])

    @staticmethod
    def _put(r: np.ndarray, J: np.ndarray | None, at: int, weight: float, block: Block) -> int:
        n = len(block.r)
        r[at:at + n] = weight * block.r
        if J is not None:
            assert block.J is not None, "a block without its Jacobian in a Jacobian evaluation"
            J[at:at + n] = weight * block.J
        return at + n

    def _circle(self, T: np.ndarray, uv: np.ndarray, J: np.ndarray | None, pts: np.ndarray) -> tuple[float, Block]:
        """A circle's block: its samples ``T`` (the model's space), their pixels ``uv`` and, in a
        Jacobian evaluation, their derivatives ``J``; the samples behind the camera left out."""
        front = self.model.front(T)
        if not front.all():  # (usually all are in front: nothing to leave out, no copy)
            if front.sum() < 2:
                return 1.0, Block(np.full(len(pts), BEHIND),
                                  None if J is None else np.zeros((len(pts), self.model.n_params)))
            uv, J = uv[front], None if J is None else J[front]
        return self.w_ln, polyline_block(uv, pts, None if J is None else J.__getitem__)

    def residuals(self, state) -> np.ndarray:
        return self.evaluate(state)[0]

    def class_rows(self) -> dict[str, np.ndarray]:
        """The residual rows of each line and circle class: a line's perpendicular distances then
        its overshoots (as many of each as it has points), a circle's distances."""
        K, L = len(self.kp_xy), len(self.line_pts)
        rows = {name: np.r_[2 * K + np.arange(s.start, s.stop), 2 * K + L + np.arange(s.start, s.stop)]
                for name, s in self.line_slices.items()}
        at = 2 * K + 2 * L
        for name, _, pts in self.circle_items:
            rows[name] = np.arange(at, at + len(pts))
            at += len(pts)
        return rows

    def class_distances(self, state) -> dict[str, np.ndarray]:
        """Unweighted distances (px) of each line and circle class's observed points at ``state``
        (rows as :meth:`class_rows` lays them out, read here in one pass: the vote calls this for
        every candidate)."""
        r = self.residuals(state)
        start = 2 * len(self.kp_xy)
        n = len(self.line_pts)
        perp, over = r[start:start + n], r[start + n:start + 2 * n]
        dist = np.sqrt(perp**2 + over**2) / self.w_ln
        out = {name: dist[s] for name, s in self.line_slices.items()}
        start += 2 * n
        for name, _, pts in self.circle_items:
            out[name] = np.abs(r[start:start + len(pts)]) / self.w_ln
            start += len(pts)
        return out


def pnl_weights(alpha: float, keypoints, curves) -> tuple[np.ndarray, np.ndarray]:
    """The weights of a frame's keypoint rows and of its line and circle rows: ``sqrt(1 - alpha)``
    and ``sqrt(alpha)`` (the paper's cost, in squares), 1 for a kind alone on its frame (no
    ``curves``: no line or circle; no ``keypoints``). Elementwise over arrays of frames."""
    return np.where(curves, np.sqrt(1 - alpha), 1.0), np.where(keypoints, np.sqrt(alpha), 1.0)


def pin_block(block: Block, pins: np.ndarray, weight: float, scale: float) -> Block:
    """The keypoint block (2 rows per point) with the rows of pinned points (mask ``pins``)
    weighted ``weight`` under a bounded loss: a pin ``d`` px from its projection costs
    ``weight^2 c^2 log(1 + d^2 / c^2)`` (Cauchy, ``c = scale``; ``scale`` 0: squares), so it pulls
    the camera hard when the camera can agree with it, and an impossible one pulls no harder than
    a few pixels' worth of the others. As a residual ``e' = s(d) e`` with ``s = g(d) / d``,
    ``g = c sqrt(log(1 + d^2 / c^2))``; its Jacobian ``(s I + s'/d e e^T) de``."""
    r = block.r.reshape(-1, 2).copy()
    J = None if block.J is None else block.J.reshape(len(r), 2, -1).copy()
    e = r[pins]
    s, ds = np.ones(len(e)), np.zeros(len(e))
    if scale > 0:
        d = np.linalg.norm(e, axis=1)
        big = d > 1e-9 * scale
        dd, q = d[big], (d[big] / scale) ** 2
        g = scale * np.sqrt(np.log1p(q))
        dg = dd / (scale * np.sqrt(np.log1p(q)) * (1 + q))
        s[big] = g / dd
        ds[big] = (dg * dd - g) / dd**2 / dd  # s'(d) / d
    r[pins] = weight * s[:, None] * e
    if J is not None:
        Je = J[pins]
        eJ = np.einsum("ni,nip->np", e, Je)
        J[pins] = weight * (s[:, None, None] * Je + ds[:, None, None] * e[:, :, None] * eJ[:, None, :])
    return Block(r.ravel(), None if J is None else J.reshape(len(block.r), -1))
