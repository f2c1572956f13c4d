"""One broadcast camera per shot, fitted to the frames' observations (the model:
:mod:`pnlviz.calib.shot`).

* **warm start** from the per-frame cameras: centre and k1 their medians; each frame's camera
  moved to that centre keeping its view; frames without a camera interpolated from their
  neighbours;
* **robust**: the first solve uses the observations that their frame's own camera agrees with
  (within ``start_outlier_px``; all of a frame that has none), then the ones the shot's camera
  agrees with, until that set stops changing (outlier detections, wrong ids, outlier frames); and
  a soft-L1 loss on every residual (``robust``, in units of the residual's scale);
* **solved jointly** by the one Levenberg-Marquardt solver (:mod:`pnlviz.calib.solver`) on the
  whole shot, with the model's Jacobian by grouped finite differences (the normal equations are
  small: 4 per frame + 4 columns). (scipy's iterative trust-region solver needed hundreds of steps
  on the narrow valley that couples the centre's depth with the focal length; its exact one
  decomposes the whole Jacobian and is slow on long shots.)

Frames with fewer keypoints than a per-frame calibration needs still get a camera: their own
observations and the prior place them. Everything here is pure (numpy / scipy, no I/O).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from pnlviz.field.model import FieldModel, load_field_model
from pnlviz.geometry.camera import Camera, look_at_rotation, pan_tilt_roll_from_rotation, rotation_from_pan_tilt_roll

from .observations import Observations
from .shot import ShotData, ShotModel, TemporalParams, flatten, jacobian
from .solver import SolverParams, levenberg_marquardt

__all__ = ["ShotFit", "camera_vector", "fit_shot"]

#: the relative decrease of the cost a solve from a previous solution stops at (1e-10 from the
#: per-frame cameras): the cameras it gives differ by hundredths of a pixel
WARM_TOL = 1e-6
#: ... and its iterations at most (the page waits for it: the next edit goes on from where it is)
WARM_ITERATIONS = 15


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


def initial(cameras: Sequence[Camera | None], T: int) -> tuple[np.ndarray, float, np.ndarray]:
    """Warm start: median centre and k1 of the per-frame cameras; per frame the angles and log f
    of its camera moved to that centre (:func:`_rebased`), unwrapped, with the frames that have no
    camera interpolated (held at the ends)."""
    found = [(t, cam) for t in range(T) if (cam := cameras[t]) is not None]
    if not found:
        raise ValueError("no frame of the shot has a camera to start from")
    known = [t for t, _ in found]
    C = np.median(np.array([cam.C for _, cam in found]), axis=0)
    k1 = float(np.median([cam.radial[0] for _, cam in found]))
    vals = np.array([_rebased(cam, C) for _, cam in found])
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
    f = cam.fx * np.linalg.norm(target - C) / max(float(np.linalg.norm(target - cam.C)), 1e-6)
    return np.array([*pan_tilt_roll_from_rotation(R), math.log(f)])


def camera_vector(cam: Camera) -> np.ndarray:
    """``[C, k1, pan, tilt, roll, log f]`` of one camera (its x focal length)."""
    return np.concatenate([cam.C, [cam.radial[0]], pan_tilt_roll_from_rotation(cam.R), [math.log(cam.fx)]])


def _agreeing(data: ShotData, cameras: Sequence[Camera | None], size, params: TemporalParams
              ) -> tuple[np.ndarray, np.ndarray]:
    """Masks of the keypoints and line points within ``start_outlier_px`` of their own frame's
    camera (every observation of a frame without one)."""
    kp_keep = np.ones(len(data.kp_t), bool)
    ln_keep = np.ones(len(data.ln_t), bool)
    one = replace(params, fit_k1=True)
    for t, cam in enumerate(cameras):
        if cam is None:
            continue
        r_kp, r_ln = ShotModel(data.frame(t), 1, size, one).data_residuals(camera_vector(cam))
        mine = data.kp_t == t
        kp_keep[mine] = (np.hypot(r_kp[:, 0], r_kp[:, 1]) <= params.start_outlier_px) | data.kp_pin[mine]
        ln_keep[data.ln_t == t] = np.abs(r_ln) <= params.start_outlier_px
    return kp_keep, ln_keep


def _cameras(x: np.ndarray, model: ShotModel, size: tuple[float, float]) -> list[Camera]:
    C, k1, per = model.unpack(x)
    R = rotation_from_pan_tilt_roll(per[:, 0], per[:, 1], per[:, 2])
    radial = np.zeros(6)
    radial[0] = k1
    out = []
    for t in range(model.T):
        f = float(math.exp(per[t, 3]))
        out.append(Camera(f, f, size[0] / 2.0, size[1] / 2.0, R[t], C, float(size[0]), float(size[1]), radial))
    return out


def _solve(m: ShotModel, x: np.ndarray, params: TemporalParams, tol: float = 1e-10) -> tuple[np.ndarray, float, int]:
    """The shot solved from ``x`` by the one solver, soft-L1 (``robust``), its Jacobian by grouped
    finite differences at accepted steps only. Returns the solution, its cost and the number of
    evaluations of the residuals. ``tol``: the relative decrease of the cost to stop at."""
    sparsity = m.sparsity().tocsc()
    groups = m.column_groups()
    nfev = 0

    def evaluate(x: np.ndarray, jac: bool):
        nonlocal nfev
        nfev += 1
        return m.residuals(x), None

    def derivative(x: np.ndarray, r: np.ndarray):
        nonlocal nfev
        nfev += len(groups)
        return jacobian(m.residuals, x, r, sparsity, groups)

    solver = SolverParams(loss="soft_l1", f_scale=params.robust, max_iter=params.max_iterations, tol=tol,
                          step_tol=1e-10 * float(np.linalg.norm(x)), max_trials=12)
    x, info = levenberg_marquardt(evaluate, lambda x, dx: x + dx, x, solver, jacobian=derivative)
    return x, float(info["cost"]), nfev


def _start_vector(start: ShotFit, T: int) -> np.ndarray:
    """The parameter vector of a previous solution of the same shot (``T`` frames)."""
    if len(start.cameras) != T:
        raise ValueError(f"a warm start needs a solution of the same {T} frames, got {len(start.cameras)}")
    per = np.column_stack([start.angles, np.log(start.focal)])
    return np.concatenate([start.C, [start.k1], per.ravel()])


def fit_shot(observations: Sequence[Observations | None], cameras: Sequence[Camera | None],
             size: tuple[float, float], params: TemporalParams = TemporalParams(),
             model: FieldModel | None = None, start: ShotFit | None = None) -> ShotFit:
    """The broadcast camera of one shot (see the module docstring): ``observations[t]`` and the
    per-frame ``cameras[t]`` (None where a frame has none) of its T frames, in time order, for
    images of ``size`` (W, H). Returns a camera for every frame. Pinned keypoints (placed or moved
    by hand, ``Observations.kp_pinned``) weigh ``pin_weight`` times more and are never dropped.

    ``start``: a previous solution of the same shot (warm start, after an edit): the solve starts
    from it, with the observations it agrees with, instead of from the per-frame cameras."""
    model = model or load_field_model()
    T = len(observations)
    if len(cameras) != T:
        raise ValueError("one camera (or None) per frame")
    data = flatten(observations, model)
    whole = ShotModel(data, T, size, params)
    if start is not None:
        x = _start_vector(start, T)
        kp_keep, ln_keep = _kept(whole, x, params)
    else:
        C0, k10, per0 = initial(cameras, T)
        x = np.concatenate([C0, [k10 if params.fit_k1 else 0.0], per0.ravel()])
        # start from the observations each frame's own camera agrees with (all of a frame without one):
        # a detector's wrong ids and lines would otherwise pull the first solve off
        kp_keep, ln_keep = _agreeing(data, cameras, size, params)
    nfev = 0
    # from a previous solution an edit moves the cameras a little: a looser stop is as good
    tol = WARM_TOL if start is not None else 1e-10
    if start is not None:
        params = replace(params, max_iterations=min(params.max_iterations, WARM_ITERATIONS))
    for _ in range(3):
        x, cost, n = _solve(ShotModel(data.subset(kp_keep, ln_keep), T, size, params), x, params, tol)
        nfev += n
        # then those the shot's camera agrees with, until the set stops changing
        new_kp, new_ln = _kept(whole, x, params)
        if np.array_equal(new_kp, kp_keep) and np.array_equal(new_ln, ln_keep):
            break
        kp_keep, ln_keep = new_kp, new_ln
    r_kp, r_ln = whole.data_residuals(x)
    res, dropped = [], []
    for t in range(T):
        k, l = data.kp_t == t, data.ln_t == t
        res.append(np.concatenate([np.hypot(r_kp[k & kp_keep, 0], r_kp[k & kp_keep, 1]), np.abs(r_ln[l & ln_keep])]))
        dropped.append(int((k & ~kp_keep).sum() + (l & ~ln_keep).sum()))
    C, k1, per = whole.unpack(x)
    return ShotFit(_cameras(x, whole, size), C.copy(), float(k1), per[:, :3].copy(), np.exp(per[:, 3]), res, dropped,
                   cost, nfev)


def _kept(whole: ShotModel, x: np.ndarray, params: TemporalParams) -> tuple[np.ndarray, np.ndarray]:
    """Masks of the observations within ``outlier_px`` of the shot's camera ``x``, and every pin."""
    r_kp, r_ln = whole.data_residuals(x)
    return (np.hypot(r_kp[:, 0], r_kp[:, 1]) <= params.outlier_px) | whole.d.kp_pin, np.abs(r_ln) <= params.outlier_px
