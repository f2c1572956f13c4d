"""One broadcast camera per shot, fitted to the frames' observations (the model:
:mod:`pnlviz.calib.shot`).

* **warm start** from the per-frame cameras: centre and k1 their medians; each frame's camera
  moved to that centre keeping its view; frames without a camera interpolated from their
  neighbours;
* **robust**: the first solve uses the observations that their frame's own camera agrees with
  (within ``start_outlier_px``; all of a frame that has none), then the ones the shot's camera
  agrees with by the frame pipeline's PnL gates (a keypoint within ``point_gate_px``, a line or
  circle when all its points are within ``line_gate_px``), until that set stops changing; and a
  soft-L1 loss on every residual but the pins' (``robust``, in units of the noise; a pin bounds its
  own loss);
* **solved jointly** by the one Levenberg-Marquardt solver (:mod:`pnlviz.calib.solver`) on the
  whole shot, with the model's analytic sparse Jacobian (the normal equations are small: 4 per
  frame + 4 columns).

Frames with fewer keypoints than a per-frame calibration needs still get a camera: their own
observations and the prior place them. Whether each frame should use it is decided afterwards,
against its own camera (:mod:`pnlviz.calib.shot_check`). Everything here is pure (numpy / scipy,
no I/O).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from pnlviz.field.model import FieldModel, load_field_model
from pnlviz.geometry.camera import Camera, look_at_rotation, pan_tilt_roll_from_rotation

from .calibrate import CalibParams
from .models import CameraModel
from .observations import Observations
from .problem import FrameData, Problem
from .shot import FrameDistances, Selection, ShotProblem, TemporalParams, frame_data
from .solver import SolverParams, levenberg_marquardt

__all__ = ["WINDOW_RADIUS", "ShotFit", "camera_vector", "distances", "fit_shot", "fit_window", "window_of"]

#: the relative decrease of the cost a solve from a previous solution stops at (1e-10 from the
#: per-frame cameras): the cameras it gives differ by hundredths of a pixel
WARM_TOL = 1e-6
#: ... and its iterations at most (the page waits for it: the next edit goes on from where it is)
WARM_ITERATIONS = 15
#: the frames an edit's quick solve frees on either side of the edited one (:func:`fit_window`:
#: half a second at 25 fps)
WINDOW_RADIUS = 12
#: frames held at each end of that window: the motion prior reads three frames in a row, so two
#: held frames carry it across the window's ends
_HELD = 2


@dataclass
class ShotFit:
    cameras: list[Camera]
    C: np.ndarray
    k1: float
    #: per frame: pan, tilt, roll (radians), focal length (px)
    angles: np.ndarray
    focal: np.ndarray
    #: per frame: distances (px) of the observations kept, and how many were left out
    residuals: list[np.ndarray]
    dropped: list[int]
    cost: float
    nfev: int
    #: the solver stopped at a minimum (not at its iteration limit, nor with no descent at all)
    converged: bool = True
    #: per frame: the observations the solve used
    selections: list[Selection | None] | None = None
    #: per frame: how far its shot camera puts each of its observations
    distances: list[FrameDistances | None] | None = None
    #: a quick answer around an edit (:func:`fit_window`), not yet a solve of the whole shot
    provisional: bool = False


def distances(data: FrameData, cam: Camera) -> FrameDistances:
    """:class:`FrameDistances` of ``cam`` on a frame (the frame pipeline's distances: the same
    problem, unweighted)."""
    model = CameraModel(cam, True, True, k1_bound=10.0)
    p = Problem(model, data)
    state = model.start()
    obs = data.obs
    kp = np.zeros(0)
    if obs.n_keypoints:
        uv, _ = model.project(obs.kp_xyz, state)
        kp = np.hypot(*(uv - obs.kp_xy).T)
        kp = np.where(np.isfinite(kp), kp, math.inf)
    per_class = p.class_distances(state)
    classes = {k: (float(np.max(v)) if len(v) else 0.0) for k, v in per_class.items()}
    rss = float(np.sum(np.square(kp))) + sum(float(np.sum(np.square(v))) for v in per_class.values())
    return FrameDistances(kp, classes, rss, 2 * len(kp) + sum(len(v) for v in per_class.values()))


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


def _solve(m: ShotProblem, x: np.ndarray, params: TemporalParams, tol: float,
           free: np.ndarray | None = None, exact: bool = False) -> tuple[np.ndarray, dict]:
    """The shot solved from ``x`` by the one solver, soft-L1 (``robust``) but on the pins
    (:meth:`ShotProblem.loss_bends`); ``free``: a mask of the parameters it may change (None: all),
    the others hold their value in ``x``; ``exact``: steps on the loss's own curvature
    (:attr:`pnlviz.calib.solver.SolverParams.exact_curvature`)."""
    solver = SolverParams(loss="soft_l1", f_scale=m.loss_bends(params.robust), max_iter=params.max_iterations, tol=tol,
                          step_tol=1e-10 * float(np.linalg.norm(x)), max_trials=12, exact_curvature=exact)
    if free is None:
        return levenberg_marquardt(m.evaluate, lambda x, dx: x + dx, x, solver)
    held = x.copy()

    def evaluate(y: np.ndarray, jac: bool = False):
        full = held.copy()
        full[free] = y
        r, J = m.evaluate(full, jac)
        return r, (None if J is None else J[:, free])

    y, info = levenberg_marquardt(evaluate, lambda y, dy: y + dy, x[free], solver)
    out = held.copy()
    out[free] = y
    return out, info


def _gated_solve(fd: Sequence[FrameData | None], size: tuple[float, float], params: TemporalParams,
                 calib: CalibParams, x: np.ndarray, sel: list[Selection | None], tol: float,
                 free: np.ndarray | None = None, exact: bool = False
                 ) -> tuple[np.ndarray, list[Selection | None], list, dict, ShotProblem]:
    """Solve from ``x`` with the observations ``sel``, then with those the shot's camera puts within
    the PnL gates, until that set stops changing (three solves at most). Returns ``x``, the
    selections, the frames' distances (everything selected), the last solve's info with the
    iterations of all of them, and the problem with everything selected (its cameras)."""
    W = float(size[0])
    point_gate, line_gate = calib.px(calib.point_gate_px, W), calib.px(calib.line_gate_px, W)
    whole = ShotProblem(fd, size, params, alpha=calib.alpha)
    nfev, info = 0, {"success": False, "cost": math.inf, "iterations": 0}
    dist: list[FrameDistances | None] = []
    for _ in range(3):
        x, info = _solve(whole.restricted(sel), x, params, tol, free, exact)
        nfev += int(info["iterations"])
        dist = whole.distances(x)
        new = _gated(fd, dist, point_gate, line_gate, calib)
        if _same(new, sel):
            break
        sel = new
    return x, sel, dist, {**info, "iterations": nfev}, whole


def _kept(fd: Sequence[FrameData | None], sel: Sequence[Selection | None],
          dist: Sequence[FrameDistances | None]) -> tuple[list[np.ndarray], list[int]]:
    """Per frame, the distances of the observations kept, and how many were left out."""
    res, dropped = [], []
    for d, s, m in zip(fd, sel, dist):
        if d is None or s is None or m is None:
            res.append(np.zeros(0))
            dropped.append(0)
            continue
        res.append(m.kept(s))
        dropped.append(d.obs.n_keypoints + len(d.obs.lines) + len(d.obs.circles) - s.size - s.left_out)
    return res, dropped


def _start_vector(start: ShotFit, T: int) -> np.ndarray:
    """The parameter vector of a previous solution of the same shot (``T`` frames)."""
    if len(start.cameras) != T:
        raise ValueError(f"a warm start needs a solution of the same {T} frames, got {len(start.cameras)}")
    per = np.column_stack([start.angles, np.log(start.focal)])
    return np.concatenate([start.C, [start.k1], per.ravel()])


def _select(m: FrameDistances, d: FrameData, point_gate: float, line_gate: float, calib: CalibParams) -> Selection:
    """What a shot's solve fits of frame ``d`` at distances ``m``: :meth:`FrameDistances.selection`
    with the frame's model's points no paint marks."""
    return m.selection(d.obs, point_gate, line_gate, calib, d.model.unmarked_points())


def _selections(data: Sequence[FrameData | None], cameras: Sequence[Camera | None], point_gate: float,
                line_gate: float, calib: CalibParams) -> list[Selection | None]:
    """Per frame, the observations ``cameras[t]`` (its own camera) puts within the gates
    (everything of a frame without a camera; ``calib``: :meth:`FrameDistances.selection`)."""
    out: list[Selection | None] = []
    for d, cam in zip(data, cameras):
        if d is None:
            out.append(None)
        elif cam is None:
            out.append(Selection.everything(d.obs))
        else:
            out.append(_select(distances(d, cam), d, point_gate, line_gate, calib))
    return out


def _gated(data: Sequence[FrameData | None], dist: Sequence[FrameDistances | None], point_gate: float,
           line_gate: float, calib: CalibParams) -> list[Selection | None]:
    """Per frame, the observations the shot's camera puts within the gates (``dist``:
    :meth:`ShotProblem.distances` with everything selected)."""
    return [None if d is None or m is None
            else _select(m, d, point_gate, line_gate, calib)
            for d, m in zip(data, dist)]


def _kept_selections(data: Sequence[FrameData | None], old: Sequence[Selection | None], cameras: Sequence[Camera],
                     point_gate: float, line_gate: float, calib: CalibParams) -> list[Selection | None]:
    """The observations a warm solve starts with: the previous solve's (``old``, with its
    ``cameras``), but for the frames whose observations changed since (an edit), gated anew
    against their camera of that solve."""
    out: list[Selection | None] = []
    for d, s, cam in zip(data, old, cameras):
        fits = (d is None and s is None) or (d is not None and s is not None and s.keypoints.shape == (d.obs.n_keypoints,)
                                             and set(s.lines) <= set(d.obs.lines)
                                             and set(s.circles) <= set(d.obs.circles)
                                             and not (d.obs.pins & ~s.keypoints).any())
        out.append(s if fits else None if d is None
                   else _select(distances(d, cam), d, point_gate, line_gate, calib))
    return out


def _same(a: Sequence[Selection | None], b: Sequence[Selection | None]) -> bool:
    return all((x is None and y is None) or (x is not None and y is not None and x.same(y)) for x, y in zip(a, b))


def fit_shot(observations: Sequence[Observations | None], cameras: Sequence[Camera | None],
             size: tuple[float, float], params: TemporalParams = TemporalParams(),
             model: FieldModel | None = None, start: ShotFit | None = None,
             calib: CalibParams = CalibParams(), data: Sequence[FrameData | None] | None = None) -> ShotFit:
    """The broadcast camera of one shot (see the module docstring): ``observations[t]`` and the
    per-frame ``cameras[t]`` (None where a frame has none) of its T frames, in time order, for
    images of ``size`` (W, H). Returns a camera for every frame. Pinned keypoints (placed or moved
    by hand, ``Observations.kp_pinned``) weigh ``pin_weight`` times more and are never dropped.
    ``calib``: the frames' calibration settings (``alpha``, the PnL gates).

    ``start``: a previous solution of the same shot (warm start, after an edit): the solve starts
    from it, with the observations it agrees with, instead of from the per-frame cameras.
    ``data``: the frames' :func:`~pnlviz.calib.shot.frame_data` when the caller keeps it."""
    model = model or load_field_model()
    T = len(observations)
    if len(cameras) != T:
        raise ValueError("one camera (or None) per frame")
    fd = list(data) if data is not None else frame_data(observations, model)
    W = float(size[0])
    point_gate, line_gate = calib.px(calib.point_gate_px, W), calib.px(calib.line_gate_px, W)
    if start is not None:
        x = _start_vector(start, T)
        sel = _kept_selections(fd, start.selections or [None] * T, start.cameras, point_gate, line_gate, calib)
        params = replace(params, max_iterations=min(params.max_iterations, WARM_ITERATIONS))
        tol = WARM_TOL  # from a previous solution an edit moves the cameras a little: a looser stop is as good
    else:
        C0, k10, per0 = initial(cameras, T)
        x = np.concatenate([C0, [k10 if params.fit_k1 else 0.0], per0.ravel()])
        # start from the observations each frame's own camera agrees with (all of a frame without
        # one): a detector's wrong ids and lines would otherwise pull the first solve off
        gate = calib.px(params.start_outlier_px, W)
        sel = _selections(fd, cameras, gate, gate, calib)
        tol = 1e-10
    x, sel, dist, info, whole = _gated_solve(fd, size, params, calib, x, sel, tol)
    res, dropped = _kept(fd, sel, dist)
    C, k1, per = whole.unpack(x)
    return ShotFit(whole.cameras(x), C.copy(), float(k1), per[:, :3].copy(), np.exp(per[:, 3]), res, dropped,
                   float(info["cost"]), int(info["iterations"]), bool(info["success"]), sel, dist)


def window_of(i: int, T: int, radius: int = WINDOW_RADIUS) -> range:
    """The frames of a ``T``-frame shot an edit on its frame ``i`` frees in :func:`fit_window`."""
    return range(max(0, i - radius), min(T, i + radius + 1))


def fit_window(data: Sequence[FrameData | None], start: ShotFit, i: int, size: tuple[float, float],
               params: TemporalParams = TemporalParams(), calib: CalibParams = CalibParams(),
               radius: int = WINDOW_RADIUS) -> ShotFit:
    """Shot ``start`` solved again after an edit on its frame ``i``, around that frame only: the
    frames of :func:`window_of` are free, the others and the shot's centre and k1 hold their
    values of ``start`` (two held frames each side carry the motion prior across the window's
    ends). ``data``: the shot's :func:`~pnlviz.calib.shot.frame_data`, the edit in it.

    An edit moves the frames near it most and the shot's shared centre a little: on a 250-frame
    synthetic shot with every marking this lands within 0.25 px of the full solve (:func:`fit_shot`
    from ``start``) in 25-40 ms against 150-230 ms (``benchmarks/bench_clip_browser.py``); where a
    pin moves the centre (few keypoints a frame) it is a few pixels off on the frames it holds. A
    provisional answer to draw at once while the full solve runs; its ``cost`` is ``start``'s.
    Its steps take the loss's own curvature (:attr:`~pnlviz.calib.solver.SolverParams.exact_curvature`):
    a pin pulling against a clean shot's observations takes residuals past the bend, where the
    reweighted steps crawled (15 iterations, the limit, 1.3 px short of the full solve on the frame 5
    on; now 4-7, within 0.2 px, 0.5 where the pin moves the shared centre)."""
    T = len(data)
    if len(start.cameras) != T:
        raise ValueError(f"a window of a solution of the same {T} frames, got {len(start.cameras)}")
    free_frames = window_of(i, T, radius)
    a, b = max(0, free_frames.start - _HELD), min(T, free_frames.stop + _HELD)
    W = float(size[0])
    point_gate, line_gate = calib.px(calib.point_gate_px, W), calib.px(calib.line_gate_px, W)
    sel = _kept_selections(data[a:b], (start.selections or [None] * T)[a:b], start.cameras[a:b],  # the window's only
                           point_gate, line_gate, calib)
    x0 = _start_vector(start, T)
    x = np.concatenate([x0[:4], x0[4 + 4 * a:4 + 4 * b]])
    free = np.zeros(len(x), bool)
    free[4 + 4 * (free_frames.start - a):4 + 4 * (free_frames.stop - a)] = True
    params = replace(params, max_iterations=min(params.max_iterations, WARM_ITERATIONS))
    fd = list(data[a:b])
    x, sel, dist, info, m = _gated_solve(fd, size, params, calib, x, sel, WARM_TOL, free, exact=True)
    _, _, per = m.unpack(x)
    res, dropped = _kept(fd, sel, dist)
    cameras, angles, focal = list(start.cameras), start.angles.copy(), start.focal.copy()
    selections = list(start.selections or [None] * T)
    distances_ = list(start.distances or [None] * T)
    residuals, dropped_ = list(start.residuals), list(start.dropped)
    cameras[a:b], selections[a:b], distances_[a:b], residuals[a:b], dropped_[a:b] = m.cameras(x), sel, dist, res, dropped
    angles[a:b], focal[a:b] = per[:, :3], np.exp(per[:, 3])
    return replace(start, cameras=cameras, angles=angles, focal=focal, residuals=residuals, dropped=dropped_,
                   nfev=int(info["iterations"]), converged=start.converged and bool(info["success"]),
                   selections=selections, distances=distances_, provisional=True)
