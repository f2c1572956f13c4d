"""Homography-only calibration (the paper's planar estimation): the ground plane alone, no camera
model. Paper Sec. "Homography Estimation" and "Point and Line Refinement Module" ("or a
homography matrix H in the case of planar estimation").

The steps are the frame pipeline's (:mod:`pnlviz.calib.pipeline`, shared with the camera);
:class:`HomographyKind` is the ground homography's part of them, everything restricted to the
ground plane (keypoints with z = 0, the straight classes on the ground, the circles):

1. Candidates. For each keypoint subset (``full``, ``main``, ``ground``, each restricted to the
   ground) and each RANSAC threshold, ``cv2.findHomography`` with RANSAC between the keypoints'
   field positions (X, Y metres) and their pixels, then a least-squares refit on the inliers
   (OpenCV's method 0: DLT followed by Levenberg-Marquardt on the reprojection error, the paper's
   refinement) and one re-selection of the inliers with the refitted H. For a homography ``full``
   restricted to the ground is the ``ground`` subset itself: the pipeline skips a subset with the
   same points as an earlier one, so ``ground`` only counts when asked for alone
   (``subsets=("ground",)``); the names stay those of the camera pipeline.
2. Heuristic voting on every ground observation: the ground keypoints and the points observed on
   ground lines (distance to the segment mapped by H) and circles (distance to the mapped arc),
   each counted as its distance. The winner (``refine_top`` = 1) is polished by
   Levenberg-Marquardt on its inliers in float64 (``findHomography`` works on float32 points:
   ~1e-7 relative).
3. Optional PnL refinement (``pnl=True``): the 8 degrees of freedom of H against
   ``alpha * lines + (1 - alpha) * points`` (in squares), lines, circles and keypoints gated by
   the voted H.

Sign and scale of the returned H (field metres (X, Y, 1) -> pixels of ``obs``): unit Frobenius
norm and the third homogeneous coordinate positive for points in front of the camera, like
``Camera.ground_homography()`` (whose third row is the depth). A camera above the pitch (z
down) then has ``det(H) > 0``; a candidate with ``det(H) < 0`` would be the mirror image of the
pitch (a camera under the ground, or left/right-swapped labels) and is rejected.

The residuals are the camera's (:mod:`pnlviz.calib.problem`) with the homography model of
:mod:`pnlviz.calib.models`, solved by the same solver (:mod:`pnlviz.calib.solver`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import cv2
import numpy as np

from pnlviz.calib.models import HomographyModel
from pnlviz.calib.observations import Observations
from pnlviz.calib.pipeline import Candidate, FrameResult, calibrate_with
from pnlviz.calib.problem import FrameData, Problem
from pnlviz.calib.solver import SolverParams, levenberg_marquardt
from pnlviz.calib.voting import SUBSETS
from pnlviz.conventions import DEFAULT_ALPHA, EVAL_WIDTH
from pnlviz.field.model import FieldModel, load_field_model

__all__ = ["HomographyKind", "HomographyParams", "HomographyResult", "estimate_homography", "normalize_visible",
           "template_homography"]


@dataclass(frozen=True)
class HomographyParams:
    """Settings. Pixel values are for a 960 px wide image and scale with the width."""

    subsets: tuple[str, ...] = SUBSETS
    ransac_thresholds: tuple[float, ...] = (5.0, 10.0, 20.0, 40.0)
    min_points: int = 4  #: ground keypoints needed for a homography
    ransac_iters: int = 500
    ransac_confidence: float = 0.999
    vote_tau: float = 10.0  #: truncation of the voting score, pixels
    refine_top: int = 1  #: candidates polished after the first vote
    max_rms: float = 15.0  #: a homography whose inlier RMS (px) is above this is a failure
    pnl: bool = False  #: run the PnL refinement after the vote
    alpha: float = DEFAULT_ALPHA  #: PnL weight of lines vs points (paper: 0.6)
    line_gate_px: float = 20.0  #: a line/circle joins PnL when all its points are this close to its mapping
    point_gate_px: float = 20.0  #: a keypoint joins PnL when this close to its initial mapping
    regate_rounds: int = 2  #: PnL again while the gates at its result let more through (as the camera's)
    lines_alone_classes: int = 4  #: PnL without the derived keypoints from this many classes on (as the camera's)
    circles: bool = True  #: ground circles take part in voting and PnL
    circle_step: float = 0.25  #: metres between samples of mapped circles
    max_iter: int = 100  #: iterations of the PnL solver

    def px(self, value: float, width: float) -> float:
        return value * width / EVAL_WIDTH


@dataclass
class HomographyResult(FrameResult):
    """One frame's ground homography and the evidence for it (see
    :class:`pnlviz.calib.pipeline.FrameResult`; the residuals are those of the ground keypoints
    and classes).

    ``H`` and ``initial_H`` map field metres (X, Y, 1) on the ground to pixels of the
    observations' image (``width`` x ``height``), unit norm, positive third coordinate in front of
    the camera. ``initial_H`` is the voted candidate, ``H`` the final one (after PnL when run).
    """

    width: int = 0
    height: int = 0

    @property
    def H(self) -> np.ndarray | None:
        return self.estimate

    @property
    def initial_H(self) -> np.ndarray | None:
        return self.initial_estimate

    def template_homography(self, image_size: tuple[int, int] = (1280, 720), model: FieldModel | None = None,
                            initial: bool = False) -> np.ndarray | None:
        """WC14-convention homography: template yards -> pixels at ``image_size``."""
        H = self.initial_H if initial else self.H
        if H is None:
            return None
        return template_homography(H, self.width, self.height, image_size, model)

    def camera(self, refine: bool = False):
        """The pinhole camera closest to ``H`` (:func:`camera_from_ground_homography`), or None."""
        from pnlviz.geometry.homography import camera_from_ground_homography

        return None if self.H is None else camera_from_ground_homography(self.H, self.width, self.height, refine=refine)


def template_homography(H: np.ndarray, width: float, height: float, image_size: tuple[int, int] = (1280, 720),
                        model: FieldModel | None = None) -> np.ndarray:
    """A field-metres -> pixels homography of a ``width`` x ``height`` image as a WC14 one:
    template yards -> pixels at ``image_size`` (pixels scaled as x * W' / W, the same scaling as
    ``Camera.scaled``)."""
    model = model or load_field_model()
    S = np.diag([image_size[0] / width, image_size[1] / height, 1.0])
    return S @ np.asarray(H, float) @ model.template_to_field_matrix


def normalize_visible(H: np.ndarray, X: np.ndarray | None = None) -> np.ndarray:
    """``H`` scaled to unit Frobenius norm, with the sign that makes the third homogeneous
    coordinate of the field points ``X`` (N, 2) positive (by majority; by ``det > 0`` without
    points)."""
    H = np.asarray(H, float) / np.linalg.norm(H)
    if X is not None and len(X):
        w = X @ H[2, :2] + H[2, 2]
        return H if np.sum(np.sign(w)) >= 0 else -H
    return H if np.linalg.det(H) >= 0 else -H


# ------------------------------------------------------------------------------ checks and fits
def _map(H: np.ndarray, X: np.ndarray) -> np.ndarray:
    h = X @ H[:, :2].T + H[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        return h[:, :2] / h[:, 2:]


def keypoint_distances(H: np.ndarray, X: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Pixel distance of field points ``X`` (N, 2) mapped by ``H`` to their pixels ``xy`` (inf
    behind the camera)."""
    xh = X @ np.asarray(H, float)[:, :2].T + H[:, 2]
    w = xh[:, 2] * np.sign(np.linalg.det(H))  # sign-free: in front <=> w det(H) > 0 for a non-mirrored H
    with np.errstate(divide="ignore", invalid="ignore"):
        d = np.linalg.norm(xh[:, :2] / xh[:, 2:] - xy, axis=1)
    return np.where(w > 0, d, np.inf)


def _problem_with(H: np.ndarray, X: np.ndarray, xy: np.ndarray) -> str | None:
    """Why ``H`` (fitted to field points ``X`` -> pixels ``xy``) is unusable, or None."""
    if H is None or H.shape != (3, 3) or not np.all(np.isfinite(H)):
        return "no homography"
    Hn = H / np.linalg.norm(H)
    w = X @ Hn[2, :2] + Hn[2, 2]
    if not (np.all(w > 0) or np.all(w < 0)):
        return "inliers on both sides of the horizon"
    if w[0] < 0:
        Hn = -Hn
    # conditioning in normalised coordinates (pixels / image scale, field / 50 m)
    scale = max(float(np.ptp(xy, axis=0).max()), 1.0)
    Hc = np.diag([1 / scale, 1 / scale, 1.0]) @ Hn @ np.diag([50.0, 50.0, 1.0])
    sv = np.linalg.svd(Hc, compute_uv=False)
    if not sv[-1] > 1e-9 * sv[0]:
        return "singular homography"
    if np.linalg.det(Hn) <= 0:
        return "mirrored pitch (camera under the ground)"
    return None


def _fit(X: np.ndarray, xy: np.ndarray, thr: float, params: HomographyParams) -> tuple[np.ndarray, np.ndarray] | None:
    """RANSAC + least-squares refit on the inliers + one re-selection. (H, inlier mask) or None."""
    X64, xy64 = X.astype(np.float64), xy.astype(np.float64)
    if len(X) == 4:
        H, _ = cv2.findHomography(X64, xy64, 0)
        mask = np.ones(4, bool)
    else:
        H, m = cv2.findHomography(X64, xy64, cv2.RANSAC, thr, maxIters=params.ransac_iters,
                                  confidence=params.ransac_confidence)
        if H is None or m is None:
            return None
        mask = m.ravel().astype(bool)
        if mask.sum() < 4:
            return None
        H, _ = cv2.findHomography(X64[mask], xy64[mask], 0)  # DLT + Levenberg-Marquardt on the inliers
        if H is None:
            return None
        err = np.linalg.norm(_map(H, X) - xy, axis=1)
        m2 = err < thr
        if m2.sum() >= 4 and not np.array_equal(m2, mask):
            H2, _ = cv2.findHomography(X64[m2], xy64[m2], 0)
            if H2 is not None and _problem_with(H2, X[m2], xy[m2]) is None:
                H, mask = H2, m2
    if H is None or _problem_with(H, X[mask], xy[mask]):
        return None
    return normalize_visible(H, X[mask]), mask


def _in_front(H: np.ndarray, X: np.ndarray, q: np.ndarray) -> bool:
    """True when the field points ``X`` and the ground seen at pixels ``q`` lie in front of the
    camera of the sign-normalised ``H`` (third coordinate of ``H X`` > 0; for a pixel, the third
    coordinate of ``H^-1 q`` > 0, i.e. the pixel lies below the horizon)."""
    if len(X) and not np.all(X @ H[2, :2] + H[2, 2] > 0):
        return False
    if len(q):
        try:
            b = np.hstack([q, np.ones((len(q), 1))]) @ np.linalg.inv(H).T
        except np.linalg.LinAlgError:
            return False
        if not np.all(b[:, 2] > 0):
            return False
    return True


#: the polish of the voted homography on its inlier keypoints
_POLISH = SolverParams(max_iter=50, tol=1e-12)


def _solve(problem: Problem, H0: np.ndarray, params: SolverParams) -> np.ndarray:
    """``H0`` refined against ``problem`` (itself when there are fewer residuals than parameters)."""
    model = problem.model
    if problem.n_res < model.n_params:
        return np.asarray(H0, float)
    M, _ = levenberg_marquardt(problem.evaluate, model.retract, model.start(H0), params)
    return model.homography(M)


# ------------------------------------------------------------------------------ the homography's part of the pipeline
class HomographyKind:
    """The ground homography in the frame pipeline (see the module docstring)."""

    ground_only = True

    def __init__(self, data: FrameData, params: HomographyParams):
        self.data, self.params = data, params
        self.model = HomographyModel()
        #: every ground observation (keypoints, lines and, with ``params.circles``, circles)
        self.full = self.problem(0.5)
        self.kp_X = data.obs.kp_xyz[self.full.kp_mask, :2]

    def problem(self, alpha: float, keypoints=None, lines=None, circles=None) -> Problem:
        """The residuals of a ground homography against the frame's ground observations."""
        if not self.params.circles:
            circles = ()
        return Problem(self.model, self.data, alpha, keypoints=keypoints, lines=lines, circles=circles,
                       ground_only=True, circle_step=self.params.circle_step)

    def new_result(self) -> HomographyResult:
        return HomographyResult(width=self.data.obs.width, height=self.data.obs.height)

    def too_few(self) -> str | None:
        n, need = int(self.data.obs.ground.sum()), self.params.min_points
        return f"too few ground keypoints ({n} < {need})" if n < need else None

    def fit(self, sub: Observations, plane: str, on_plane: np.ndarray, local_xy: np.ndarray, thr_px: float):
        """The ground homography of RANSAC and refits (every point of ``sub`` is on the ground)."""
        fit = _fit(local_xy, sub.kp_xy, thr_px, self.params)
        if fit is None:
            return None
        H, inl = fit
        return H, inl, np.linalg.norm(_map(H, local_xy) - sub.kp_xy, axis=1)

    def scorer(self, first: np.ndarray):
        def distances(H: np.ndarray) -> np.ndarray:  # every ground observation's pixel distance
            cls = self.full.class_distances(self.model.start(H))
            d = np.concatenate([keypoint_distances(H, self.kp_X, self.full.kp_xy)] + [cls[k] for k in cls])
            return np.where(np.isfinite(d), d, np.inf)

        return distances

    def refine(self, c: Candidate) -> Candidate:
        """Levenberg-Marquardt on the reprojection error of the inliers, in float64 (OpenCV's own
        refinement in ``findHomography`` works on float32 points, ~1e-7 relative); the candidate
        unchanged when that does not help."""
        H = c.estimate
        prob = self.problem(0.0, keypoints=np.isin(self.data.obs.kp_ids, c.inliers), lines=(), circles=())
        X = self.data.obs.kp_xyz[prob.kp_mask, :2]
        if prob.n_res >= 8:
            H1 = _solve(prob, H, _POLISH)
            if (np.all(np.isfinite(H1)) and not _problem_with(H1, X, prob.kp_xy)
                    and np.sum(prob.residuals(self.model.start(H1)) ** 2) <= np.sum(prob.residuals(self.model.start(H)) ** 2)):
                H = normalize_visible(H1, X)
        err = keypoint_distances(H, X, prob.kp_xy)
        return Candidate(c.subset, c.threshold, c.plane, H, c.inliers, float(np.sqrt(np.mean(err ** 2))))

    @staticmethod
    def fallback() -> list[Candidate]:
        return []

    def degenerate(self) -> str:
        return (f"degenerate geometry: no homography from {int(self.data.obs.ground.sum())} ground keypoints "
                "(collinear, or no 4 consistent ones)")

    def point_errors(self, H: np.ndarray) -> dict[int, float]:
        return {int(i): float(d) for i, d in zip(self.full.kp_ids, keypoint_distances(H, self.kp_X, self.full.kp_xy))}

    def class_errors(self, H: np.ndarray) -> dict[str, float]:
        return {name: float(np.max(d)) for name, d in self.full.class_distances(self.model.start(H)).items() if len(d)}

    def pnl_solve(self, H: np.ndarray, keypoints: np.ndarray, lines: list[str], circles: list[str]) -> np.ndarray | None:
        """The paper's PnL for a ground homography: its 8 degrees of freedom; None when too few
        residuals join or the solution is unusable (an observed point crossing the horizon, a
        mirrored or singular H)."""
        H0 = normalize_visible(np.asarray(H, float), self.kp_X if len(self.kp_X) else None)
        prob = self.problem(self.params.alpha, keypoints=keypoints, lines=lines, circles=circles)
        if prob.n_res < 9:
            return None
        # the model starts at the sign-normalised H0 and moves continuously, so the sign carries over
        H1 = _solve(prob, H0, SolverParams(max_iter=self.params.max_iter, tol=1e-12))
        H1 = H1 / np.linalg.norm(H1)
        X = self.data.obs.kp_xyz[prob.kp_mask, :2]
        pts = np.vstack([prob.line_pts] + [p for _, _, p in prob.circle_items])
        if not np.all(np.isfinite(H1)) or np.linalg.det(H1) <= 0 or not _in_front(H1, X, pts):
            return None
        if len(X) and _problem_with(H1, X, prob.kp_xy):
            return None
        return H1


def estimate_homography(obs: Observations, params: HomographyParams | None = None, *,
                        thresholds: tuple[float, ...] | None = None, subsets: tuple[str, ...] | None = None,
                        pnl: bool | None = None, model: FieldModel | None = None, **overrides) -> HomographyResult:
    """Ground homography of one frame (field metres -> pixels of ``obs``) from its ground
    keypoints, voted over subsets x RANSAC thresholds, optionally PnL-refined (``pnl=True``).

    ``thresholds`` (pixels at 960 px width), ``subsets``, ``pnl`` and any other
    :class:`HomographyParams` field given as a keyword override ``params``. Never raises on bad
    geometry: failures come back with a reason in ``failure``.
    """
    params = params or HomographyParams()
    if thresholds is not None:
        overrides["ransac_thresholds"] = tuple(thresholds)
    if subsets is not None:
        overrides["subsets"] = tuple(subsets)
    if pnl is not None:
        overrides["pnl"] = bool(pnl)
    if overrides:
        params = replace(params, **overrides)
    return calibrate_with(HomographyKind(FrameData.build(obs, model or load_field_model()), params), params)
