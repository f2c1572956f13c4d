"""The model of one shot of a broadcast clip: one camera centre and lens, a pan, tilt, roll and
zoom per frame, and the residuals that measure it against the frames' observations.

A broadcast camera stands on a tripod head: within a shot its centre and its lens (k1) do not
move, only pan, tilt, roll and the zoom (focal length) change, and they change smoothly. Here:

* **parameters** ``[C (3), k1, pan_0, tilt_0, roll_0, log f_0, pan_1, ...]``: one centre ``C`` and
  one ``k1`` for the shot; per frame ``t`` pan, tilt, roll (radians, SoccerNet angles) and
  ``log f`` (square pixels, principal point at the centre);
* **data residuals** (pixels, divided by ``noise_px``): keypoints, reprojected minus observed
  (a pinned keypoint, placed or moved by hand, weighs ``pin_weight`` times more);
  points observed on straight lines, their distance to the image of the line (computed in
  undistorted coordinates, where the image of a 3D line is straight). The projection and the
  undistortion are those of the per-frame refinements (:mod:`pnlviz.geometry.projection`), with
  one rotation and focal length per point (its frame's);
* **smoothness prior**: the second difference (acceleration) of each per-frame parameter, divided
  by its expected size (``accel_deg``, ``accel_log_f``); and a weak prior on k1 (``k1_sigma``).

Its Jacobian (:func:`jacobian`) is taken by finite differences over column groups: each frame's
parameters touch only its own residuals and three prior rows, so the columns of every third frame
share no row and one evaluation differentiates them all (~16 evaluations whatever the shot's
length). :mod:`pnlviz.calib.shot_fit` solves it with the one solver (:mod:`pnlviz.calib.solver`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse

from pnlviz.field.model import FieldModel
from pnlviz.geometry.camera import rotation_from_pan_tilt_roll
from pnlviz.geometry.projection import camera_to_pixels, to_camera, undistort_k1
from pnlviz.geometry.so3 import cross

from .observations import Observations

__all__ = ["ShotData", "ShotModel", "TemporalParams", "flatten", "jacobian"]


@dataclass(frozen=True)
class TemporalParams:
    #: detection noise (px): the scale of the data residuals
    noise_px: float = 1.5
    #: expected frame-to-frame acceleration of pan, tilt and roll (degrees / frame^2)
    accel_deg: float = 0.01
    #: ... of log focal length (1 / frame^2)
    accel_log_f: float = 0.001
    #: soft-L1 threshold, in units of each residual's scale
    robust: float = 3.0
    #: observations farther than this from the shot's camera are dropped (px)
    outlier_px: float = 12.0
    #: ... and, for the first solve, those farther than this from their own frame's camera (px;
    #: looser: a per-frame camera is itself a few pixels off where it extrapolates)
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


@dataclass
class ShotData:
    """The observations of a shot, flattened: keypoints and line points with their frame index."""

    kp_t: np.ndarray  # (N,)
    kp_X: np.ndarray  # (N, 3)
    kp_xy: np.ndarray  # (N, 2)
    ln_t: np.ndarray  # (M,)
    ln_A: np.ndarray  # (M, 3) world ends of the line
    ln_B: np.ndarray
    ln_q: np.ndarray  # (M, 2) observed pixels
    #: (N,) True for keypoints placed or moved by hand (none when left out)
    kp_pin: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))

    def __post_init__(self):
        if len(self.kp_pin) != len(self.kp_t):
            self.kp_pin = np.zeros(len(self.kp_t), bool)

    def subset(self, kp_keep: np.ndarray, ln_keep: np.ndarray) -> ShotData:
        return ShotData(self.kp_t[kp_keep], self.kp_X[kp_keep], self.kp_xy[kp_keep], self.ln_t[ln_keep],
                        self.ln_A[ln_keep], self.ln_B[ln_keep], self.ln_q[ln_keep], self.kp_pin[kp_keep])

    def frame(self, t: int) -> ShotData:
        """Frame ``t``'s observations alone, as a shot of one frame."""
        k, l = self.kp_t == t, self.ln_t == t
        return ShotData(np.zeros(k.sum(), int), self.kp_X[k], self.kp_xy[k], np.zeros(l.sum(), int), self.ln_A[l],
                        self.ln_B[l], self.ln_q[l], self.kp_pin[k])


def flatten(observations: Sequence[Observations | None], model: FieldModel) -> ShotData:
    """The shot's observations (None: a frame without any) as one :class:`ShotData`."""
    kt, kX, kx, kp, lt, lA, lB, lq = [], [], [], [], [], [], [], []
    for t, obs in enumerate(observations):
        if obs is None:
            continue
        kt.append(np.full(obs.n_keypoints, t))
        kX.append(obs.kp_xyz)
        kx.append(obs.kp_xy)
        kp.append(obs.pins)
        for name, pts in obs.lines.items():
            seg = model.lines.get(name)
            if seg is None or len(pts) == 0:
                continue
            m = len(pts)
            lt.append(np.full(m, t))
            lA.append(np.repeat(seg.start[None], m, 0))
            lB.append(np.repeat(seg.end[None], m, 0))
            lq.append(np.asarray(pts, float).reshape(-1, 2))

    def cat(parts, shape):
        return np.concatenate(parts) if parts else np.zeros(shape)

    return ShotData(cat(kt, (0,)).astype(int), cat(kX, (0, 3)), cat(kx, (0, 2)), cat(lt, (0,)).astype(int),
                    cat(lA, (0, 3)), cat(lB, (0, 3)), cat(lq, (0, 2)), cat(kp, (0,)).astype(bool))


class ShotModel:
    """The shot's residual function over the parameter vector
    ``[C (3), k1, pan_0, tilt_0, roll_0, logf_0, pan_1, ...]`` (see the module docstring)."""

    def __init__(self, data: ShotData, T: int, size: tuple[float, float], params: TemporalParams):
        self.d, self.T, self.params = data, T, params
        self.cx, self.cy = size[0] / 2.0, size[1] / 2.0
        self.prior_scale = np.array([math.radians(params.accel_deg)] * 3 + [params.accel_log_f])
        # each keypoint residual's scale: the noise, smaller for a pin (it weighs pin_weight times more)
        self.kp_scale = np.repeat(np.where(data.kp_pin, params.noise_px / params.pin_weight, params.noise_px), 2)

    def unpack(self, x: np.ndarray):
        C, k1 = x[:3], (x[3] if self.params.fit_k1 else 0.0)
        per = x[4:].reshape(self.T, 4)
        return C, k1, per

    def data_residuals(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Keypoint residuals (N, 2) and line distances (M,), pixels."""
        d = self.d
        C, k1, per = self.unpack(x)
        R = rotation_from_pan_tilt_roll(per[:, 0], per[:, 1], per[:, 2])
        f = np.exp(per[:, 3])
        Rk = R[d.kp_t]
        uv, _ = camera_to_pixels(to_camera(d.kp_X, Rk, C), Rk, f[d.kp_t], 1.0, self.cx, self.cy, k1)
        r_kp = uv - d.kp_xy
        # lines: the observed points undistorted, then their distance to the pinhole image of the
        # 3D line (the plane through the centre and the line: l = A x B in camera coordinates)
        fl, Rl = f[d.ln_t], R[d.ln_t]
        qu, _ = undistort_k1(d.ln_q, fl, 1.0, self.cx, self.cy, k1)
        l = cross(to_camera(d.ln_A, Rl, C), to_camera(d.ln_B, Rl, C))
        nrm = np.maximum(np.hypot(l[:, 0], l[:, 1]), 1e-12)
        r_ln = fl * (l[:, 0] * qu[:, 0] + l[:, 1] * qu[:, 1] + l[:, 2]) / nrm
        return r_kp, r_ln

    def residuals(self, x: np.ndarray) -> np.ndarray:
        r_kp, r_ln = self.data_residuals(x)
        per = self.unpack(x)[2]
        acc = (per[:-2] - 2 * per[1:-1] + per[2:]) / self.prior_scale if self.T >= 3 else np.zeros((0, 4))
        k1 = [x[3] / self.params.k1_sigma] if self.params.fit_k1 else []
        return np.concatenate([r_kp.ravel() / self.kp_scale, r_ln / self.params.noise_px, acc.ravel(), k1])

    def column_groups(self) -> list[np.ndarray]:
        """Columns that share no row, to be differentiated together: each shared parameter alone;
        a per-frame parameter with the same parameter of every third frame (frames t and t + 1
        or t + 2 share a prior row, t and t + 3 do not)."""
        groups = [np.array([c]) for c in ([0, 1, 2, 3] if self.params.fit_k1 else [0, 1, 2])]
        for j in range(4):
            for phase in range(3):
                cols = 4 + 4 * np.arange(phase, self.T, 3) + j
                if len(cols):
                    groups.append(cols)
        return groups

    def sparsity(self) -> scipy.sparse.csr_matrix:
        """Which rows each parameter touches (1 where it may)."""
        d, T = self.d, self.T
        n_data, n_acc = 2 * len(d.kp_t) + len(d.ln_t), 4 * max(T - 2, 0)
        rows, cols = [], []
        shared = [0, 1, 2] + ([3] if self.params.fit_k1 else [])
        frame_of_row = np.concatenate([np.repeat(d.kp_t, 2), d.ln_t]).astype(int)
        for c in shared:
            rows.append(np.arange(n_data))
            cols.append(np.full(n_data, c))
        for j in range(4):
            rows.append(np.arange(n_data))
            cols.append(4 + 4 * frame_of_row + j)
        for s in range(max(T - 2, 0)):  # prior row of the acceleration at s + 1: frames s, s+1, s+2
            for j in range(4):
                rows.append(np.full(3, n_data + 4 * s + j))
                cols.append(4 + 4 * np.arange(s, s + 3) + j)
        n_k1 = 0
        if self.params.fit_k1:  # the k1 prior row
            rows.append(np.array([n_data + n_acc]))
            cols.append(np.array([3]))
            n_k1 = 1
        row, col = np.concatenate(rows), np.concatenate(cols)
        return scipy.sparse.csr_matrix((np.ones(len(row)), (row, col)), shape=(n_data + n_acc + n_k1, 4 + 4 * T))


def jacobian(fun: Callable[[np.ndarray], np.ndarray], x: np.ndarray, r0: np.ndarray,
             sparsity: scipy.sparse.csc_matrix, groups: list[np.ndarray]) -> scipy.sparse.csr_matrix:
    """Forward differences of ``fun`` at ``x`` (where it is ``r0``), one evaluation per group of
    columns with disjoint rows (the sparsity pattern says which rows each column touches)."""
    rows, cols, vals = [], [], []
    for group in groups:
        h = 1.5e-8 * np.maximum(1.0, np.abs(x[group]))
        xh = x.copy()
        xh[group] += h
        diff = fun(xh) - r0
        for c, hc in zip(group, h):
            rr = sparsity.indices[sparsity.indptr[c]:sparsity.indptr[c + 1]]
            rows.append(rr)
            cols.append(np.full(len(rr), c))
            vals.append(diff[rr] / hc)
    return scipy.sparse.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                                   shape=sparsity.shape)
