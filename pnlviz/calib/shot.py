"""The model of one shot of a broadcast clip: one camera centre and lens, a pan, tilt, roll and
zoom per frame, and the residuals that measure it against the frames' observations.

A broadcast camera stands on a tripod head: within a shot its centre and its lens (k1) do not
move, only pan, tilt, roll and the zoom (focal length) change, and they change smoothly. Here:

* **parameters** ``x = [C (3), k1, pan_0, tilt_0, roll_0, log f_0, pan_1, ...]``: one centre
  ``C`` and one ``k1`` for the shot; per frame ``t`` pan, tilt, roll (radians, SoccerNet angles)
  and ``log f`` (square pixels, principal point at the centre);
* **data residuals**: each frame's own refinement problem (:class:`pnlviz.calib.problem.Problem`,
  the one the frame pipeline's PnL step solves), so a shot weighs exactly what a frame weighs:
  keypoints, the distance of line points to their projected segment (perpendicular and
  overshoot), circle points to the projected arc, lines and circles ``sqrt(alpha)`` against
  keypoints ``sqrt(1 - alpha)``, a pinned keypoint (placed or moved by hand) ``pin_weight`` times
  a detected one. Residuals are divided by ``noise_px``, the scale of detection noise, so that
  they are commensurate with the prior;
* **smoothness prior**: the second difference (acceleration) of each per-frame parameter, divided
  by its expected size (``accel_deg``, ``accel_log_f``); and a weak prior on k1 (``k1_sigma``).

The Jacobian is analytic: each frame's problem gives its residuals' derivatives with respect to
its camera (a rotation step, the centre, log f and k1), mapped to the shot's parameters by the
chain rule (:func:`angle_steps`: how a change of pan, tilt or roll turns the camera). The
matrix is sparse: a frame's rows touch its own four columns and the four shared ones.
:mod:`pnlviz.calib.shot_fit` solves it with the one solver (:mod:`pnlviz.calib.solver`).
"""

from __future__ import annotations

import copy
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse

from pnlviz.conventions import DEFAULT_ALPHA
from pnlviz.field.model import FieldModel
from pnlviz.geometry.camera import MIN_DEPTH, Camera, rotation_from_pan_tilt_roll
from pnlviz.geometry.projection import camera_to_pixels, to_camera, undistort_k1
from pnlviz.geometry.so3 import cross

from .observations import Observations
from .pipeline import pnl_set
from .problem import FrameData, pin_block, pnl_weights
from .residuals import Block, SegmentJacobian, point_block, segment_block
from .shot_circles import CircleGroup, circle_residuals, group_circles

if TYPE_CHECKING:
    from .calibrate import CalibParams

__all__ = ["FrameDistances", "Selection", "ShotProblem", "TemporalParams", "angle_steps", "frame_data"]


@dataclass(frozen=True)
class TemporalParams:
    #: detection noise (px at 960 px width): the scale of the data residuals against the prior
    noise_px: float = 1.5
    #: expected frame-to-frame acceleration of pan, tilt and roll (degrees / frame^2)
    accel_deg: float = 0.01
    #: ... of log focal length (1 / frame^2)
    accel_log_f: float = 0.001
    #: soft-L1 threshold, in units of ``noise_px``, on every row but the pins'
    #: (:meth:`ShotProblem.loss_bends`); chosen on tuning clips by ``benchmarks/tune_shot_loss.py``
    #: (the smallest that leaves every frame its camera)
    robust: float = 1.5
    #: for the first solve, an observation joins when its own frame's camera puts it within this
    #: (px at 960 px width; looser than the frame's gates: a per-frame camera is itself a few pixels
    #: off where it extrapolates). After it, the frame pipeline's PnL gates decide
    #: (``CalibParams.line_gate_px``, ``point_gate_px``) against the shot's camera
    start_outlier_px: float = 30.0
    #: fit k1 for the shot (off for detectors whose calibration settings say ``refine_k1: false``)
    fit_k1: bool = True
    #: a weak prior on k1 (its scale): it only keeps k1 from running away on a shot that does not
    #: determine it (broadcast lenses have |k1| of a few hundredths)
    k1_sigma: float = 0.3
    #: consecutive per-frame centres farther apart than this (metres) make a cut (per-frame centres
    #: scatter by 1-2 m within a shot; a missed cut costs far more than a false one)
    cut_centre_m: float = 5.0
    #: ... and their views of the pitch differ by more than this share of the image width (median
    #: displacement of a 5 m grid of pitch points between the two cameras)
    cut_view: float = 0.15
    #: an image change above this makes a cut (see :func:`pnlviz.calib.temporal.image_change`)
    cut_image: float = 0.025
    #: Levenberg-Marquardt iterations per solve
    max_iterations: int = 50
    #: weight of a pinned keypoint (placed or moved by hand on one frame) in the shot's solve; a
    #: pin is never dropped as an outlier (as on a single frame, :mod:`pnlviz.calib.pins`)
    pin_weight: float = 7.0


@dataclass(frozen=True)
class Selection:
    """The observations of one frame a shot's solve uses: a keypoint mask and the line and circle
    classes (the rest are outliers for now)."""

    keypoints: np.ndarray
    lines: tuple[str, ...]
    circles: tuple[str, ...]
    #: derived keypoints within the gates left out because the lines and circles fix the camera
    left_out: int = 0

    @classmethod
    def everything(cls, obs: Observations) -> Selection:
        return cls(np.ones(obs.n_keypoints, bool), tuple(obs.lines), tuple(obs.circles))

    def same(self, other: Selection) -> bool:
        return (np.array_equal(self.keypoints, other.keypoints) and self.lines == other.lines
                and self.circles == other.circles)

    @property
    def size(self) -> int:
        return int(self.keypoints.sum()) + len(self.lines) + len(self.circles)


@dataclass(frozen=True)
class FrameDistances:
    """How far a camera puts a frame's observations (px): each keypoint's distance (N,), the
    farthest point of each line and circle class, and (when measured point by point, else 0) the
    sum of the squared distances with the number of scalars it sums (2 per keypoint, 1 per point
    of a line or circle)."""

    keypoints: np.ndarray
    classes: dict[str, float]
    rss: float = 0.0
    n: int = 0

    def selection(self, obs: Observations, point_gate: float, line_gate: float, calib: CalibParams | None = None,
                  unmarked: Mapping[int, str] | None = None) -> Selection:
        """The observations within the gates (and every pin); with ``calib`` (the frames'
        :class:`~pnlviz.calib.calibrate.CalibParams`), what the frame pipeline's PnL fits of them
        (:func:`pnlviz.calib.pipeline.pnl_set`; ``unmarked``: :meth:`FieldModel.unmarked_points`)."""
        kp = (self.keypoints <= point_gate) | obs.pins
        lines = tuple(k for k in obs.lines if self.classes.get(k, math.inf) <= line_gate)
        circles = tuple(k for k in obs.circles if self.classes.get(k, math.inf) <= line_gate)
        if calib is None:
            return Selection(kp, lines, circles)
        fitted, fit_lines, fit_circles = pnl_set(obs, calib, kp, lines, circles, unmarked or {})
        return Selection(fitted, tuple(fit_lines), tuple(fit_circles), int((kp & ~fitted).sum()))

    def values(self, classes: Sequence[str] | None = None) -> np.ndarray:
        """The distances as one array: each keypoint's, then those of ``classes`` (default: every
        class measured)."""
        names = self.classes if classes is None else classes
        return np.concatenate([self.keypoints, [self.classes[k] for k in names]])

    def kept(self, sel: Selection) -> np.ndarray:
        """The distances of the selected observations (keypoints, then classes)."""
        return np.concatenate([self.keypoints[sel.keypoints],
                               [self.classes[k] for k in (*sel.lines, *sel.circles) if k in self.classes]])


def frame_data(observations: Sequence[Observations | None], model: FieldModel) -> list[FrameData | None]:
    """Each frame's observations laid out once for its problem (None: nothing observed)."""
    return [None if o is None else FrameData.build(o, model) for o in observations]


def angle_steps(pan, tilt, roll) -> np.ndarray:
    """(3, 3) (or (T, 3, 3) for arrays of T angles): column ``i`` is the rotation step ``w``
    (``R <- exp([w]x) R``, the frame problems' update) that a unit change of angle ``i`` (pan,
    tilt, roll) makes, to first order.

    With ``O = Rz(pan) Rx(tilt) Rz(roll)`` and ``R = O^T``: ``dR/dpan R^T = -[R e_z]x``,
    ``dR/dtilt R^T = -[R Rz(pan) e_x]x``, ``dR/droll R^T = -[e_z]x``."""
    R = rotation_from_pan_tilt_roll(pan, tilt, roll)
    c, s = np.cos(pan), np.sin(pan)
    out = np.empty(np.shape(R))
    out[..., 0] = -R[..., 2]
    out[..., 1] = -(R[..., 0] * np.expand_dims(c, -1) + R[..., 1] * np.expand_dims(s, -1))  # -R Rz(pan) e_x
    out[..., 2] = [0.0, 0.0, -1.0]
    return out


class ShotProblem:
    """The shot's residuals over ``x`` (see the module docstring) against the frames' data
    (``frames[t]``: :class:`FrameData` or None), each frame restricted to its :class:`Selection`
    (None: everything it observed). ``size``: (W, H) of the frames; ``alpha``: the PnL weight of
    lines against points; ``pin_scale``: px where a pin's bounded loss bends (0: squares).

    The frames' rows are stacked (every keypoint, line point and circle of the shot at once, each
    with its frame's rotation and focal length) and go through the frame problem's residual blocks
    (:mod:`pnlviz.calib.residuals`) with the frame problem's weights, so one evaluation costs a
    few vectorised calls whatever the shot's length (a loop over frames costs ~0.2 ms a frame)."""

    def __init__(self, frames: Sequence[FrameData | None], size: tuple[float, float], params: TemporalParams,
                 selections: Sequence[Selection | None] | None = None, alpha: float = DEFAULT_ALPHA,
                 pin_scale: float = 0.0):
        self.T, self.params = len(frames), params
        W, H = float(size[0]), float(size[1])
        self.size, self.cx, self.cy = (W, H), W / 2.0, H / 2.0
        self.noise = params.noise_px * W / 960.0
        self.pin_scale = pin_scale
        self.rows = _Rows.stack(frames, alpha)
        if selections is not None:
            self.rows = self.rows.restricted(selections)
        self.n_data = self.rows.n_res
        self.prior_scale = np.array([math.radians(params.accel_deg)] * 3 + [params.accel_log_f])
        self.n_params = 4 + 4 * self.T
        self._prior = self._prior_jacobian()

    def restricted(self, selections: Sequence[Selection | None]) -> ShotProblem:
        """This problem with each frame restricted to ``selections[t]`` (None: everything), for a
        problem made with everything selected: the same as a new problem on those selections, its
        rows taken from this one's (a solve restricts the shot anew after each gating)."""
        out = copy.copy(self)
        out.rows = self.rows.restricted(selections)
        out.n_data = out.rows.n_res
        return out

    # ------------------------------------------------------------------ parameters
    def unpack(self, x: np.ndarray) -> tuple[np.ndarray, float, np.ndarray]:
        """``(C (3,), k1, per-frame (T, 4): pan, tilt, roll, log f)``."""
        return x[:3], (float(x[3]) if self.params.fit_k1 else 0.0), x[4:].reshape(self.T, 4)

    def cameras(self, x: np.ndarray) -> list[Camera]:
        C, k1, per = self.unpack(x)
        R = rotation_from_pan_tilt_roll(per[:, 0], per[:, 1], per[:, 2])
        W, H = self.size
        radial = np.zeros(6)
        radial[0] = k1
        return [Camera(f, f, self.cx, self.cy, R[t], C, W, H, radial)
                for t, f in enumerate(np.exp(per[:, 3]).tolist())]

    # ------------------------------------------------------------------ residuals
    def loss_bends(self, bend: float) -> float | np.ndarray:
        """Where the robust loss bends (noise units) on each row of :meth:`evaluate`: at ``bend``
        for the observations and the priors; nowhere (np.inf: squares) for the pins, which bound
        their own loss (:func:`pin_block`) and are never outliers. ``bend`` itself for a shot
        without pins."""
        pins = self.rows.kp_pin
        if not pins.any():
            return bend
        out = np.full(self.rows.n_res + self._prior.shape[0], bend)  # the data rows, then the prior's
        out[:2 * len(pins)][np.repeat(pins, 2)] = np.inf
        return out

    def evaluate(self, x: np.ndarray, jac: bool = False) -> tuple[np.ndarray, scipy.sparse.csr_matrix | None]:
        """Residuals (n,) at ``x`` (keypoints, line points' perpendicular distances and overshoots,
        circle points, then the prior rows) and, with ``jac``, their Jacobian (n, 4 + 4 T) as a
        sparse matrix."""
        C, k1, per = self.unpack(x)
        R = rotation_from_pan_tilt_roll(per[:, 0], per[:, 1], per[:, 2])
        f = np.exp(per[:, 3])
        rows = self.rows
        r = np.empty(rows.n_res)
        J = np.empty((rows.n_res, 8)) if jac else None
        at = 0
        if rows.kp_t.size:
            tk = rows.kp_t
            uv, Juv = camera_to_pixels(to_camera(rows.kp_X, R[tk], C), R[tk], f[tk], 1.0, self.cx, self.cy, k1, jac)
            block = point_block(uv, Juv, rows.kp_xy)
            if rows.kp_pin.any():
                block = pin_block(block, rows.kp_pin, self.params.pin_weight, self.pin_scale)
            at = _put(r, J, at, np.repeat(rows.kp_w, 2), block)
        if rows.ln_t.size:
            tl = rows.ln_t
            A, B = to_camera(rows.ln_A, R[tl], C), to_camera(rows.ln_B, R[tl], C)
            q, dq = undistort_k1(rows.ln_q, f[tl], 1.0, self.cx, self.cy, k1, jac)
            sj = _segment_jacobian(A, B, dq, R[tl]) if dq is not None else None
            for block in segment_block(A, B, q, f[tl], MIN_DEPTH, sj):
                at = _put(r, J, at, rows.ln_w, block)
        for g in rows.circles:
            at = _put(r, J, at, g.weights[g.item], circle_residuals(g, R, C, f, k1, self.cx, self.cy, jac))
        acc = (per[:-2] - 2 * per[1:-1] + per[2:]) / self.prior_scale if self.T >= 3 else np.zeros((0, 4))
        k1_row = [x[3] / self.params.k1_sigma] if self.params.fit_k1 else []
        out = np.concatenate([r / self.noise, acc.ravel(), k1_row])
        if J is None:
            return out, None
        return out, scipy.sparse.vstack([self._chain(J / self.noise, per), self._prior], format="csr")

    def distances(self, x: np.ndarray) -> list[FrameDistances | None]:
        """Per frame, how far its camera at ``x`` puts its selected observations (unweighted
        pixels, as :class:`FrameDistances`: with every observation selected, each keypoint of the
        frame in order); None for a frame without data."""
        C, k1, per = self.unpack(x)
        R = rotation_from_pan_tilt_roll(per[:, 0], per[:, 1], per[:, 2])
        f = np.exp(per[:, 3])
        rows = self.rows
        kp = np.zeros(0)
        if rows.kp_t.size:
            tk = rows.kp_t
            uv, _ = camera_to_pixels(to_camera(rows.kp_X, R[tk], C), R[tk], f[tk], 1.0, self.cx, self.cy, k1)
            kp = np.hypot(*(uv - rows.kp_xy).T)
        ln = np.zeros(0)
        if rows.ln_t.size:
            tl = rows.ln_t
            A, B = to_camera(rows.ln_A, R[tl], C), to_camera(rows.ln_B, R[tl], C)
            q, _ = undistort_k1(rows.ln_q, f[tl], 1.0, self.cx, self.cy, k1)
            perp, over = segment_block(A, B, q, f[tl], MIN_DEPTH)
            ln = np.hypot(perp.r, over.r)
        seen = np.unique(np.concatenate([rows.kp_t, rows.ln_t] + [g.frames for g in rows.circles]).astype(int))
        kp = np.nan_to_num(kp, nan=math.inf)
        # the rows are stacked frame by frame, and a class's rows follow each other: split, not searched
        frames, at = np.unique(rows.kp_t, return_index=True)
        per_frame = dict(zip(frames.tolist(), np.split(kp, at[1:]))) if len(frames) else {}
        found = {int(t): FrameDistances(per_frame.get(int(t), np.zeros(0)), {}) for t in seen}
        for (t, name), worst in zip(rows.ln_items, _runs_max(ln, rows.ln_counts)):
            found[t].classes[name] = worst
        for g in rows.circles:
            d = np.abs(circle_residuals(g, R, C, f, k1, self.cx, self.cy, False).r)
            for t, worst in zip(g.frames.tolist(), _runs_max(d, np.bincount(g.item, minlength=len(g.frames)))):
                found[t].classes[g.name] = worst
        return [found.get(t) for t in range(self.T)]

    def _chain(self, J: np.ndarray, per: np.ndarray) -> scipy.sparse.csr_matrix:
        """The data rows' Jacobian with respect to each row's camera (a rotation step, the centre,
        log f, k1: :mod:`pnlviz.geometry.projection`'s 8) chained to the shot's parameters."""
        t = self.rows.frame
        steps = angle_steps(per[:, 0], per[:, 1], per[:, 2])
        # each row's 8 entries in column order (the centre and k1, then its frame's 4): the CSR
        # arrays are written directly
        block = np.empty((len(J), 8))
        block[:, :3] = J[:, 3:6]  # the centre
        block[:, 3] = J[:, 7] if self.params.fit_k1 else 0.0
        block[:, 4:7] = np.einsum("nk,nkj->nj", J[:, :3], steps[t])  # pan, tilt, roll
        block[:, 7] = J[:, 6]  # log f
        cols = np.empty((len(J), 8), np.int32)
        cols[:, :4] = np.arange(4)
        cols[:, 4:] = 4 + 4 * t[:, None] + np.arange(4)
        indptr = np.arange(0, 8 * len(J) + 1, 8, dtype=np.int32)
        return scipy.sparse.csr_matrix((block.ravel(), cols.ravel(), indptr), shape=(len(J), self.n_params))

    def _prior_jacobian(self) -> scipy.sparse.csr_matrix:
        """The prior rows' Jacobian (constant: the prior is linear in ``x``): the acceleration of
        parameter j at frame s + 1 reads frames s, s + 1, s + 2."""
        n_acc = 4 * max(self.T - 2, 0)
        s, j = np.divmod(np.arange(n_acc), 4)
        rows = np.repeat(np.arange(n_acc), 3)
        cols = (4 + 4 * (s[:, None] + np.arange(3)) + j[:, None]).ravel()
        vals = (np.array([1.0, -2.0, 1.0]) / self.prior_scale[j][:, None]).ravel()
        if self.params.fit_k1:
            rows, cols = np.append(rows, n_acc), np.append(cols, 3)
            vals = np.append(vals, 1.0 / self.params.k1_sigma)
        return scipy.sparse.csr_matrix((vals, (rows, cols)), shape=(n_acc + int(self.params.fit_k1), self.n_params))


@dataclass
class _Rows:
    """The selected observations of every frame of a shot, stacked, with each row's frame and
    weight (the frame problem's: keypoints ``sqrt(1 - alpha)``, lines and circles ``sqrt(alpha)``,
    1 for a kind alone on its frame)."""

    kp_t: np.ndarray
    kp_X: np.ndarray
    kp_xy: np.ndarray
    kp_pin: np.ndarray
    kp_w: np.ndarray
    ln_t: np.ndarray
    ln_A: np.ndarray
    ln_B: np.ndarray
    ln_q: np.ndarray
    ln_w: np.ndarray
    #: the circles seen, one group per class (:class:`pnlviz.calib.shot_circles.CircleGroup`)
    circles: list[CircleGroup]
    #: each residual row's frame
    frame: np.ndarray
    #: the (frame, class) of each run of line rows, in row order, and the rows of each run
    ln_items: list[tuple[int, str]]
    ln_counts: np.ndarray
    #: the circles' items before grouping, ``(frame, world, pixels, weight, class)`` in frame order
    circle_items: list[tuple[int, np.ndarray, np.ndarray, float, str]]
    #: the PnL weight of lines against points the weights come from
    alpha: float

    @property
    def n_res(self) -> int:
        return len(self.frame)

    @classmethod
    def stack(cls, frames: Sequence[FrameData | None], alpha: float) -> _Rows:
        """Every observation of each frame (a frame's rows as its :class:`FrameData` holds them)."""
        T = len(frames)
        kp: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        ln: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        n_kp, n_ln = np.zeros(T, int), np.zeros(T, int)
        drawn = np.zeros(T, bool)  # a frame with a line or a circle
        items: list[tuple[int, str]] = []
        counts: list[int] = []
        circles: list[tuple[int, np.ndarray, np.ndarray, str]] = []
        for t, data in enumerate(frames):
            if data is None:
                continue
            obs = data.obs
            if obs.n_keypoints:
                kp.append((obs.kp_xyz, obs.kp_xy, obs.pins))
                n_kp[t] = obs.n_keypoints
            if data.line_names:
                ln.append((data.line_a, data.line_b, data.line_pts))
                n_ln[t] = len(data.line_pts)
                items += [(t, name) for name in data.line_names]
                counts += [rows.stop - rows.start for rows in data.line_rows]
            circles += [(t, world, pts, name) for name, world, pts in data.arcs(0.5)]
            drawn[t] = bool(data.line_names or obs.circles)
        w_pt, w_ln = pnl_weights(alpha, n_kp > 0, drawn)  # per frame
        kp_t, ln_t = np.repeat(np.arange(T), n_kp), np.repeat(np.arange(T), n_ln)
        arcs = [(t, world, pts, float(w_ln[t]), name) for t, world, pts, name in circles]
        groups = group_circles(arcs)
        frame = np.concatenate([np.repeat(kp_t, 2), ln_t, ln_t] + [g.row_frames for g in groups])

        def cat(parts: list[tuple], i: int, shape: tuple, dtype=float) -> np.ndarray:
            return np.concatenate([p[i] for p in parts]).astype(dtype) if parts else np.zeros(shape, dtype)

        return cls(kp_t, cat(kp, 0, (0, 3)), cat(kp, 1, (0, 2)), cat(kp, 2, (0,), bool), w_pt[kp_t],
                   ln_t, cat(ln, 0, (0, 3)), cat(ln, 1, (0, 3)), cat(ln, 2, (0, 2)), w_ln[ln_t],
                   groups, frame.astype(int), items, np.array(counts, int), arcs, alpha)

    def restricted(self, selections: Sequence[Selection | None]) -> _Rows:
        """These rows (every observation of each frame: :meth:`stack`) with each frame restricted to
        ``selections[t]`` (None: everything), rows in the same order: what :meth:`stack` gives for
        the frames without the observations left out."""
        T = len(selections)
        counts = np.bincount(self.kp_t, minlength=T)
        masks = [np.ones(n, bool) if s is None else s.keypoints for s, n in zip(selections, counts)]
        if any(len(m) != n for m, n in zip(masks, counts)):
            raise ValueError("a frame's keypoint mask does not match its rows: restrict the rows of every observation")
        kp = np.concatenate([masks[t] for t in np.flatnonzero(counts)]) if len(self.kp_t) else np.zeros(0, bool)
        lines_of = [None if s is None else set(s.lines) for s in selections]  # None: every class
        circles_of = [None if s is None else set(s.circles) for s in selections]
        keep = np.array([(kept := lines_of[t]) is None or name in kept for t, name in self.ln_items], bool)
        circles = [it for it in self.circle_items if (kept := circles_of[it[0]]) is None or it[4] in kept]
        K = np.bincount(self.kp_t[kp], minlength=T)  # each frame's keypoints left
        drawn = np.zeros(T, bool)  # ... and whether it keeps a line or a circle
        drawn[[t for (t, _), k in zip(self.ln_items, keep) if k] + [it[0] for it in circles]] = True
        w_pt, w_ln = pnl_weights(self.alpha, K > 0, drawn)  # per frame
        n = self.ln_counts[keep]  # the kept runs' rows, back to back
        starts = (np.cumsum(self.ln_counts) - self.ln_counts)[keep]
        ln = np.repeat(starts - (np.cumsum(n) - n), n) + np.arange(n.sum(), dtype=int)
        kp_t, ln_t = self.kp_t[kp], self.ln_t[ln]
        groups = group_circles([(t, world, pts, float(w_ln[t]), name) for t, world, pts, _, name in circles])
        frame = np.concatenate([np.repeat(kp_t, 2), ln_t, ln_t] + [g.row_frames for g in groups])
        return _Rows(kp_t, self.kp_X[kp], self.kp_xy[kp], self.kp_pin[kp], w_pt[kp_t],
                     ln_t, self.ln_A[ln], self.ln_B[ln], self.ln_q[ln], w_ln[ln_t],
                     groups, frame.astype(int), [it for it, k in zip(self.ln_items, keep) if k], n, circles,
                     self.alpha)


def _runs_max(values: np.ndarray, counts) -> list[float]:
    """The largest of each run of ``values`` (runs of ``counts`` values back to back; 0 for an
    empty run)."""
    counts = np.asarray(counts, int)
    out = np.zeros(len(counts))
    full = counts > 0
    if full.any():
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
        out[full] = np.maximum.reduceat(values, starts[full])
    return out.tolist()


def _put(r: np.ndarray, J: np.ndarray | None, at: int, weight, block: Block) -> int:
    n = len(block.r)
    w = np.asarray(weight, float)
    r[at:at + n] = w * block.r
    if J is not None:
        assert block.J is not None, "a block without its Jacobian in a Jacobian evaluation"
        J[at:at + n] = (w[:, None] if w.ndim else w) * block.J
    return at + n


def _segment_jacobian(A: np.ndarray, B: np.ndarray, dq: np.ndarray, R: np.ndarray) -> SegmentJacobian:
    """:meth:`pnlviz.calib.models.CameraModel.segment_jacobian` with a rotation per row."""
    A2, B2, R2, Jq = np.vstack([A, A]), np.vstack([B, B]), np.concatenate([R, R]), np.vstack([dq, dq])

    def ends_vjp(ga, gb):
        out = np.zeros((len(ga), 8))
        out[:, :3] = cross(A2, ga) + cross(B2, gb)
        out[:, 3:6] = -np.einsum("ni,nij->nj", ga + gb, R2)
        return out

    def q_vjp(g):
        out = np.zeros((len(g), 8))
        out[:, 6] = g[:, 0] * Jq[:, 0, 0] + g[:, 1] * Jq[:, 1, 0]
        out[:, 7] = g[:, 0] * Jq[:, 0, 1] + g[:, 1] * Jq[:, 1, 1]
        return out

    return SegmentJacobian(ends_vjp, q_vjp, 6)
