"""Temporal calibration of broadcast clips: shots, and one broadcast camera per shot.

A broadcast camera stands on a tripod head: within a shot its centre and its lens (k1) do not
move, only pan, tilt, roll and the zoom (focal length) change, and they change smoothly. Per-frame
calibration ignores that, so its cameras jitter with the detection noise (and fail on frames with
too few keypoints). Here, per shot:

* **parameters**: one centre ``C`` (3) and one ``k1`` for the shot; per frame ``t`` pan, tilt,
  roll (radians, SoccerNet angles) and ``log f`` (square pixels, principal point at the centre);
* **data residuals** (pixels, divided by ``noise_px``): keypoints, reprojected minus observed;
  points observed on straight lines, their distance to the image of the line (computed in
  undistorted coordinates, where the image of a 3D line is straight);
* **smoothness prior**: the second difference (acceleration) of each per-frame parameter, divided
  by its expected size (``accel_deg``, ``accel_log_f``);
* **robust**: the first solve uses the observations that their frame's own camera agrees with
  (within ``start_outlier_px``; all of a frame that has none), then the ones the shot's camera agrees
  with, until that set stops changing (outlier detections, wrong ids, outlier frames); and a
  soft-L1 loss on every residual (``robust``, in units of the residual's scale);
* **solved jointly** by robust Levenberg-Marquardt on the whole shot (:func:`_solve`: the Jacobian
  by finite differences over column groups, since each frame's parameters touch only its own
  residuals and three prior rows; the normal equations are small), warm started from the
  per-frame cameras (centre and k1: their medians; each frame's camera moved to that centre
  keeping its view; frames without a camera interpolated from their neighbours).

Frames with fewer keypoints than a per-frame calibration needs still get a camera: their own
observations and the prior place them. Everything here is pure (numpy / scipy, no I/O).

:func:`segment_shots` finds the cuts: a large image change between consecutive frames (when the
caller measured one, see :func:`image_change`), or per-frame cameras whose centres and views
jump (a different camera position), confirmed by the next frame.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, replace

import numpy as np
import scipy.optimize
import scipy.sparse

from pnlviz.field.model import FieldModel, load_field_model, pitch_grid
from pnlviz.geometry.camera import Camera, look_at_rotation, pan_tilt_roll_from_rotation

from .observations import Observations

__all__ = ["ClipCalibration", "ClipResult", "ShotFit", "TemporalParams", "calibrate_clip", "calibrate_clip_frames",
           "fit_shot", "image_change", "image_changes", "rotations", "segment_shots"]


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
    #: an image change above this makes a cut (see :func:`image_change`)
    cut_image: float = 0.025
    #: Levenberg-Marquardt iterations per solve
    max_iterations: int = 50


@dataclass
class ShotFit:
    cameras: list[Camera]
    C: np.ndarray
    k1: float
    #: per frame: pan, tilt, roll (radians), focal length (px)
    angles: np.ndarray
    focal: np.ndarray
    #: per frame: residuals (px) of the observations kept, and how many were dropped
    residuals: list[np.ndarray]
    dropped: list[int]
    cost: float
    nfev: int


# -- geometry, vectorised over frames ------------------------------------------------------------
def rotations(pan: np.ndarray, tilt: np.ndarray, roll: np.ndarray) -> np.ndarray:
    """(T, 3, 3) world -> camera rotations ``(Rz(pan) Rx(tilt) Rz(roll))^T`` (see
    :func:`pnlviz.geometry.camera.rotation_from_pan_tilt_roll`)."""
    cp, sp, ct, st, cr, sr = np.cos(pan), np.sin(pan), np.cos(tilt), np.sin(tilt), np.cos(roll), np.sin(roll)
    T = len(pan)
    o = np.empty((T, 3, 3))  # orientation Rz(pan) Rx(tilt) Rz(roll)
    o[:, 0, 0] = cp * cr - sp * ct * sr
    o[:, 0, 1] = -cp * sr - sp * ct * cr
    o[:, 0, 2] = sp * st
    o[:, 1, 0] = sp * cr + cp * ct * sr
    o[:, 1, 1] = -sp * sr + cp * ct * cr
    o[:, 1, 2] = -cp * st
    o[:, 2, 0] = st * sr
    o[:, 2, 1] = st * cr
    o[:, 2, 2] = ct
    return np.transpose(o, (0, 2, 1))


@dataclass
class _Data:
    """The observations of a shot, flattened: keypoints and line points with their frame index."""

    kp_t: np.ndarray  # (N,)
    kp_X: np.ndarray  # (N, 3)
    kp_xy: np.ndarray  # (N, 2)
    ln_t: np.ndarray  # (M,)
    ln_A: np.ndarray  # (M, 3) world ends of the line
    ln_B: np.ndarray
    ln_q: np.ndarray  # (M, 2) observed pixels


def _flatten(observations: Sequence[Observations | None], model: FieldModel) -> _Data:
    kt, kX, kx, lt, lA, lB, lq = [], [], [], [], [], [], []
    for t, obs in enumerate(observations):
        if obs is None:
            continue
        n = obs.n_keypoints
        kt.append(np.full(n, t))
        kX.append(obs.kp_xyz)
        kx.append(obs.kp_xy)
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

    return _Data(cat(kt, (0,)).astype(int), cat(kX, (0, 3)), cat(kx, (0, 2)), cat(lt, (0,)).astype(int),
                 cat(lA, (0, 3)), cat(lB, (0, 3)), cat(lq, (0, 2)))


def _subset(d: _Data, kp_keep: np.ndarray, ln_keep: np.ndarray) -> _Data:
    return _Data(d.kp_t[kp_keep], d.kp_X[kp_keep], d.kp_xy[kp_keep], d.ln_t[ln_keep], d.ln_A[ln_keep],
                 d.ln_B[ln_keep], d.ln_q[ln_keep])


class _Model:
    """The shot's residual function over the parameter vector
    ``[C (3), k1, pan_0, tilt_0, roll_0, logf_0, pan_1, ...]``."""

    def __init__(self, data: _Data, T: int, size: tuple[float, float], params: TemporalParams):
        self.d, self.T, self.params = data, T, params
        self.cx, self.cy = size[0] / 2.0, size[1] / 2.0
        self.prior_scale = np.array([math.radians(params.accel_deg)] * 3 + [params.accel_log_f])

    def unpack(self, x: np.ndarray):
        C, k1 = x[:3], (x[3] if self.params.fit_k1 else 0.0)
        per = x[4:].reshape(self.T, 4)
        return C, k1, per

    def data_residuals(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Keypoint residuals (N, 2) and line distances (M,), pixels."""
        d = self.d
        C, k1, per = self.unpack(x)
        R = rotations(per[:, 0], per[:, 1], per[:, 2])
        f = np.exp(per[:, 3])
        # keypoints
        Xc = np.einsum("nij,nj->ni", R[d.kp_t], d.kp_X - C)
        z = np.where(Xc[:, 2] > 1e-6, Xc[:, 2], 1e-6)
        xn = Xc[:, :2] / z[:, None]
        xd = xn * (1.0 + k1 * (xn * xn).sum(1))[:, None]
        fk = f[d.kp_t][:, None]
        r_kp = xd * fk + (self.cx, self.cy) - d.kp_xy
        # lines: undistort the observed points, then distance to the pinhole image of the 3D line
        fl = f[d.ln_t]
        qd = (d.ln_q - (self.cx, self.cy)) / fl[:, None]
        qu = qd.copy()
        for _ in range(4):  # fixed point of qd = qu (1 + k1 |qu|^2)
            qu = qd / (1.0 + k1 * (qu * qu).sum(1))[:, None]
        Rl = R[d.ln_t]
        a = np.einsum("nij,nj->ni", Rl, d.ln_A - C)
        b = np.einsum("nij,nj->ni", Rl, d.ln_B - C)
        l = np.cross(a, b)
        nrm = np.maximum(np.hypot(l[:, 0], l[:, 1]), 1e-12)
        r_ln = fl * (l[:, 0] * qu[:, 0] + l[:, 1] * qu[:, 1] + l[:, 2]) / nrm
        return r_kp, r_ln

    def residuals(self, x: np.ndarray) -> np.ndarray:
        r_kp, r_ln = self.data_residuals(x)
        per = self.unpack(x)[2]
        acc = (per[:-2] - 2 * per[1:-1] + per[2:]) / self.prior_scale if self.T >= 3 else np.zeros((0, 4))
        k1 = [x[3] / self.params.k1_sigma] if self.params.fit_k1 else []
        return np.concatenate([r_kp.ravel() / self.params.noise_px, r_ln / self.params.noise_px, acc.ravel(), k1])

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
        d, T = self.d, self.T
        n_kp, n_ln, n_acc = 2 * len(d.kp_t), len(d.ln_t), 4 * max(T - 2, 0)
        rows, cols = [], []
        shared = [0, 1, 2] + ([3] if self.params.fit_k1 else [])
        frame_of_row = np.concatenate([np.repeat(d.kp_t, 2), d.ln_t]).astype(int)
        n_data = n_kp + n_ln
        for c in shared:
            rows.append(np.arange(n_data))
            cols.append(np.full(n_data, c))
        for j in range(4):
            rows.append(np.arange(n_data))
            cols.append(4 + 4 * frame_of_row + j)
        for s in range(max(T - 2, 0)):  # prior row of the acceleration at s + 1: frames s, s+1, s+2
            for j in range(4):
                for t in (s, s + 1, s + 2):
                    rows.append(np.array([n_data + 4 * s + j]))
                    cols.append(np.array([4 + 4 * t + j]))
        n_k1 = 0
        if self.params.fit_k1:  # the k1 prior row
            rows.append(np.array([n_data + n_acc]))
            cols.append(np.array([3]))
            n_k1 = 1
        rows, cols = np.concatenate(rows), np.concatenate(cols)
        return scipy.sparse.csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(n_data + n_acc + n_k1, 4 + 4 * T))


def _initial(cameras: Sequence[Camera | None], T: int) -> tuple[np.ndarray, float, np.ndarray]:
    """Warm start: median centre and k1 of the per-frame cameras; per frame the angles and log f
    of its camera moved to that centre (:func:`_rebased`), unwrapped, with the frames that have no
    camera interpolated (held at the ends)."""
    known = [t for t in range(T) if cameras[t] is not None]
    if not known:
        raise ValueError("no frame of the shot has a camera to start from")
    C = np.median(np.array([cameras[t].C for t in known]), axis=0)
    k1 = float(np.median([cameras[t].radial[0] for t in known]))
    vals = np.array([_rebased(cameras[t], C) for t in known])
    vals[:, 0] = np.unwrap(vals[:, 0])
    vals[:, 2] = np.unwrap(vals[:, 2])
    per = np.column_stack([np.interp(np.arange(T), known, vals[:, j]) for j in range(4)])
    return C, k1, per


def _rebased(cam: Camera, C: np.ndarray) -> np.ndarray:
    """``[pan, tilt, roll, log f]`` of a camera at ``C`` that sees what ``cam`` sees at the image
    centre, as ``cam`` sees it: aimed at the same ground point, with the same roll about its axis
    and the focal length scaled by the ratio of distances (a per-frame camera found its own centre;
    its angles and focal length compensate for it)."""
    target = cam.back_project_to_ground(np.array([[cam.cx, cam.cy]]))[0]
    if not np.all(np.isfinite(target)) or np.linalg.norm(target - cam.C) > 500:
        target = cam.C + 60.0 * cam.R[2]  # looking above the horizon: a point on the optical axis
    R0 = look_at_rotation(cam.C, target)
    rel = cam.R @ R0.T  # = Rz(roll)^T for look_at's roll
    roll = math.atan2(rel[0, 1], rel[0, 0])
    R = look_at_rotation(C, target, roll)
    f = cam.fx * np.linalg.norm(target - C) / max(np.linalg.norm(target - cam.C), 1e-6)
    return np.array([*pan_tilt_roll_from_rotation(R), math.log(f)])


def _camera_vector(cam: Camera) -> np.ndarray:
    """``[C, k1, pan, tilt, roll, log f]`` of one camera (its x focal length)."""
    return np.concatenate([cam.C, [cam.radial[0]], pan_tilt_roll_from_rotation(cam.R), [math.log(cam.fx)]])


def _agreeing(data: _Data, cameras: Sequence[Camera | None], size, params: TemporalParams
              ) -> tuple[np.ndarray, np.ndarray]:
    """Masks of the keypoints and line points within ``start_outlier_px`` of their own frame's
    camera (every observation of a frame without one)."""
    kp_keep = np.ones(len(data.kp_t), bool)
    ln_keep = np.ones(len(data.ln_t), bool)
    one = replace(params, fit_k1=True)
    for t, cam in enumerate(cameras):
        if cam is None:
            continue
        k, l = data.kp_t == t, data.ln_t == t
        frame = _Data(np.zeros(k.sum(), int), data.kp_X[k], data.kp_xy[k], np.zeros(l.sum(), int), data.ln_A[l],
                      data.ln_B[l], data.ln_q[l])
        r_kp, r_ln = _Model(frame, 1, size, one).data_residuals(_camera_vector(cam))
        kp_keep[k] = np.hypot(r_kp[:, 0], r_kp[:, 1]) <= params.start_outlier_px
        ln_keep[l] = np.abs(r_ln) <= params.start_outlier_px
    return kp_keep, ln_keep


def _cameras(x: np.ndarray, model: _Model, size: tuple[float, float]) -> list[Camera]:
    C, k1, per = model.unpack(x)
    R = rotations(per[:, 0], per[:, 1], per[:, 2])
    radial = np.zeros(6)
    radial[0] = k1
    out = []
    for t in range(model.T):
        f = float(math.exp(per[t, 3]))
        out.append(Camera(f, f, size[0] / 2.0, size[1] / 2.0, R[t], C, float(size[0]), float(size[1]), radial))
    return out


def _jacobian(fun, x: np.ndarray, r0: np.ndarray, sparsity: scipy.sparse.csc_matrix,
              groups: list[np.ndarray]) -> scipy.sparse.csr_matrix:
    """Forward differences, one evaluation per group of columns with disjoint rows (the sparsity
    pattern says which rows each column touches)."""
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


@dataclass
class _Solution:
    x: np.ndarray
    cost: float
    nfev: int


def _solve(m: _Model, x: np.ndarray, params: TemporalParams) -> _Solution:
    """Robust Levenberg-Marquardt on the shot, by iteratively reweighted least squares: soft-L1
    weights ``1 / sqrt(1 + (r / s)^2)`` (``s = robust``), the normal equations of the weighted
    residuals with Marquardt's diagonal damping. The Jacobian is estimated by finite differences
    over groups of columns that share no residual (each frame's parameters touch only its own rows
    and three prior rows: ~16 evaluations whatever the shot's length); the normal matrix is small
    (4 per frame + 4 columns), so each step is one dense solve. (scipy's iterative trust-region
    solver needed hundreds of steps on the narrow valley that couples the centre's depth with the
    focal length; its exact one decomposes the whole Jacobian and is slow on long shots.)"""
    sparsity = m.sparsity().tocsc()
    groups = m.column_groups()
    s2 = params.robust ** 2

    def cost_of(r: np.ndarray) -> float:  # scipy's soft_l1 cost: 0.5 s^2 sum 2 (sqrt(1 + (r/s)^2) - 1)
        return float(np.sum(s2 * (np.sqrt(1.0 + r * r / s2) - 1.0)))

    r = m.residuals(x)
    cost, nfev, lam = cost_of(r), 1, 1e-3
    for _ in range(params.max_iterations):
        J = _jacobian(m.residuals, x, r, sparsity, groups)
        nfev += len(groups)
        w = 1.0 / np.sqrt(1.0 + r * r / s2)
        Jw = scipy.sparse.diags(np.sqrt(w)) @ J
        A = (Jw.T @ Jw).toarray()
        g = Jw.T @ (np.sqrt(w) * r)
        d = np.maximum(np.diag(A), 1e-12)
        improved = False
        for _ in range(12):
            try:
                dx = -np.linalg.solve(A + lam * np.diag(d), g)
            except np.linalg.LinAlgError:
                lam *= 10
                continue
            x_new = x + dx
            r_new = m.residuals(x_new)
            nfev += 1
            c_new = cost_of(r_new) if np.all(np.isfinite(r_new)) else np.inf
            if c_new < cost:
                improved = True
                break
            lam *= 4
        if not improved:
            break
        step = np.linalg.norm(dx) / (np.linalg.norm(x) + 1e-12)
        gain = (cost - c_new) / max(cost, 1e-12)
        x, r, cost, lam = x_new, r_new, c_new, max(lam / 3, 1e-9)
        if step < 1e-10 or gain < 1e-10:
            break
    return _Solution(x, cost, nfev)


def fit_shot(observations: Sequence[Observations | None], cameras: Sequence[Camera | None],
             size: tuple[float, float], params: TemporalParams = TemporalParams(),
             model: FieldModel | None = None) -> ShotFit:
    """The broadcast camera of one shot (see the module docstring): ``observations[t]`` and the
    per-frame ``cameras[t]`` (None where a frame has none) of its T frames, in time order, for
    images of ``size`` (W, H). Returns a camera for every frame."""
    model = model or load_field_model()
    T = len(observations)
    if len(cameras) != T:
        raise ValueError("one camera (or None) per frame")
    data = _flatten(observations, model)
    C0, k10, per0 = _initial(cameras, T)
    if not params.fit_k1:
        k10 = 0.0
    x = np.concatenate([C0, [k10], per0.ravel()])
    nfev = 0
    # start from the observations each frame's own camera agrees with (all of a frame without one):
    # a detector's wrong ids and lines would otherwise pull the first solve off
    kp_keep, ln_keep = _agreeing(data, cameras, size, params)
    for _ in range(3):
        m = _Model(_subset(data, kp_keep, ln_keep), T, size, params)
        sol = _solve(m, x, params)
        x, nfev = sol.x, nfev + sol.nfev
        # then those the shot's camera agrees with, until the set stops changing
        r_kp, r_ln = _Model(data, T, size, params).data_residuals(x)
        new_kp = np.hypot(r_kp[:, 0], r_kp[:, 1]) <= params.outlier_px
        new_ln = np.abs(r_ln) <= params.outlier_px
        if np.array_equal(new_kp, kp_keep) and np.array_equal(new_ln, ln_keep):
            break
        kp_keep, ln_keep = new_kp, new_ln
    final = _Model(data, T, size, params)
    r_kp, r_ln = final.data_residuals(x)
    res, dropped = [], []
    for t in range(T):
        k = (data.kp_t == t)
        l = (data.ln_t == t)
        res.append(np.concatenate([np.hypot(r_kp[k & kp_keep, 0], r_kp[k & kp_keep, 1]), np.abs(r_ln[l & ln_keep])]))
        dropped.append(int((k & ~kp_keep).sum() + (l & ~ln_keep).sum()))
    C, k1, per = final.unpack(x)
    return ShotFit(_cameras(x, final, size), C.copy(), float(k1), per[:, :3].copy(), np.exp(per[:, 3]), res, dropped,
                   float(sol.cost), nfev)


# -- shots ---------------------------------------------------------------------------------------
def image_change(a: np.ndarray, b: np.ndarray) -> float:
    """How different two consecutive frames look, 0 (same) .. 1: the mean absolute difference of
    their 32x18 grey thumbnails, in units of full scale. Within a shot the thumbnails barely move
    (grass is uniform, a pan shifts them by a fraction of a thumbnail pixel): 0.002-0.007 on
    synthetic clips; a cut replaces them: 0.04-0.11 there."""
    import cv2

    def thumb(img: np.ndarray) -> np.ndarray:
        grey = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY) if img.ndim == 3 else img
        return cv2.resize(grey, (32, 18), interpolation=cv2.INTER_AREA).astype(np.float32)

    return float(np.mean(np.abs(thumb(a) - thumb(b))) / 255.0)


_GRID = pitch_grid(5.0)


def _view_change(a: Camera, b: Camera) -> float:
    """Median displacement (pixels of ``a``) of the pitch grid points both cameras see (inf when
    they see none in common)."""
    pa, _ = a.project(_GRID)
    pb, _ = b.scaled(a.width, a.height).project(_GRID)
    seen = a.in_image(pa) & np.all(np.isfinite(pb), 1)
    return float(np.median(np.linalg.norm(pa[seen] - pb[seen], axis=1))) if seen.any() else math.inf


def segment_shots(cameras: Sequence[Camera | None], changes: Sequence[float | None] | None = None,
                  params: TemporalParams = TemporalParams()) -> list[range]:
    """Cut a clip into shots: ``range`` objects covering ``0 .. len(cameras) - 1`` in order. A cut
    falls before frame t when ``changes[t - 1]`` (the image change from t - 1 to t) exceeds
    ``cut_image``, or when frame t's per-frame camera is apart from the current shot (its centre
    farther than ``cut_centre_m`` from the median of the shot's last five centres, and its view of
    the pitch moved by more than ``cut_view`` of the image width from the shot's latest camera)
    *and* so is the next calibrated frame (one wrong per-frame camera is an outlier, not a cut).
    Frames without a camera never cut."""
    T = len(cameras)
    if T == 0:
        return []
    calibrated = [t for t in range(T) if cameras[t] is not None]
    cuts: list[int] = []
    centres: list[np.ndarray] = []
    last: Camera | None = None  # the shot's latest camera that was not an outlier

    def apart(a: Camera, b: Camera, ref: np.ndarray) -> bool:
        return (float(np.linalg.norm(a.C - ref)) > params.cut_centre_m
                and _view_change(a, b) > params.cut_view * a.width)

    for t in range(T):
        if t > 0 and changes is not None and changes[t - 1] is not None and changes[t - 1] > params.cut_image:
            cuts.append(t)
            centres = []
        cam = cameras[t]
        if cam is None:
            continue
        C = np.asarray(cam.C, float)
        if centres and last is not None:
            ref = np.median(np.array(centres[-5:]), axis=0)
            if apart(cam, last, ref):
                later = [u for u in calibrated if u > t][:1]
                confirmed = bool(later) and apart(cameras[later[0]], last, ref)
                if not confirmed:
                    continue  # an outlier frame: it neither cuts nor moves the reference
                if not cuts or cuts[-1] != t:
                    cuts.append(t)
                centres = []
        centres.append(C)
        last = cam
    bounds = [0, *sorted(set(c for c in cuts if 0 < c < T)), T]
    return [range(a, b) for a, b in zip(bounds[:-1], bounds[1:]) if b > a]


@dataclass
class ClipResult:
    #: per frame: the shot's camera, or None (a shot without any per-frame camera to start from)
    cameras: list[Camera | None]
    #: per frame: index of its shot
    shot_of: list[int]
    shots: list[range]
    fits: list[ShotFit | None]


def calibrate_clip(observations: Sequence[Observations | None], cameras: Sequence[Camera | None],
                   size: tuple[float, float], params: TemporalParams = TemporalParams(),
                   changes: Sequence[float | None] | None = None, model: FieldModel | None = None) -> ClipResult:
    """A clip in time order: its shots (:func:`segment_shots`), and in each shot that has at least
    one per-frame camera the broadcast camera (:func:`fit_shot`) of every frame that has
    observations (frames with none keep no camera)."""
    model = model or load_field_model()
    T = len(observations)
    shots = segment_shots(cameras, changes, params)
    out: list[Camera | None] = [None] * T
    shot_of = [0] * T
    fits: list[ShotFit | None] = []
    for k, shot in enumerate(shots):
        for t in shot:
            shot_of[t] = k
        if all(cameras[t] is None for t in shot):
            fits.append(None)
            continue
        fit = fit_shot([observations[t] for t in shot], [cameras[t] for t in shot], size, params, model)
        fits.append(fit)
        for t, cam in zip(shot, fit.cameras):
            if observations[t] is not None:
                out[t] = cam
    return ClipResult(out, shot_of, shots, fits)


def image_changes(images: Iterable[np.ndarray | None]) -> list[float | None]:
    """:func:`image_change` from each frame to the next (one value fewer than frames; None where
    either frame is missing), the ``changes`` of :func:`calibrate_clip`. ``images`` may be a
    generator: two frames are held at a time."""
    out: list[float | None] = []
    prev, first = None, True
    for img in images:
        if not first:
            out.append(image_change(prev, img) if prev is not None and img is not None else None)
        prev, first = img, False
    return out


@dataclass
class ClipCalibration:
    #: per frame: its own camera (None without one), its observations (None without input)
    per_frame: list[Camera | None]
    observations: list[Observations | None]
    result: ClipResult


def calibrate_clip_frames(inputs: Sequence[object | None], settings: object, *,
                          cameras: Sequence[Camera | None] | None = None,
                          changes: Sequence[float | None] | None = None,
                          model: FieldModel | None = None) -> ClipCalibration:
    """A clip as ``pnlviz calibrate --temporal`` calibrates it: ``inputs`` are the frames'
    :class:`pnlviz.calib.frame.FrameInputs` in time order (None: unreadable), all of one size, and
    ``settings`` their :class:`~pnlviz.calib.frame.FrameSettings`. The per-frame cameras (computed
    with :func:`~pnlviz.calib.frame.calibrate_frame` unless given), the frames' observations, and
    :func:`calibrate_clip` with the shot's lens fitted the way the frames' calibration fits it (no
    k1 for detections whose detector says ``refine_k1: false``)."""
    from .frame import calib_params, calibrate_frame, observations_for

    model = model or load_field_model()
    sizes = {tuple(i.size) for i in inputs if i is not None}
    if len(sizes) != 1:
        raise ValueError("the frames of a clip must have one size")
    if cameras is None:
        cameras = []
        for i in inputs:
            fc = calibrate_frame(i, settings, model) if i is not None else None
            cameras.append(fc.result.camera if fc is not None and fc.ok else None)
    found = [observations_for(i, settings.source, model) if i is not None else (None, None) for i in inputs]
    origin = next((g for _, g in found if g is not None), None)
    params = TemporalParams(fit_k1=calib_params(settings, origin).refine_k1)
    obs = [o for o, _ in found]
    result = calibrate_clip(obs, list(cameras), sizes.pop(), params, changes=changes, model=model)
    return ClipCalibration(list(cameras), obs, result)
