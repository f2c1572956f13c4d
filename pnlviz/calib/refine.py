"""Refinement of a camera against keypoints, lines and circles: the camera model
(:class:`pnlviz.calib.models.CameraModel`) in the shared least-squares problem
(:mod:`pnlviz.calib.problem`), solved by the shared solver (:mod:`pnlviz.calib.solver`).

State: rotation ``R``, centre ``C``, focal ``f`` (``fy = aspect * f`` with the aspect of the
starting camera) and radial ``k1``; principal point fixed. Any of focal/k1 can be held fixed: the
PnL refinement holds K fixed and optimises the pose only, as in the paper.

Residuals (pixels): keypoints; for straight classes the distance of each observed point
(undistorted) to the projected *segment* (perpendicular distance to the image of the 3D line plus
the overshoot beyond its ends), which is what the SoccerNet evaluator measures; for circles the
distance to the class projected as a dense polyline (every ``circle_step`` metres, with lens
distortion). A closed-form conic distance (Sampson) was tried first and dropped: it is badly
wrong for the thin ellipses of far penalty arcs seen at grazing angles, and led the optimiser
into false minima.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from pnlviz.calib.models import CameraModel
from pnlviz.calib.observations import Observations
from pnlviz.calib.problem import FrameData, Problem
from pnlviz.calib.solver import SolverParams, levenberg_marquardt
from pnlviz.conventions import DEFAULT_ALPHA
from pnlviz.field.model import FieldModel, load_field_model
from pnlviz.geometry.camera import Camera


#: Levenberg-Marquardt steps of each round of :meth:`CameraProblem.tighten` (it starts from a
#: solution: a few steps move a class the pixel or two it needs)
TIGHTEN_ITERATIONS = 10


@dataclass(frozen=True)
class RefineParams:
    alpha: float = DEFAULT_ALPHA  #: weight of line/circle terms vs keypoints (paper: 0.6)
    refine_focal: bool = True
    refine_k1: bool = False
    loss: str = "linear"  #: linear, huber, soft_l1 or cauchy
    f_scale: float = 2.0  #: pixels where the robust loss bends
    max_iter: int = 50
    tol: float = 1e-8  #: stop when the cost drops by less than this fraction
    k1_bound: float = 1.0  #: |k1| limit (SN22 fits push k1 to +0.4..0.6 at 15-30 deg FOV; a 0.5 cap cost 0.8 FS)
    circle_step: float = 0.5  #: metres between samples of projected circles (chord error < 4 mm)
    pin_weight: float = 1.0  #: weight of pinned (hand-placed) keypoints against the others
    pin_scale: float = 0.0  #: px where the pins' bounded loss bends (0: squares)

    @property
    def solver(self) -> SolverParams:
        return SolverParams(self.loss, self.f_scale, self.max_iter, self.tol)


class CameraProblem:
    """The residuals of a camera against a frame's observations (``Observations``, or the
    ``FrameData`` built from them once per frame), and their refinement from ``cam0``.

    ``use_keypoints`` (N,) selects keypoints; ``lines`` / ``circles`` select classes (default:
    all observed).
    """

    def __init__(self, cam0: Camera, obs: Observations | FrameData, params: RefineParams = RefineParams(),
                 model: FieldModel | None = None, use_keypoints: np.ndarray | None = None, *, lines=None,
                 circles=None):
        data = obs if isinstance(obs, FrameData) else FrameData.build(obs, model or load_field_model())
        self.cam0, self.params = cam0, params
        self.model = CameraModel(cam0, params.refine_focal, params.refine_k1, params.k1_bound)
        self.problem = Problem(self.model, data, params.alpha, keypoints=use_keypoints, lines=lines, circles=circles,
                               circle_step=params.circle_step, pin_weight=params.pin_weight, pin_scale=params.pin_scale)
        self.n_res, self.n_free = self.problem.n_res, self.problem.n_free

    def residuals(self, cam: Camera | None = None) -> np.ndarray:
        """Weighted residuals at ``cam`` (default: the starting camera)."""
        return self.problem.residuals(self.model.start(cam))

    def class_residuals(self, cam: Camera | None = None) -> dict[str, np.ndarray]:
        """Unweighted distances (px) of each line/circle class's points at ``cam``."""
        return self.problem.class_distances(self.model.start(cam))

    def beyond(self, cam: Camera, tolerance: float) -> set[str]:
        """What ``cam`` leaves farther than ``tolerance`` px: the line and circle classes with a
        point that far from their projection, and the keypoints (``"kp <id>"``) that far from
        theirs."""
        state = self.model.start(cam)
        P = self.problem
        out = {n for n, d in P.class_distances(state).items() if len(d) and float(d.max()) > tolerance}
        if len(P.kp_xy):
            uv, _ = self.model.pixels(self.model.transform(P.kp_X, state), state)
            far = np.hypot(*(uv - P.kp_xy).T) > tolerance
            out |= {f"kp {k}" for k in P.kp_ids[far].tolist()}
        return out

    def tighten(self, cam: Camera, tolerance: float, gain: float = 3.0, rounds: int = 3) -> Camera:
        """``cam`` (a solution of this problem) with the classes that end beyond ``tolerance`` px
        pulled in: the rows of each such class weigh ``gain`` times more, the problem is solved
        again from there (at most ``TIGHTEN_ITERATIONS`` steps), up to ``rounds`` times (weights
        compound while a class stays out). A least-squares fit spreads its error over every point;
        the evaluator counts a class right only when *all* its points are within the threshold, so
        a class 6 px off at one end is lost while others sit at 1 px. Returns the camera that
        leaves the fewest classes beyond ``tolerance``, keypoints counted too (``cam`` itself
        unless one leaves fewer)."""
        bad = self.beyond(cam, tolerance)
        best, n_best = cam, len(bad)
        rows, w = self.problem.class_rows(), np.ones(self.n_res)

        def weighted(state, jac: bool = False):
            r, J = self.problem.evaluate(state, jac)
            return r * w, (None if J is None else J * w[:, None])

        for _ in range(rounds):
            if not bad & rows.keys():  # keypoints alone are off: nothing to pull on
                break
            for name in bad & rows.keys():
                w[rows[name]] *= gain
            state, _ = levenberg_marquardt(weighted, self.model.retract, self.model.start(cam),
                                           replace(self.params.solver, max_iter=TIGHTEN_ITERATIONS),
                                           held=self.model.held)
            cam = self.model.camera(state)
            bad = self.beyond(cam, tolerance)
            if len(bad) < n_best:
                best, n_best = cam, len(bad)
        return best

    def solve(self) -> tuple[Camera, dict]:
        if self.n_res < self.n_free:
            return self.cam0, {"success": False, "message": "fewer residuals than parameters", "iterations": 0}
        state, info = levenberg_marquardt(self.problem.evaluate, self.model.retract, self.model.start(),
                                          self.params.solver, held=self.model.held)
        return self.model.camera(state), info
