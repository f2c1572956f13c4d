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

from dataclasses import dataclass

import numpy as np

from pnlviz.calib.models import CameraModel
from pnlviz.calib.observations import Observations
from pnlviz.calib.problem import FrameData, Problem
from pnlviz.calib.solver import SolverParams, levenberg_marquardt
from pnlviz.conventions import DEFAULT_ALPHA
from pnlviz.field.model import FieldModel, load_field_model
from pnlviz.geometry.camera import Camera


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

    def solve(self) -> tuple[Camera, dict]:
        if self.n_res < self.n_free:
            return self.cam0, {"success": False, "message": "fewer residuals than parameters", "iterations": 0}
        state, info = levenberg_marquardt(self.problem.evaluate, self.model.retract, self.model.start(),
                                          self.params.solver)
        return self.model.camera(state), info
