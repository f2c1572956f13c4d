"""Homography-only calibration (the paper's planar estimation): the ground plane alone, no camera
model. Paper Sec. "Homography Estimation" and "Point and Line Refinement Module" ("or a
homography matrix H in the case of planar estimation").

The pipeline for one frame, the planar twin of :mod:`pnlviz.calib.calibrate`:

1. Candidates. For each keypoint subset (``full``, ``main``, ``ground``, each restricted to the
   keypoints on the ground, z = 0) and each RANSAC threshold (pixels at 960 px width, scaled with
   the image width), ``cv2.findHomography`` with RANSAC between the keypoints' field positions
   (X, Y metres) and their pixels, then a least-squares refit on the inliers (OpenCV's method 0:
   DLT followed by Levenberg-Marquardt on the reprojection error, the paper's refinement) and one
   re-selection of the inliers with the refitted H. Identical inlier sets are kept once. For a
   homography ``full`` restricted to the ground is the ``ground`` subset itself: a subset with
   the same points as an earlier one is skipped (OpenCV's RANSAC is deterministic), so
   ``ground`` only counts when asked for alone (``subsets=("ground",)``); the names stay those of
   the camera pipeline.
2. Heuristic voting: every candidate is scored on *all* ground observations, the ground keypoints
   and the points observed on ground lines (distance to the segment mapped by H) and circles
   (distance to the mapped arc), with a truncated quadratic ``sum(min(d^2, tau^2))``; the lowest
   score wins, ``full`` winning ties. The winner is polished by Levenberg-Marquardt on its
   inliers in float64 (``findHomography`` works on float32 points: ~1e-7 relative).
3. Optional PnL refinement (:func:`refine_homography_pnl`): the 8 degrees of freedom of H
   against ``alpha * lines + (1 - alpha) * points`` (in squares, as least squares needs), the
   lines and keypoints gated by the voted H.

Sign and scale of the returned H (field metres (X, Y, 1) -> pixels of ``obs``): unit Frobenius
norm and the third homogeneous coordinate positive for points in front of the camera, like
``Camera.ground_homography()`` (whose third row is the depth). A camera above the pitch (z
down) then has ``det(H) > 0``; a candidate with ``det(H) < 0`` would be the mirror image of the
pitch (a camera under the ground, or left/right-swapped labels) and is rejected.

The residuals are the camera's (:mod:`pnlviz.calib.problem`: keypoints, the distance to the
image of each model segment with its overshoot beyond the ends, the distance to mapped arcs) with
the homography model of :mod:`pnlviz.calib.models`, solved by the same solver
(:mod:`pnlviz.calib.solver`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from pnlviz.calib.models import HomographyModel
from pnlviz.calib.observations import Observations
from pnlviz.calib.problem import FrameData, Problem
from pnlviz.calib.solver import SolverParams, levenberg_marquardt
from pnlviz.calib.voting import SUBSETS, best, subset_mask, truncated_score
from pnlviz.conventions import DEFAULT_ALPHA
from pnlviz.field.model import FieldModel, load_field_model

__all__ = ["SUBSETS", "HomographyParams", "HomographyResult", "estimate_homography", "refine_homography_pnl",
           "HomographyProblem", "template_homography", "normalize_visible"]


@dataclass(frozen=True)
class HomographyParams:
    """Settings. Pixel values are for a 960 px wide image and scale with the width."""

    subsets: tuple[str, ...] = SUBSETS
    ransac_thresholds: tuple[float, ...] = (5.0, 10.0, 20.0, 40.0)
    min_points: int = 4  #: ground keypoints needed for a homography
    ransac_iters: int = 500
    ransac_confidence: float = 0.999
    vote_tau: float = 10.0  #: truncation of the voting score, pixels
    max_rms: float = 15.0  #: a homography whose inlier RMS (px) is above this is a failure
    pnl: bool = False  #: run the PnL refinement after the vote
    alpha: float = DEFAULT_ALPHA  #: PnL weight of lines vs points (paper: 0.6)
    gate_px: float = 20.0  #: a line joins PnL when all its points are this close to the initial mapped segment
    point_gate_px: float | None = None  #: a keypoint joins PnL when this close to its initial projection (default gate_px)
    circles: bool = True  #: ground circles take part in voting and PnL
    circle_step: float = 0.25  #: metres between samples of mapped circles
    max_iter: int = 100  #: iterations of the PnL solver

    def px(self, value: float, width: float) -> float:
        return value * width / 960.0


@dataclass
class HomographyResult:
    """One frame's ground homography and the evidence for it.

    ``H`` and ``initial_H`` map field metres (X, Y, 1) on the ground to pixels of the
    observations' image (``width`` x ``height``), unit norm, positive third coordinate in front of
    the camera. ``initial_H`` is the voted candidate, ``H`` the final one (after PnL when run).
    Residuals are pixel distances: per ground keypoint id, and per ground line/circle class the
    largest distance of its observed points.
    """

    H: np.ndarray | None
    width: int = 0
    height: int = 0
    initial_H: np.ndarray | None = None
    subset: str | None = None
    threshold: float | None = None
    inliers: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    point_residuals_initial: dict[int, float] = field(default_factory=dict)
    point_residuals: dict[int, float] = field(default_factory=dict)
    line_residuals_initial: dict[str, float] = field(default_factory=dict)
    line_residuals: dict[str, float] = field(default_factory=dict)
    pnl_lines: list[str] = field(default_factory=list)
    candidates: list[dict] = field(default_factory=list)
    failure: str | None = None

    @property
    def ok(self) -> bool:
        return self.H is not None

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


# ------------------------------------------------------------------------------ residuals
def _hom(xy: np.ndarray) -> np.ndarray:
    return np.hstack([np.asarray(xy, float).reshape(-1, 2), np.ones((len(xy), 1))])


class HomographyProblem:
    """The residuals of a ground homography against :class:`Observations` (or their
    :class:`FrameData`): ground keypoints, the straight classes on the ground and (optionally)
    the circles, as :class:`pnlviz.calib.problem.Problem` with the homography model (its
    parameters: ``M <- M (I + P)``, ``H = M diag(s, s, 1)``, s = 1/50 m)."""

    def __init__(self, obs: Observations | FrameData, alpha: float = DEFAULT_ALPHA, model: FieldModel | None = None, *,
                 use_keypoints: np.ndarray | None = None, lines=None, circles=None, circle_step: float = 0.25):
        data = obs if isinstance(obs, FrameData) else FrameData.build(obs, model or load_field_model())
        self.model = HomographyModel()
        self.problem = Problem(self.model, data, alpha, keypoints=use_keypoints, lines=lines, circles=circles,
                               ground_only=True, circle_step=circle_step)
        prob = self.problem
        self.kp_ids, self.kp_xy = prob.kp_ids, prob.kp_xy
        self.kp_X = data.obs.kp_xyz[prob.kp_mask, :2]
        self.line_q, self.circle_items, self.n_res = prob.line_pts, prob.circle_items, prob.n_res

    def residuals(self, H: np.ndarray) -> np.ndarray:
        return self.problem.residuals(self.model.start(H))

    def solve(self, H0: np.ndarray, params: SolverParams) -> np.ndarray:
        """``H0`` refined (the starting H when there are fewer residuals than parameters)."""
        if self.n_res < self.model.n_params:
            return np.asarray(H0, float)
        M, _ = levenberg_marquardt(self.problem.evaluate, self.model.retract, self.model.start(H0), params)
        return self.model.homography(M)

    def keypoint_distances(self, H: np.ndarray) -> np.ndarray:
        """Pixel distance of each ground keypoint to its mapping (inf behind the camera)."""
        xh = self.kp_X @ np.asarray(H, float)[:, :2].T + H[:, 2]
        w = xh[:, 2] * np.sign(np.linalg.det(H))  # sign-free: in front <=> w det(H) > 0 for a non-mirrored H
        with np.errstate(divide="ignore", invalid="ignore"):
            d = np.linalg.norm(xh[:, :2] / xh[:, 2:] - self.kp_xy, axis=1)
        return np.where(w > 0, d, np.inf)

    def class_distances(self, H: np.ndarray) -> dict[str, np.ndarray]:
        """Unweighted distances (px) of each line/circle class's observed points."""
        return self.problem.class_distances(self.model.start(H))

    def observation_distances(self, H: np.ndarray) -> np.ndarray:
        """Every ground observation's pixel distance: keypoints, then line and circle points."""
        cls = self.class_distances(H)
        parts = [self.keypoint_distances(H)] + [cls[k] for k in cls]
        d = np.concatenate(parts) if parts else np.zeros(0)
        return np.where(np.isfinite(d), d, np.inf)


# ------------------------------------------------------------------------------ candidates
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


@dataclass
class _Candidate:
    subset: str
    threshold: float
    H: np.ndarray
    inliers: np.ndarray  # keypoint ids
    rms: float
    score: float = np.inf


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


def _map(H: np.ndarray, X: np.ndarray) -> np.ndarray:
    h = X @ H[:, :2].T + H[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        return h[:, :2] / h[:, 2:]


#: the polish of the voted homography on its inlier keypoints, and the PnL refinement
_POLISH = SolverParams(max_iter=50, tol=1e-12)


def _polish(H: np.ndarray, obs: Observations | FrameData, inliers: np.ndarray, model: FieldModel) -> np.ndarray:
    """Levenberg-Marquardt on the reprojection error of the inliers, in float64 (OpenCV's own
    refinement in ``findHomography`` works on float32 points, ~1e-7 relative)."""
    kp_ids = obs.obs.kp_ids if isinstance(obs, FrameData) else obs.kp_ids
    prob = HomographyProblem(obs, 0.0, model, use_keypoints=np.isin(kp_ids, inliers), lines=(), circles=())
    if prob.n_res < 8:
        return H
    H1 = prob.solve(H, _POLISH)
    if (not np.all(np.isfinite(H1)) or _problem_with(H1, prob.kp_X, prob.kp_xy)
            or np.sum(prob.residuals(H1) ** 2) > np.sum(prob.residuals(H) ** 2)):
        return H
    return normalize_visible(H1, prob.kp_X)


def make_candidates(obs: Observations, params: HomographyParams) -> list[_Candidate]:
    """Step 1: one homography per (subset, threshold) with a distinct inlier set."""
    out, seen, masks = [], set(), []
    for subset in params.subsets:
        mask = subset_mask(obs, subset, ground_only=True)
        if mask.sum() < params.min_points or any(np.array_equal(mask, m) for m in masks):
            continue  # the same points as an earlier subset give the same (deterministic) RANSAC fits
        masks.append(mask)
        X, xy, ids = obs.kp_xyz[mask, :2], obs.kp_xy[mask], obs.kp_ids[mask]
        for thr in params.ransac_thresholds:
            fit = _fit(X, xy, params.px(thr, obs.width), params)
            if fit is None:
                continue
            H, inl = fit
            key = tuple(ids[inl])
            if key in seen:
                continue
            seen.add(key)
            err = np.linalg.norm(_map(H, X[inl]) - xy[inl], axis=1)
            out.append(_Candidate(subset, float(thr), H, ids[inl], float(np.sqrt(np.mean(err**2)))))
    return out


def vote(cands: list[_Candidate], prob: HomographyProblem, tau: float) -> _Candidate | None:
    """Step 2: truncated-quadratic score on every ground observation; lowest wins (``full`` on ties)."""
    for c in cands:
        c.score = truncated_score(prob.observation_distances(c.H), tau)
    return best(cands)


# ------------------------------------------------------------------------------ PnL
def refine_homography_pnl(H: np.ndarray, obs: Observations | FrameData, alpha: float = DEFAULT_ALPHA,
                          gate_px: float = 20.0, *, point_gate_px: float | None = None, circles: bool = True,
                          scale_gates: bool = True, model: FieldModel | None = None, circle_step: float = 0.25,
                          max_iter: int = 100) -> tuple[np.ndarray, list[str]]:
    """The paper's PnL refinement for a ground homography: the 8 degrees of freedom of ``H``
    (field metres -> pixels of ``obs``) against ``alpha * lines + (1 - alpha) * points``.

    Gating by the starting ``H``: a ground line (or circle, with ``circles``) joins when every
    observed point of it lies within ``gate_px`` of its mapped segment (arc); a ground keypoint
    joins when within ``point_gate_px`` (default ``gate_px``) of its mapping. Gates are pixels at
    960 px width scaled with the image width (``scale_gates=False``: pixels as given).

    Returns ``(H, joined classes)``; the starting ``H`` (normalised) and ``[]`` when too few
    residuals join or the solution is unusable (an observed point crossing the horizon, a
    mirrored or singular H).
    """
    data = obs if isinstance(obs, FrameData) else FrameData.build(obs, model or load_field_model())
    o = data.obs
    k = o.width / 960.0 if scale_gates else 1.0
    gate_l = gate_px * k
    gate_p = (gate_px if point_gate_px is None else point_gate_px) * k
    full = HomographyProblem(data, alpha, circles=None if circles else (), circle_step=circle_step)
    H0 = normalize_visible(np.asarray(H, float), full.kp_X if len(full.kp_X) else None)
    joined = {name for name, d in full.class_distances(H0).items() if len(d) and np.all(d < gate_l)}
    kp_ok = np.zeros(o.n_keypoints, bool)
    kp_ok[np.flatnonzero(full.problem.kp_mask)] = full.keypoint_distances(H0) < gate_p
    prob = HomographyProblem(data, alpha, use_keypoints=kp_ok, lines=[n for n in o.lines if n in joined],
                             circles=[n for n in o.circles if n in joined and circles], circle_step=circle_step)
    if prob.n_res < 9:
        return H0, []
    # the model starts at the sign-normalised H0 and moves continuously, so the sign carries over
    H1 = prob.solve(H0, SolverParams(max_iter=max_iter, tol=1e-12))
    H1 = H1 / np.linalg.norm(H1)
    pts = np.vstack([prob.line_q] + [p for _, _, p in prob.circle_items])
    if not np.all(np.isfinite(H1)) or np.linalg.det(H1) <= 0 or not _in_front(H1, prob.kp_X, pts):
        return H0, []
    if len(prob.kp_X) and _problem_with(H1, prob.kp_X, prob.kp_xy):
        return H0, []
    return H1, sorted(joined)


def _in_front(H: np.ndarray, X: np.ndarray, q: np.ndarray) -> bool:
    """True when the field points ``X`` and the ground seen at pixels ``q`` lie in front of the
    camera of the sign-normalised ``H`` (third coordinate of ``H X`` > 0; for a pixel, the third
    coordinate of ``H^-1 q`` > 0, i.e. the pixel lies below the horizon)."""
    if len(X) and not np.all(X @ H[2, :2] + H[2, 2] > 0):
        return False
    if len(q):
        try:
            b = _hom(q) @ np.linalg.inv(H).T
        except np.linalg.LinAlgError:
            return False
        if not np.all(b[:, 2] > 0):
            return False
    return True


# ------------------------------------------------------------------------------ residual reports
def _point_report(prob: HomographyProblem, H: np.ndarray) -> dict[int, float]:
    return {int(i): float(d) for i, d in zip(prob.kp_ids, prob.keypoint_distances(H))}


def _class_report(prob: HomographyProblem, H: np.ndarray) -> dict[str, float]:
    return {name: float(np.max(d)) for name, d in prob.class_distances(H).items() if len(d)}


# ------------------------------------------------------------------------------ the whole frame
def estimate_homography(obs: Observations, params: HomographyParams | None = None, *,
                        thresholds: tuple[float, ...] | None = None, subsets: tuple[str, ...] | None = None,
                        pnl: bool | None = None, model: FieldModel | None = None, **overrides) -> HomographyResult:
    """Ground homography of one frame (field metres -> pixels of ``obs``) from its ground
    keypoints, voted over subsets x RANSAC thresholds, optionally PnL-refined (``pnl=True``).

    ``thresholds`` (pixels at 960 px width), ``subsets``, ``pnl`` and any other
    :class:`HomographyParams` field given as a keyword override ``params``. Never raises on bad
    geometry: failures come back with a reason in ``failure``.
    """
    from dataclasses import replace

    params = params or HomographyParams()
    if thresholds is not None:
        overrides["ransac_thresholds"] = tuple(thresholds)
    if subsets is not None:
        overrides["subsets"] = tuple(subsets)
    if pnl is not None:
        overrides["pnl"] = bool(pnl)
    if overrides:
        params = replace(params, **overrides)
    model = model or load_field_model()
    W, Hh = obs.width, obs.height
    n_ground = int(obs.ground.sum())
    if n_ground < params.min_points:
        return HomographyResult(None, W, Hh, failure=f"too few ground keypoints ({n_ground} < {params.min_points})")
    data = FrameData.build(obs, model)
    prob = HomographyProblem(data, 0.5, circles=None if params.circles else (), circle_step=params.circle_step)
    cands = make_candidates(obs, params)
    winner = vote(cands, prob, params.px(params.vote_tau, W))
    table = [{"subset": c.subset, "threshold": c.threshold, "inliers": len(c.inliers), "rms": c.rms, "score": c.score}
             for c in cands]
    if winner is None:
        return HomographyResult(None, W, Hh, candidates=table,
                                failure=f"degenerate geometry: no homography from {n_ground} ground keypoints "
                                        "(collinear, or no 4 consistent ones)")
    winner.H = _polish(winner.H, data, winner.inliers, model)
    res = HomographyResult(winner.H, W, Hh, initial_H=winner.H, subset=winner.subset, threshold=winner.threshold,
                           inliers=winner.inliers, candidates=table)
    res.point_residuals_initial = _point_report(prob, winner.H)
    res.line_residuals_initial = _class_report(prob, winner.H)
    H = winner.H
    if params.pnl and (obs.lines or obs.circles):
        H, res.pnl_lines = refine_homography_pnl(H, data, params.alpha, params.gate_px,
                                                 point_gate_px=params.point_gate_px, circles=params.circles,
                                                 model=model, circle_step=params.circle_step,
                                                 max_iter=params.max_iter)
    res.H = H
    res.point_residuals = _point_report(prob, H)
    res.line_residuals = _class_report(prob, H)
    inl = np.array([res.point_residuals[int(i)] for i in winner.inliers])
    rms = float(np.sqrt(np.mean(inl**2))) if len(inl) else np.inf
    if not rms <= params.px(params.max_rms, W):
        res.H = None
        res.failure = f"residual above the limit (inlier RMS {rms:.1f} px > {params.px(params.max_rms, W):.1f})"
    return res
