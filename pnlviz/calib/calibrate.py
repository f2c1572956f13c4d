"""Camera calibration from keypoints (and lines): candidates over keypoint subsets and RANSAC
thresholds, heuristic voting, PnL refinement (by default over focal length and k1 too). The steps
are the frame pipeline's (:mod:`pnlviz.calib.pipeline`, shared with the ground homography); the
camera's part of them is :class:`CameraKind`.

The pipeline for one frame (paper Sec. "Camera Parameters Estimation" and "Point and Line
Refinement Module", plus what the data asked for):

1. Candidates: for each keypoint subset (``full``: every keypoint; ``main``: the line-line
   intersections of the annotation or detector; ``ground``: keypoints with z = 0) and each RANSAC
   threshold, a plane homography with RANSAC (the ground plane, or a goal plane x = +-52.5 when
   the ground has too few points) decomposed into a camera (principal point at the centre,
   square pixels, no distortion); its inliers are counted over the subset, non-planar points
   included. Identical inlier sets are kept once.
2. Heuristic voting: every candidate is scored on *all* observations (keypoints, and the points
   on lines and circles) with a truncated quadratic ``sum(min(r^2, tau^2))``. The best
   ``refine_top`` are refined (focal length and pose on their inliers over all three planes: the
   3-plane rig of the paper, the homography giving the intrinsic initial guess), scored again, and
   the lowest score wins (ties: ``full`` first, as in the paper). Frames with too few keypoints
   for a homography start from their straight lines instead (:func:`line_candidates`, where the
   lines fix the ground plane) and from broadcast camera priors (:func:`prior_candidates`).
3. PnL refinement, cost ``alpha * lines + (1 - alpha) * points`` (squares): a line or circle
   joins when all its observed points are within ``line_gate_px`` of its projection by the voted
   camera, a keypoint when within ``point_gate_px``. The paper refines the pose with K fixed
   (``refine_focal=False, refine_k1=False``); by default the focal length and radial k1 are
   refined with the pose, which the data supports (+5.5 JaC@5 on WC14, +4 on SN22; see docs/benchmarks.md).
   Optionally the classes left with a point beyond ``class_tolerance_px`` are then pulled in
   (:meth:`CameraProblem.tighten`: the evaluator counts a class right only when all its points
   are within its threshold; off by default since the verdict judges a fit from the lines alone
   by its lines, see below). A k1 whose lens model folds part of the pitch back into the image
   (:func:`pnlviz.geometry.lens.folds_into_view`) is refused and the frame fitted again with
   k1 = 0 (``refuse_folding_lens``).

A frame whose keypoints and classes name both ends of the pitch and that gets no camera is
calibrated from each half alone (``one_half_when_both_fail``, ``result.half``).

The keypoints derived from the frame's own lines (the labels of an annotation, the intersections
of detected lines) are left out of the PnL when its lines and circles alone fix the camera
(``lines_alone_classes``), and PnL is gated again at its own result (``regate_rounds``).

Throughout, the line points on the image border are aimed ``border_aim_px`` inside
(:func:`pnlviz.calib.problem.aim_inside`: a projected line is drawn and scored only as far as it
stays inside the image; +0.5 FS@5 on SN22, +0.4 on WC14); residuals are reported against the
points as observed.

Every threshold is a :class:`CalibParams` field (:mod:`pnlviz.calib.params`), given at 960 px image
width and scaled with the image width.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace

import numpy as np

from pnlviz.calib.line_start import CHECKED_CLASSES, LINE_SUBSET, MIN_SPAN_PX, line_sets
from pnlviz.calib.observations import Observations
from pnlviz.calib.params import CalibParams
from pnlviz.calib.pins import PinFailure, pin_camera
from pnlviz.calib.pipeline import Candidate, FrameResult, calibrate_with, plane_masks, refit_with
from pnlviz.calib.plane_cameras import camera_from_plane_homography, plane_homography
from pnlviz.calib.problem import FrameData
from pnlviz.calib.refine import CameraProblem, RefineParams
from pnlviz.calib.voting import SUBSETS, subset_mask
from pnlviz.conventions import FAILURE_CODES as _FAILURE_CODES
from pnlviz.field.model import FieldModel, load_field_model
from pnlviz.geometry.camera import Camera
from pnlviz.geometry.lens import folds_into_view


#: why a frame has no camera (``CalibrationResult.failure_code``; "pins": its hand-placed points
#: alone cannot calibrate it, ``pin_condition`` says which condition fails); the engine adds "no_input"
#: (nothing to calibrate from) and "internal" (a bug), the commands "bad_input" (unreadable files)
FAILURE_CODES = _FAILURE_CODES


@dataclass
class CalibrationResult(FrameResult):
    """One frame's calibration and the evidence for it (what the app shows; see
    :class:`pnlviz.calib.pipeline.FrameResult`): the camera, and the voted one before PnL."""

    @property
    def camera(self) -> Camera | None:
        return self.estimate

    @property
    def initial_camera(self) -> Camera | None:
        return self.initial_estimate


def _sane(cam: Camera, params: CalibParams) -> str | None:
    if not np.all(np.isfinite(cam.R)) or not np.all(np.isfinite(cam.C)):
        return "non-finite camera"
    if cam.C[2] >= 0:
        return "camera below the pitch"
    height, distance = -float(cam.C[2]), math.hypot(cam.C[0], cam.C[1])
    if height < params.min_height_m:
        return f"camera {height:.1f} m above the pitch (a broadcast's: {params.min_height_m:g} m or more)"
    if distance > params.max_distance_m:
        return f"camera {distance:.0f} m from the centre mark (at most {params.max_distance_m:g})"
    if not params.min_hfov_deg <= cam.hfov_deg <= params.max_hfov_deg:
        return f"field of view {cam.hfov_deg:.1f} deg out of range"
    return None


def _kp_errors(cam: Camera, obs: Observations) -> np.ndarray:
    uv, z = cam.project_with_depth(obs.kp_xyz)
    err = np.linalg.norm(uv - obs.kp_xy, axis=1)
    return np.where(z > 1e-3, err, np.inf)


def pin_settings(params: CalibParams, width: int, obs: Observations) -> dict:
    """The :class:`RefineParams` fields of pinned keypoints, when the frame has some."""
    if not obs.pins.any():
        return {}
    return {"pin_weight": params.pin_weight, "pin_scale": params.px(params.pin_scale_px, width)}


#: where a candidate's refinement stops (the cost dropping by less than this fraction): the
#: candidates are refined to be ranked, and PnL refines the winner on everything to
#: :attr:`CalibParams.tol`. 1e-6 took 5.3 iterations where this takes 3.9 (WC14), for the same
#: figures (WC14 and SN22: JaC@5 within 0.001 in every setting)
RANKING_TOL = 1e-3


def refine_candidate(c: Candidate, data: FrameData, params: CalibParams) -> Candidate | None:
    """Focal length and pose of a candidate refined on its inliers (all three planes), with one
    re-selection of the inliers among the subset's keypoints; pinned keypoints are always in."""
    obs = data.obs
    in_subset = subset_mask(obs, c.subset) | obs.pins if c.subset in SUBSETS else obs.pins | np.isin(obs.kp_ids, c.inliers)
    sub = obs.subset(in_subset)
    quick = RefineParams(refine_focal=True, max_iter=20, tol=RANKING_TOL, **pin_settings(params, obs.width, obs))

    def solve(start: Camera, inliers: np.ndarray) -> Camera:  # keypoints alone; lines join in PnL
        use = np.zeros(obs.n_keypoints, bool)
        use[np.flatnonzero(in_subset)[inliers]] = True
        return CameraProblem(start, data, quick, use_keypoints=use, lines=(), circles=()).solve()[0]

    inl = np.isin(sub.kp_ids, c.inliers) | sub.pins
    cam = solve(c.estimate, inl)
    err = _kp_errors(cam, sub)
    inl2 = (err < params.px(c.threshold, obs.width)) | sub.pins
    if inl2.sum() >= params.min_points and not np.array_equal(inl2, inl):
        cam = solve(cam, inl2)
        inl = inl2
        err = _kp_errors(cam, sub)
    if _sane(cam, params):
        return None
    return Candidate(c.subset, c.threshold, c.plane, cam, sub.kp_ids[inl], float(np.sqrt(np.mean(err[inl] ** 2))))


# ------------------------------------------------------------------------------ prior-based start
#: Broadcast camera positions (x, y, z) tried when keypoints alone cannot give a camera: the main
#: camera high on the near side (y > 0), along the pitch, 10-20 m up.
PRIOR_POSITIONS = tuple((x, y, -h) for x in (-30.0, -10.0, 10.0, 30.0) for y in (45.0, 60.0) for h in (12.0, 20.0))
PRIOR_HFOV_DEG = (15.0, 30.0, 50.0)


def _align_rays(cam_dirs: np.ndarray, world_dirs: np.ndarray) -> np.ndarray:
    """Rotation R (world -> camera) with R world_dirs ~ cam_dirs (Kabsch on unit vectors, the
    cross product of the first two added so two rays suffice)."""
    a = np.vstack([cam_dirs, np.cross(cam_dirs[0], cam_dirs[1])])
    b = np.vstack([world_dirs, np.cross(world_dirs[0], world_dirs[1])])
    U, _, Vt = np.linalg.svd(a.T @ b)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    return U @ D @ Vt


def fits_everything(cam: Camera, data: FrameData, params: CalibParams) -> bool:
    """Whether every observation (keypoints, lines, circles) fits ``cam`` within
    ``prior_good_rms`` px RMS: a start good enough to stop searching for others."""
    r = CameraProblem(cam, data, RefineParams(alpha=0.5)).residuals()
    return bool(np.sqrt(np.mean(r * r)) < params.px(params.prior_good_rms, data.obs.width))


def prior_candidates(data: FrameData, params: CalibParams) -> list[Candidate]:
    """Cameras for frames with too few keypoints for a homography: start from typical broadcast
    positions and fields of view, rotate so that two keypoints (or line intersections) line up,
    and fit focal length and pose to every observation (keypoints, lines, circles). Mirrored
    positions (y < 0) are covered by the evaluator's left/right symmetry of the labels."""
    obs = data.obs
    if obs.n_keypoints < 2 or not (obs.lines or obs.circles):
        return []
    W, H = obs.width, obs.height
    # the two keypoints farthest apart in the image give the best-conditioned rotation
    d = np.linalg.norm(obs.kp_xy[:, None] - obs.kp_xy[None], axis=2)
    i, j = np.unravel_index(np.argmax(d), d.shape)
    out = []
    tau = params.px(params.vote_tau, W)
    for hfov in PRIOR_HFOV_DEG:
        f = (W / 2) / np.tan(np.radians(hfov) / 2)
        rays = np.array([[(obs.kp_xy[k, 0] - W / 2) / f, (obs.kp_xy[k, 1] - H / 2) / f, 1.0] for k in (i, j)])
        rays /= np.linalg.norm(rays, axis=1, keepdims=True)
        for pos in PRIOR_POSITIONS:
            C = np.array(pos)
            wd = obs.kp_xyz[[i, j]] - C
            wd /= np.linalg.norm(wd, axis=1, keepdims=True)
            R = _align_rays(rays, wd)
            cam0 = Camera(f, f, W / 2, H / 2, R, C, W, H)
            if np.any(cam0.to_camera(obs.kp_xyz[[i, j]])[:, 2] <= 0):
                continue
            cam, _ = CameraProblem(cam0, data, RefineParams(alpha=0.5, loss="soft_l1", f_scale=tau, max_iter=40)).solve()
            if _sane(cam, params):
                continue
            err = _kp_errors(cam, obs)
            inl = err < params.px(params.ransac_thresholds[-1], W)
            out.append(Candidate("prior", float(params.ransac_thresholds[-1]), "ground", cam, obs.kp_ids[inl],
                                 float(np.sqrt(np.mean(np.minimum(err, 1e3) ** 2)))))
            if fits_everything(cam, data, params):
                return out
    return out


def line_candidates(data: FrameData, params: CalibParams, sets: list | None = None) -> tuple[list[Candidate], bool]:
    """Cameras for frames whose keypoints are too few for a homography but whose straight ground
    lines (with their ground keypoints) fix the plane (:mod:`pnlviz.calib.line_start`): each
    homography of :func:`pnlviz.calib.line_start.line_sets` decomposed, then fitted (focal
    length and pose) to the lines and keypoints it was solved from (the vote then scores it on
    every observation, and PnL's gates choose what it fits). Also whether one of them is settled:
    :data:`pnlviz.calib.line_start.CHECKED_CLASSES` lines or more (more than fix it) that it fits
    within ``prior_good_rms`` px RMS (no broadcast prior need be tried then). ``sets``: the
    frame's line sets when the caller has them already."""
    obs, W = data.obs, data.obs.width
    if sets is None:
        sets = line_sets(obs, data.model, params.px(MIN_SPAN_PX, W))
    tau = params.px(params.vote_tau, W)
    thr = params.ransac_thresholds[-1]
    out, settled = [], False
    for H, lines, points in sets:
        cam0 = camera_from_plane_homography(H, "ground", W, obs.height, data.model)
        if cam0 is None or _sane(cam0, params):
            continue
        use = np.zeros(obs.n_keypoints, bool)
        use[points] = True
        own = CameraProblem(cam0, data, RefineParams(alpha=0.5, loss="soft_l1", f_scale=tau, max_iter=40),
                            use_keypoints=use, lines=lines, circles=())
        cam, _ = own.solve()
        if _sane(cam, params):
            continue
        err = _kp_errors(cam, obs)
        inl = err < params.px(thr, W)
        rms = float(np.sqrt(np.mean(np.minimum(err, 1e3) ** 2))) if len(err) else 0.0
        out.append(Candidate(LINE_SUBSET, float(thr), "ground", cam, obs.kp_ids[inl], rms))
        r = own.residuals(cam)  # the loss is the solver's: these are the plain weighted residuals
        fits = np.sqrt(np.mean(r * r)) < params.px(params.prior_good_rms, W)
        settled |= bool(fits and len(lines) >= CHECKED_CLASSES)
    return out, settled


# ------------------------------------------------------------------------------ residual reports
def point_residuals(cam: Camera, obs: Observations) -> dict[int, float]:
    return {int(i): float(e) for i, e in zip(obs.kp_ids, _kp_errors(cam, obs))}


def line_residuals(cam: Camera, data: FrameData) -> dict[str, float]:
    """Largest distance (px) of a class's observed points to its projection (lines and circles)."""
    no_keypoints = np.zeros(data.obs.n_keypoints, bool)
    per_class = CameraProblem(cam, data, RefineParams(alpha=1.0), use_keypoints=no_keypoints).class_residuals()
    return {name: float(np.max(r)) for name, r in per_class.items()}


# ------------------------------------------------------------------------------ the camera's part of the pipeline
class CameraKind:
    """The camera in the frame pipeline: candidates from plane homographies decomposed into
    cameras, with inliers over all three planes; refined on them (focal length and pose); the
    broadcast priors when nothing is left; PnL over the pose (and focal length and k1 unless the
    settings say not)."""

    ground_only = False

    def __init__(self, data: FrameData, params: CalibParams, observed: FrameData | None = None):
        """``data``: what the camera is fitted to; ``observed``: the same observations as they were
        seen, which residuals are reported against (default ``data``; they differ when the line
        points on the border are aimed inside: :attr:`CalibParams.border_aim_px`)."""
        self.data, self.params = data, params
        self.observed = data if observed is None else observed
        #: why the last plane camera was refused as no broadcast's (:func:`_sane`), for the failure
        self.refused: str | None = None
        #: the plane fits by (plane, points, threshold), and by (plane, points) the first that kept
        #: every point, with its threshold (see :meth:`_plane_camera`)
        self._plane_fits: dict[tuple[str, bytes, float], tuple[Camera, np.ndarray] | None] = {}
        self._kept_all: dict[tuple[str, bytes], tuple[float, tuple[Camera, np.ndarray]]] = {}

    @classmethod
    def of(cls, obs: Observations, params: CalibParams, model: FieldModel | None = None) -> "CameraKind":
        """The camera kind of a frame's observations, built as ``params`` say."""
        observed = FrameData.build(obs, model or load_field_model())
        aim = params.px(params.border_aim_px, obs.width)
        return cls(observed.aimed_inside(aim) if aim > 0 else observed, params, observed)

    @staticmethod
    def new_result() -> CalibrationResult:
        return CalibrationResult()

    @functools.cached_property
    def line_sets(self) -> list:
        """The frame's line sets (:func:`pnlviz.calib.line_start.line_sets`), found once: whether
        there are any decides :meth:`too_few`, and :meth:`fallback` starts from them."""
        obs = self.data.obs
        return line_sets(obs, self.data.model, self.params.px(MIN_SPAN_PX, obs.width))

    def too_few(self) -> str | None:
        obs, p = self.data.obs, self.params
        needed = 2 if p.prior_search and (obs.lines or obs.circles) else p.min_points
        if obs.n_keypoints >= needed:
            return None
        if p.line_search and self.line_sets:
            return None
        return f"too few keypoints ({obs.n_keypoints} < {needed})"

    def fit(self, sub: Observations, plane: str, on_plane: np.ndarray, local_xy: np.ndarray, thr_px: float):
        """The camera of a RANSAC homography of the plane's points, its inliers over the subset
        (within the threshold, at least 5 px, and the homography's own) and its errors."""
        obs, p = self.data.obs, self.params
        fitted = self._plane_camera(plane, sub.kp_ids[on_plane], local_xy, sub.kp_xy[on_plane], thr_px)
        if fitted is None:
            return None
        cam0, inl_plane = fitted
        insane = _sane(cam0, p)
        if insane:
            self.refused = insane
            return None
        err = _kp_errors(cam0, sub)
        inl = err < max(thr_px, p.px(5.0, obs.width))
        inl[np.flatnonzero(on_plane)[inl_plane]] = True
        return cam0, inl, err

    def _plane_camera(self, plane: str, ids: np.ndarray, local_xy: np.ndarray, xy: np.ndarray,
                      thr_px: float) -> tuple[Camera, np.ndarray] | None:
        """The camera of the plane points' RANSAC homography and its inlier mask over them (None:
        no homography, or no camera from it), fitted once: subsets that share the plane's points
        share the fit (OpenCV's RANSAC is deterministic), and a fit that kept every point is the
        fit of every larger threshold too (RANSAC would keep them all again, and its least-squares
        refit on all of them is the same camera). Thresholds come in increasing order."""
        points = (plane, ids.tobytes())
        every = self._kept_all.get(points)
        if every is not None and every[0] <= thr_px:
            return every[1]
        key = (*points, thr_px)
        if key not in self._plane_fits:
            fit = plane_homography(local_xy, xy, thr_px)
            cam0 = None if fit is None else camera_from_plane_homography(fit[0], plane, self.data.obs.width,
                                                                         self.data.obs.height, self.data.model)
            got = self._plane_fits[key] = None if fit is None or cam0 is None else (cam0, fit[1])
            if got is not None and got[1].all():
                self._kept_all[points] = (thr_px, got)
        return self._plane_fits[key]

    def scorer(self, first: Camera):
        return CameraProblem(first, self.data, RefineParams(alpha=0.5)).residuals  # residuals at any camera

    def vote_taus(self, n: int, tau: float, pin_tau: float) -> np.ndarray:
        """The truncation of each of the scorer's ``n`` residuals: ``pin_tau`` for the pinned
        keypoints' rows (keypoints come first, two rows each), ``tau`` for the rest."""
        taus = np.full(n, tau)
        rows = 2 * np.flatnonzero(self.data.obs.pins)
        taus[np.concatenate([rows, rows + 1])] = pin_tau
        return taus

    def pin_candidates(self) -> list[Candidate]:
        """The camera of the hand-placed ground points alone (:func:`pnlviz.calib.pins.pin_camera`),
        its inliers among every keypoint; none when they cannot give one."""
        obs, p = self.data.obs, self.params
        cam = pin_camera(obs, p.min_hfov_deg, p.max_hfov_deg, p.px(p.max_rms, obs.width))
        if isinstance(cam, PinFailure) or _sane(cam, p):
            return []
        thr = p.ransac_thresholds[-1]
        err = _kp_errors(cam, obs)
        inl = (err < p.px(thr, obs.width)) | obs.pins
        return [Candidate("pins", float(thr), "ground", cam, obs.kp_ids[inl], float(np.sqrt(np.mean(err[inl] ** 2))))]

    def refine(self, c: Candidate) -> Candidate | None:
        return refine_candidate(c, self.data, self.params)

    def fallback(self) -> list[Candidate]:
        """The starts of a frame with too few keypoints: its straight lines first (a few ms), then
        the broadcast priors (up to 72 fits, about a second) unless a line start is settled
        (:func:`line_candidates`)."""
        p = self.params
        lines, settled = line_candidates(self.data, p, self.line_sets) if p.line_search else ([], False)
        if settled:
            return lines
        return lines + (prior_candidates(self.data, p) if p.prior_search else [])

    def degenerate(self) -> str:
        if self.refused:  # the points fit a plane, through a camera no broadcast has
            return f"no camera a broadcast can have: the keypoints fit a {self.refused}"
        planes = plane_masks(self.data.obs.kp_xyz, self.data.model)
        counts = ", ".join(f"{p} {int(m.sum())}" for p, m in planes.items())
        return f"degenerate geometry: no plane with {self.params.min_points} consistent keypoints ({counts})"

    def point_errors(self, cam: Camera) -> dict[int, float]:
        return point_residuals(cam, self.data.obs)

    def class_errors(self, cam: Camera) -> dict[str, float]:
        return line_residuals(cam, self.observed)

    def pnl_solve(self, cam: Camera, keypoints: np.ndarray, lines: list[str], circles: list[str]) -> Camera | None:
        """The paper's PnL (pose, K fixed) or, by default, PnL over pose + focal + k1 (with the
        final loss); None when there is too little to fit or the result is not a sane camera."""
        p = self.params
        intrinsics = p.refine_focal or p.refine_k1
        rp = RefineParams(alpha=p.alpha, refine_focal=p.refine_focal, refine_k1=p.refine_k1,
                          loss=p.final_loss if intrinsics else "linear",
                          f_scale=p.px(p.final_f_scale, self.data.obs.width), tol=p.tol, max_iter=p.pnl_max_iter,
                          **pin_settings(p, self.data.obs.width, self.data.obs))
        prob = CameraProblem(cam, self.data, rp, use_keypoints=keypoints, lines=lines, circles=circles)
        if prob.n_res < prob.n_free + 1:
            return None
        new, _ = prob.solve()
        insane = _sane(new, p)
        # the pitch sampled as the evaluator samples it (0.9 m): a lens that folds it into the image
        # is fitted again without k1
        if not insane and p.refine_k1 and p.refuse_folding_lens \
                and folds_into_view(new, self.data.model.sample_points(0.9)):
            prob = CameraProblem(replace(cam, radial=np.zeros(6)), self.data, replace(rp, refine_k1=False),
                                 use_keypoints=keypoints, lines=lines, circles=circles)
            new, _ = prob.solve()
            insane = _sane(new, p)
        if insane:
            return None
        if intrinsics and p.class_tolerance_px > 0:
            tight = prob.tighten(new, p.px(p.class_tolerance_px, self.data.obs.width))
            if tight is not new and not _sane(tight, p):
                new = tight
        return new


def calibrate(obs: Observations, params: CalibParams = CalibParams(), model: FieldModel | None = None) -> CalibrationResult:
    """Calibrate one frame. Never raises on bad geometry: failures come back with a reason; a
    frame with hand-placed points that cannot give a camera says which condition they fail."""
    whole = CameraKind.of(obs, params, model)
    result = calibrate_with(whole, params)
    if not result.ok and params.one_half_when_both_fail and not obs.pins.any():
        result = _one_half(whole, params) or result
    if not result.ok and obs.pins.any():
        why = pin_camera(obs, params.min_hfov_deg, params.max_hfov_deg, params.px(params.max_rms, obs.width))
        if isinstance(why, PinFailure):
            result.failure, result.failure_code, result.pin_condition = why.message, "pins", why.condition.value
    return result


def _half_of(x: np.ndarray) -> float:
    """-1 for a class entirely on the left half (x < 0), 1 entirely on the right, 0 otherwise."""
    return float(np.sign(x[0])) if np.all(np.sign(np.round(x, 6)) == np.sign(x[0])) else 0.0


def _one_half(whole: CameraKind, params: CalibParams) -> CalibrationResult | None:
    """A frame (``whole``: its observations as the pipeline laid them out) whose keypoints and
    classes name both halves of the pitch and give no camera together, calibrated from each half's
    alone (with those that span both or lie on the half-way line): a detector or an annotator
    unsure of the side names some of one end with the other end's ids. The half whose camera fits
    its inlier keypoints best, or None when neither gives one (``result.half`` says which)."""
    obs, model = whole.observed.obs, whole.observed.model
    side = np.sign(np.round(obs.kp_xyz[:, 0], 6))
    class_side = {n: _half_of(pts[:, 0]) for n, pts in model.sample_polylines(1.0, 1.0).items()}
    named = [*side, *(class_side.get(n, 0.0) for n in (*obs.lines, *obs.circles))]
    if not (min(named, default=0) < 0 < max(named, default=0)):
        return None
    best, best_rms = None, np.inf
    for name, drop in (("left", 1.0), ("right", -1.0)):
        half = replace(obs.subset(side != drop),
                       lines={n: v for n, v in obs.lines.items() if class_side.get(n, 0.0) != drop},
                       circles={n: v for n, v in obs.circles.items() if class_side.get(n, 0.0) != drop})
        result = calibrate_with(CameraKind.of(half, params, model), params)
        if not result.ok:
            continue
        inl = [result.point_residuals[int(k)] for k in result.inliers if int(k) in result.point_residuals]
        rms = float(np.sqrt(np.mean(np.square(inl)))) if inl else np.inf
        if best is None or rms < best_rms:
            best, best_rms = result, rms
            best.half = name
    if best is not None and best.camera is not None:  # every observation's residual, the other half's too
        best.point_residuals = point_residuals(best.camera, obs)
        best.line_residuals = whole.class_errors(best.camera)
    return best


def refit(obs: Observations, start: Camera, params: CalibParams = CalibParams(),
          model: FieldModel | None = None) -> CalibrationResult:
    """``start`` (a camera of this frame, e.g. fitted with one more point) refined on ``obs``
    and judged as :func:`calibrate` judges its own (:func:`pnlviz.calib.pipeline.refit_with`):
    the one solve a leave-one-out check needs, not a new vote."""
    return refit_with(CameraKind.of(obs, params, model), params, start)
