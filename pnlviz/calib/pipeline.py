"""The pipeline of one frame, the same for the camera and the ground homography (paper Sec.
"Camera Parameters Estimation", "Homography Estimation" and "Point and Line Refinement Module"):

1. **candidates**: per keypoint subset (:data:`pnlviz.calib.voting.SUBSETS`) and RANSAC threshold,
   a plane homography fitted to the subset's keypoints on one plane (the ground, or a goal plane
   x = +-52.5 when the ground has too few), turned into the model (a camera, or the homography
   itself); identical inlier sets are kept once;
2. **the heuristic vote**: every candidate scored on *all* observations with a truncated quadratic
   ``sum(min(r^2, tau^2))``; the best ``refine_top`` are refined on their inliers and scored
   again; the lowest score wins, ``full`` on ties;
3. **PnL**: lines, circles and keypoints gated by the voted model, then the model refined against
   ``alpha * lines + (1 - alpha) * points`` (:mod:`pnlviz.calib.problem`, the one solver); gated
   again at the refined model and refined again while that lets more through;
4. the evidence (residuals before and after, the candidates) and the verdict: a model whose
   inlier keypoints are farther than ``max_rms`` (RMS) is a failure.

What differs between the models is a :class:`Kind`: the camera (:mod:`pnlviz.calib.calibrate`,
all three planes, the 3D rig) and the ground homography (:mod:`pnlviz.calib.homography`, the
ground-plane subset of everything: keypoints, lines and circles). Pixel thresholds are given at
960 px image width and scaled with the width (``params.px``).

Pinned keypoints (placed or moved by hand, ``Observations.pins``; :mod:`pnlviz.calib.pins`) are
in every subset and every candidate's inliers, count in the vote up to ``pin_vote_px`` (where the
others count up to ``vote_tau``), join PnL whatever their residual, and are left out of the
verdict's RMS when flagged (farther than ``pin_flag_px`` from the camera: the result says so).
Without pins every step is what it was.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol, TypeVar

import numpy as np

from pnlviz.calib.line_start import CHECKED_CLASSES, LINE_SUBSET
from pnlviz.calib.observations import Observations
from pnlviz.calib.pins import flagged_pins
from pnlviz.calib.problem import FrameData
from pnlviz.calib.voting import best, subset_mask, truncated_score
from pnlviz.field.model import FieldModel

@dataclass(eq=False)  # compared by identity: fields hold arrays
class Candidate:
    subset: str
    threshold: float
    plane: str
    estimate: Any  #: the model: a Camera, or a 3x3 homography
    inliers: np.ndarray  # keypoint ids
    rms: float
    score: float = np.inf


@dataclass
class FrameResult:
    """One frame's estimate (``None``: a failure, with ``failure`` in words and ``failure_code``,
    one of :data:`pnlviz.calib.calibrate.FAILURE_CODES`) and the evidence for it: the voted
    candidate's subset, threshold, plane and inlier keypoint ids, the residuals (px) of each
    keypoint and of each line or circle class (its farthest point) before and after PnL, the
    classes PnL used, and every candidate of both votes."""

    estimate: Any = None
    initial_estimate: Any = None
    subset: str | None = None
    threshold: float | None = None
    plane: str | None = None
    inliers: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    point_residuals_initial: dict[int, float] = field(default_factory=dict)
    point_residuals: dict[int, float] = field(default_factory=dict)
    line_residuals_initial: dict[str, float] = field(default_factory=dict)
    line_residuals: dict[str, float] = field(default_factory=dict)
    pnl_lines: list[str] = field(default_factory=list)
    candidates: list[dict] = field(default_factory=list)
    failure: str | None = None
    failure_code: str | None = None
    pinned: list[int] = field(default_factory=list)  #: ids of the pinned (hand-placed) keypoints
    flagged: dict[int, float] = field(default_factory=dict)  #: pinned ids the camera cannot agree with -> residual px
    pin_condition: str | None = None  #: the :class:`pnlviz.calib.pins.PinCondition` that failed, if one did
    #: ids of the derived keypoints the final fit left out (all of them, when its lines and circles
    #: fix the model alone: :func:`lines_alone`); the verdict judges the other inliers if any
    lines_alone: list[int] = field(default_factory=list)
    #: "left" or "right": the frame's keypoints named both halves and gave no camera together, and
    #: this one comes from that half's keypoints alone (the others left out); None otherwise
    half: str | None = None

    @property
    def ok(self) -> bool:
        return self.estimate is not None


ResultT_co = TypeVar("ResultT_co", bound=FrameResult, covariant=True)
ResultT = TypeVar("ResultT", bound=FrameResult)


class Kind(Protocol[ResultT_co]):
    """What the pipeline needs of a model, for one frame (``data``) and its settings; its results
    are ``ResultT_co``."""

    data: FrameData
    ground_only: bool  #: keypoints off the ground plane take no part (the homography)

    def new_result(self) -> ResultT_co: ...  # an empty result of the model's type

    def too_few(self) -> str | None: ...  # why the frame has too few keypoints, or None

    def fit(self, sub: Observations, plane: str, on_plane: np.ndarray, local_xy: np.ndarray,
            threshold_px: float) -> tuple[Any, np.ndarray, np.ndarray] | None: ...  # (estimate, inliers, errors)

    def scorer(self, first: Any): ...  # estimate -> the residuals the vote scores

    def refine(self, c: Candidate) -> Candidate | None: ...

    def fallback(self) -> list[Candidate]: ...  # candidates when no refined one is left

    def degenerate(self) -> str: ...  # why no candidate, in words

    def point_errors(self, estimate) -> dict[int, float]: ...

    def class_errors(self, estimate) -> dict[str, float]: ...

    def pnl_solve(self, estimate, keypoints: np.ndarray, lines: list[str], circles: list[str]) -> Any | None: ...


def plane_frame(plane: str, model: FieldModel) -> tuple[np.ndarray, np.ndarray]:
    """Rotation ``B`` (rows: local x', y', z' in world) and origin of a plane's local frame in
    which the plane is z' = 0 and the camera side is z' < 0."""
    hl = model.dimensions["pitch_length"] / 2
    if plane == "goal_left":  # x = -52.5, pitch side x > -52.5: z' = -(x + 52.5)
        return np.array([[0.0, 0, 1], [0, 1, 0], [-1, 0, 0]]), np.array([-hl, 0.0, 0.0])
    if plane == "goal_right":  # x = +52.5, pitch side x < 52.5: z' = x - 52.5
        return np.array([[0.0, 1, 0], [0, 0, 1], [1, 0, 0]]), np.array([hl, 0.0, 0.0])
    return np.eye(3), np.zeros(3)


def plane_masks(xyz: np.ndarray, model: FieldModel) -> dict[str, np.ndarray]:
    """The points (N, 3) on each plane a candidate may be fitted on: the ground, the goal planes."""
    hl = model.dimensions["pitch_length"] / 2
    return {"ground": np.abs(xyz[:, 2]) < 1e-9,
            "goal_left": np.abs(xyz[:, 0] + hl) < 1e-9,
            "goal_right": np.abs(xyz[:, 0] - hl) < 1e-9}


def make_candidates(kind: Kind, params) -> list[Candidate]:
    """Step 1: per (subset, threshold), ``kind.fit`` on the ground plane (a goal plane, the one
    with the most points, when the ground has too few), with its inliers over the subset.
    Identical inlier sets are kept once; a subset with the same points as an earlier one is
    skipped (OpenCV's RANSAC is deterministic)."""
    obs, model = kind.data.obs, kind.data.model
    seen: set[tuple] = set()
    out: list[Candidate] = []
    thresholds = {params.px(t, obs.width): t for t in params.ransac_thresholds}
    done: set[bytes] = set()
    pins = obs.pins & (obs.ground if kind.ground_only else True)
    for subset in params.subsets:
        mask = subset_mask(obs, subset, kind.ground_only) | pins
        if mask.sum() < params.min_points or mask.tobytes() in done:
            continue
        done.add(mask.tobytes())
        sub = obs.subset(mask)
        planes = plane_masks(sub.kp_xyz, model)
        if planes["ground"].sum() >= params.min_points:
            order = ["ground"]
        else:
            order = sorted((p for p in planes if p != "ground" and planes[p].sum() >= params.min_points),
                           key=lambda p: -planes[p].sum())
        for plane in order:
            pm = planes[plane]
            B, origin = plane_frame(plane, model)
            local = (sub.kp_xyz[pm] - origin) @ B.T
            found = False
            for thr_px in thresholds:
                fit = kind.fit(sub, plane, pm, local[:, :2], thr_px)
                if fit is None:
                    continue
                estimate, inl, err = fit
                inl = inl | sub.pins
                key = tuple(sub.kp_ids[inl])
                found = True
                if key in seen:
                    continue
                seen.add(key)
                out.append(Candidate(subset, thresholds[thr_px], plane, estimate, sub.kp_ids[inl],
                                     float(np.sqrt(np.mean(err[inl] ** 2)))))
            if found:
                break
    extra = getattr(kind, "pin_candidates", None)
    if pins.any() and extra is not None:
        out += [c for c in extra() if tuple(c.inliers) not in seen]
    return out


def vote(cands: list[Candidate], kind: Kind, params) -> Candidate | None:
    """Step 2: truncated-quadratic score of each candidate on all observations; lowest wins
    (pinned keypoints truncated at ``pin_vote_px``: see ``kind.vote_taus``)."""
    if not cands:
        return None
    obs = kind.data.obs
    tau = params.px(params.vote_tau, obs.width)
    taus = getattr(kind, "vote_taus", None) if obs.pins.any() else None  # per-observation bounds with pins
    # only a kind with per-observation bounds has pins' own (the homography's parameters have none)
    pin_tau = params.px(params.pin_vote_px, obs.width) if taus is not None else tau
    residuals = kind.scorer(cands[0].estimate)
    for c in cands:
        r = residuals(c.estimate)
        c.score = truncated_score(r, tau if taus is None else taus(len(r), tau, pin_tau))
    return best(cands)


def _gated(obs: Observations, params, line_errors: Mapping[str, float],
           point_errors: Mapping[int, float]) -> tuple[np.ndarray, list[str], list[str]]:
    """The keypoints (mask), lines and circles that pass PnL's gates at these residuals: a line
    or circle when all its observed points are within ``line_gate_px`` (``line_errors``: their
    farthest), a keypoint when within ``point_gate_px``; pinned keypoints always."""
    gate_l = params.px(params.line_gate_px, obs.width)
    gate_p = params.px(params.point_gate_px, obs.width)
    lines = [k for k in obs.lines if line_errors.get(k, np.inf) < gate_l]
    circles = [k for k in obs.circles if line_errors.get(k, np.inf) < gate_l]
    kp_ok = (np.array([point_errors.get(int(i), np.inf) for i in obs.kp_ids]).reshape(-1) < gate_p) | obs.pins
    return kp_ok, lines, circles


def _classes_fix_it(params, lines: Sequence[str], circles: Sequence[str]) -> bool:
    """At least ``params.lines_alone_classes`` line and circle classes (0: never)."""
    return bool(params.lines_alone_classes) and len(lines) + len(circles) >= params.lines_alone_classes


def left_out(obs: Observations, params, lines: Sequence[str], circles: Sequence[str]) -> np.ndarray:
    """Mask of the derived keypoints (``Observations.kp_derived``) a fit with these classes leaves
    out: all of them when at least ``params.lines_alone_classes`` line and circle classes are in
    it (they repeat those classes, computed from them as straight lines under a pinhole where the
    fit has the lens, and the classes alone fix the model's eight parameters), else none."""
    return obs.derived.copy() if _classes_fix_it(params, lines, circles) else np.zeros(obs.n_keypoints, bool)


def lines_alone(obs: Observations, params, keypoints: np.ndarray, lines: list[str], circles: list[str]) -> np.ndarray:
    """The keypoints PnL fits, of those that passed the gates: without the derived ones
    :func:`left_out` names."""
    return keypoints & ~left_out(obs, params, lines, circles)


def pnl_set(obs: Observations, params, keypoints: np.ndarray, lines: Sequence[str], circles: Sequence[str],
            unmarked: Mapping[int, str]) -> tuple[np.ndarray, list[str], list[str]]:
    """What PnL fits of what passed the gates: the keypoints :func:`lines_alone` keeps, and the
    classes, but for a class made of nothing but detected points no paint marks (``unmarked``:
    :meth:`FieldModel.unmarked_points`, added to their marking as its points) while those
    keypoints are fitted (fewer classes than ``params.lines_alone_classes``): they count once."""
    kp = lines_alone(obs, params, keypoints, list(lines), list(circles))
    if _classes_fix_it(params, lines, circles):
        return kp, list(lines), list(circles)
    stand_in: dict[str, list[np.ndarray]] = {}
    for k, xy, use in zip(obs.kp_ids, obs.kp_xy, kp & obs.derived):
        if use and int(k) in unmarked:
            stand_in.setdefault(unmarked[int(k)], []).append(xy)

    def repeated(name: str, points: np.ndarray) -> bool:
        held = np.asarray(stand_in.get(name) or np.zeros((0, 2)))
        return len(held) > 0 and all(np.any(np.all(held == p, axis=1)) for p in np.asarray(points))

    return (kp, [n for n in lines if not repeated(n, obs.lines[n])],
            [n for n in circles if not repeated(n, obs.circles[n])])


def pnl_refine(estimate, kind: Kind, params, line_errors: dict[str, float],
               point_errors: dict[int, float]) -> tuple[Any, list[str], np.ndarray]:
    """Step 3: the lines, circles and keypoints that pass the gates at ``estimate`` (:func:`_gated`,
    :func:`pnl_set`), then ``kind.pnl_solve``. The voted estimate can be several pixels off,
    so a class it gates out may be within the gate of the refined one: the gates are applied
    again at the refined estimate and, when they let something more through, solved again from
    there with it, up to ``params.regate_rounds`` times. Nothing that passed is dropped (on a frame
    with four keypoints and two lines, dropping one that the refined model moved away from let the
    next solve drift: three synthetic frames lost their camera).

    Returns the estimate, the classes it fitted (:func:`pnl_set`) and the mask of the derived
    keypoints it left out (:func:`left_out`; the estimate unchanged, no class and none left out
    when the solve had too little to go on or failed)."""
    obs, unmarked = kind.data.obs, kind.data.model.unmarked_points()
    kp_ok, lines, circles = _gated(obs, params, line_errors, point_errors)
    fit = pnl_set(obs, params, kp_ok, lines, circles, unmarked)
    new = kind.pnl_solve(estimate, *fit)
    if new is None:
        return estimate, [], np.zeros(obs.n_keypoints, bool)
    for _ in range(params.regate_rounds):
        gated = _gated(obs, params, kind.class_errors(new), kind.point_errors(new))
        again = (kp_ok | gated[0], [k for k in obs.lines if k in lines or k in gated[1]],
                 [k for k in obs.circles if k in circles or k in gated[2]])
        if np.array_equal(again[0], kp_ok) and again[1:] == (lines, circles):
            break
        fit_again = pnl_set(obs, params, *again, unmarked)
        newer = kind.pnl_solve(new, *fit_again)
        if newer is None:
            break
        new, (kp_ok, lines, circles), fit = newer, again, fit_again
    return new, sorted(fit[1] + fit[2]), left_out(obs, params, lines, circles)


def calibrate_with(kind: Kind[ResultT], params) -> ResultT:
    """The whole frame (steps 1-4), as ``kind.new_result()``. Never raises on bad geometry:
    failures come back with a reason."""
    result = kind.new_result()
    why = kind.too_few()
    if why:
        result.failure, result.failure_code = why, "too_few_keypoints"
        return result
    raw = make_candidates(kind, params)
    # vote on the raw candidates, refine the best few, vote again among the refined ones
    vote(raw, kind, params)
    raw.sort(key=lambda c: c.score)
    cands = [r for r in (kind.refine(c) for c in raw[: params.refine_top]) if r is not None]
    if not cands:
        cands = kind.fallback()
    winner = vote(cands, kind, params)
    result.candidates = [{"stage": stage, "subset": c.subset, "threshold": c.threshold, "plane": c.plane,
                          "inliers": len(c.inliers), "rms": c.rms, "score": c.score, "won": c is winner}
                         for stage, group in (("candidate", raw), ("refined", cands)) for c in group]
    if winner is None:
        result.failure, result.failure_code = kind.degenerate(), "degenerate"
        return result
    result.subset, result.threshold, result.plane, result.inliers = winner.subset, winner.threshold, winner.plane, \
        winner.inliers
    _finish(result, winner.estimate, kind, params)
    return result


def refit_with(kind: Kind[ResultT], params, start) -> ResultT:
    """Steps 3-4 alone, from ``start`` (an estimate the caller has: the frame's own, fitted
    with one more point), as ``kind.new_result()``: the keypoints within the largest RANSAC
    threshold of ``start`` (and the pinned ones) are its inliers, then PnL and the verdict as
    :func:`calibrate_with` does them. One solve where a calibration makes and votes on dozens of
    candidates: for leave-one-out checks (:func:`pnlviz.calib.pins.slips`). A frame too few for
    :func:`calibrate_with` is a failure here too."""
    obs = kind.data.obs
    result = kind.new_result()
    why = kind.too_few()
    if why:
        result.failure, result.failure_code = why, "too_few_keypoints"
        return result
    errors = kind.point_errors(start)
    reach = params.px(params.ransac_thresholds[-1], obs.width)
    near = np.array([errors.get(int(i), np.inf) < reach for i in obs.kp_ids], bool).reshape(-1) | obs.pins
    result.subset, result.threshold, result.plane, result.inliers = "start", float(params.ransac_thresholds[-1]), \
        "start", obs.kp_ids[near]
    _finish(result, start, kind, params, solve=True)
    return result


class _LastErrors:
    """``kind`` with the errors of the last estimate asked about kept, handed out as copies:
    :func:`_finish` asks twice about the estimate PnL ends at (to gate again, then for the result)
    and about one PnL did not move (before and after). Everything else is ``kind``'s own."""

    def __init__(self, kind: Kind):
        self._kind = kind
        self._last: dict[str, tuple[Any, dict]] = {}

    def __getattr__(self, name: str) -> Any:
        return getattr(self._kind, name)

    def point_errors(self, estimate) -> dict[int, float]:
        return self._remembered("points", estimate, self._kind.point_errors)

    def class_errors(self, estimate) -> dict[str, float]:
        return self._remembered("classes", estimate, self._kind.class_errors)

    def _remembered(self, what: str, estimate, compute) -> dict:
        last = self._last.get(what)
        if last is None or last[0] is not estimate:
            last = self._last[what] = (estimate, compute(estimate))
        return dict(last[1])


def _finish(result: FrameResult, estimate, kind: Kind, params, solve: bool = False) -> None:
    """Steps 3 and 4 on ``result`` from ``estimate``, the voted (or given) model; the solve runs
    with PnL and something to refine against, or always with ``solve`` (a given model is not
    fitted to these observations yet)."""
    kind = _LastErrors(kind)
    obs = kind.data.obs
    result.estimate = result.initial_estimate = estimate
    result.point_residuals_initial = kind.point_errors(estimate)
    result.line_residuals_initial = kind.class_errors(estimate)
    if solve or (params.pnl and (obs.lines or obs.circles)):
        estimate, result.pnl_lines, out = pnl_refine(estimate, kind, params, result.line_residuals_initial,
                                                     result.point_residuals_initial)
        result.lines_alone = [int(i) for i in obs.kp_ids[out]]
    result.estimate = estimate
    result.point_residuals = kind.point_errors(estimate)
    result.line_residuals = kind.class_errors(estimate)
    if obs.pins.any():
        result.pinned = [int(i) for i in obs.kp_ids[obs.pins]]
        limit = params.px(getattr(params, "pin_flag_px", 10.0), obs.width)
        result.flagged = flagged_pins(obs, result.point_residuals, limit)
    _verdict(result, obs, params)


def _verdict(result: FrameResult, obs: Observations, params) -> None:
    """Step 4: no estimate when no inlier keypoint has a residual, or their RMS is above ``max_rms``.
    The inliers judged are those that are not derived keypoints the final fit left out
    (:func:`lines_alone`: they are not measurements) when any remain; when the fit left out every
    inlier (its lines and circles fixed it alone), the farthest point of each class it fitted
    (the derived keypoints repeat those classes, computed as straight lines under a pinhole: an
    intersection of two detected lines far outside the image can be tens of pixels off a camera
    that sits on both lines). A fit with no inlier keypoint at all is judged by its classes the
    same way when they fix it alone (``lines_alone_classes``: a frame whose lines meet outside
    the image, started from them by :mod:`pnlviz.calib.line_start`). A camera started from the
    lines with no measured keypoint must fit :data:`pnlviz.calib.line_start.CHECKED_CLASSES`
    classes: four lines fix a homography exactly, a wrong one among them too."""
    inlier_ids = [int(i) for i in obs.kp_ids[np.isin(obs.kp_ids, result.inliers)]
                  if int(i) in result.point_residuals and int(i) not in result.flagged]
    fitted = [i for i in inlier_ids if i not in result.lines_alone]
    if fitted or (inlier_ids and not result.lines_alone):
        inlier_residuals = [result.point_residuals[i] for i in (fitted or inlier_ids)]
    elif result.lines_alone or _classes_fix_it(params, result.pnl_lines, ()):
        inlier_residuals = [result.line_residuals[c] for c in result.pnl_lines if c in result.line_residuals]
    else:
        inlier_residuals = []
    if not inlier_residuals:
        result.estimate, result.failure_code = None, "no_inliers"
        result.failure = "no keypoint agrees with the camera (no inliers)"
        return
    if result.subset == LINE_SUBSET and len(result.pnl_lines) < CHECKED_CLASSES and \
            not set(fitted) - {int(i) for i in obs.kp_ids[obs.derived]}:  # no measured keypoint fitted
        result.estimate, result.failure_code = None, "degenerate"
        result.failure = (f"degenerate geometry: the camera started from the lines fits {len(result.pnl_lines)} "
                          "classes, no more than fix it, and no measured keypoint: nothing checks them")
        return
    rms = float(np.sqrt(np.mean(np.square(inlier_residuals))))
    limit = params.px(params.max_rms, obs.width)
    if not rms <= limit:
        result.estimate, result.failure_code = None, "residual"
        result.failure = f"residual above the limit (inlier RMS {rms:.1f} px > {limit:.1f})"
