"""Temporal calibration of broadcast clips: shots, and one broadcast camera per shot.

Per-frame calibration ignores that a broadcast camera stands on a tripod head (within a shot its
centre and lens do not move, and pan, tilt, roll and zoom change smoothly), so its cameras jitter
with the detection noise and fail on frames with too few keypoints. A clip, in time order, is cut
into shots (the one rule of :mod:`pnlviz.calib.cuts`: large image changes, or per-frame cameras
that jump to another position, then the hand's cuts), and each shot that has at least one
per-frame camera gets one broadcast camera (:func:`pnlviz.calib.shot_fit.fit_shot`, the model in
:mod:`pnlviz.calib.shot`). Each frame then uses its shot's camera unless that is worse than its own
on its own observations (:mod:`pnlviz.calib.shot_check`); a shot worse on some frames is split
where that helps. This module is the clip's driver, and measures the image changes that mark
cuts.
"""

from __future__ import annotations

import copy
from collections.abc import Iterable, Sequence, Set
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np

from pnlviz.field.model import FieldModel, load_field_model
from pnlviz.geometry.camera import Camera

from .calibrate import CalibParams
from .cuts import CutEdits, apply_cuts, find_shots
from .observations import Observations
from .problem import FrameData
from .shot import FrameDistances, TemporalParams, frame_data
from .shot_check import CameraChoice, alone_kept_by_shot, judge_frame, second_look_choice
from .shot_fit import ShotFit, distances, fit_shot, fit_window, window_of

if TYPE_CHECKING:  # imported when called (frame imports this module's neighbours)
    from .frame import FrameInputs, FrameSettings

__all__ = ["MIN_CLIP", "ClipCalibration", "ClipResult", "ShotPart", "ShotSolver", "calibrate_clip", "calibrate_clip_frames", "image_change",
           "image_changes", "start_cameras"]

#: a clip has at least this many frames, and on average at least this many per shot (else its
#: frames are unrelated pictures)
MIN_CLIP = 3


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


#: a shot split by the fit (:func:`solve_clip`) leaves parts of at least this many frames
MIN_PART = 3
#: a split is tried this many times deep at most (a shot becomes at most 2^depth shots)
SPLIT_DEPTH = 3
#: a shot worse than its frames' own cameras is first fitted again with its motion prior this many
#: times looser (before it is split)
RELAX = 10.0


@dataclass
class ClipResult:
    #: per frame: the camera it uses (``choices[t].use``: the shot's, its own, or None)
    cameras: list[Camera | None]
    #: per frame: index of its shot
    shot_of: list[int]
    shots: list[range]
    #: per shot: its fit (None: no frame of it has a camera to start from)
    fits: list[ShotFit | None]
    #: per frame: which camera it uses and why (:func:`pnlviz.calib.shot_check.judge_frame`)
    choices: list[CameraChoice] = field(default_factory=list)
    #: cuts the fit added: a shot split because its camera was worse than its frames' own
    splits: list[int] = field(default_factory=list)
    #: why the frames are not calibrated as a clip (None: they are)
    unrelated: str | None = None


@dataclass
class ShotPart:
    """A shot: its frames, its fit (None: no frame had a camera to start from) and each frame's
    choice of camera."""

    frames: range
    fit: ShotFit | None
    choices: list[CameraChoice]

    @property
    def worse(self) -> int:
        """Frames whose shot camera is worse than their own."""
        return sum(c.use == "own" for c in self.choices)

    def camera(self, i: int, own: Camera | None) -> Camera | None:
        """The camera the shot's ``i``-th frame uses (``own``: its own camera)."""
        use = self.choices[i].use
        if use == "shot" and self.fit is not None:
            return self.fit.cameras[i]
        return own if use == "own" else None


def calibrate_clip(observations: Sequence[Observations | None], cameras: Sequence[Camera | None],
                   size: tuple[float, float], params: TemporalParams = TemporalParams(),
                   changes: Sequence[float | None] | None = None, model: FieldModel | None = None, *,
                   calib: CalibParams = CalibParams(), cuts: CutEdits = CutEdits(),
                   data: Sequence[FrameData | None] | None = None, looked: Set[int] = frozenset()) -> ClipResult:
    """A clip in time order: ``observations[t]`` and the per-frame ``cameras[t]`` (its own
    calibration, None without one) of its frames, images of ``size`` (W, H), the image
    ``changes`` from each frame to the next when known, the ``cuts`` changed by hand. Returns its
    shots (the one rule of :mod:`pnlviz.calib.cuts`, the fit's splits included), the broadcast
    camera of each shot (:func:`fit_shot`) and the camera each frame uses
    (:func:`pnlviz.calib.shot_check.judge_frame`): its shot's where that is not worse than its
    own. Frames with nothing observed keep no camera. A clip whose shots are mostly single frames
    is a folder of unrelated pictures: each frame keeps its own camera. ``looked``: the frames
    whose camera of their own rests on a second look at their detections (given here as None:
    :func:`pnlviz.calib.looks.for_shot`), for the reason each frame is told."""
    model = model or load_field_model()
    T = len(observations)
    if len(cameras) != T:
        raise ValueError("one camera (or None) per frame")
    fd = list(data) if data is not None else frame_data(observations, model)
    solver = ShotSolver(fd, list(cameras), size, params, calib, model, looked)
    found = find_shots(cameras, changes, params)
    parts, unrelated = solver.solve(found, cuts)
    shots = [p.frames for p in parts]
    out = ClipResult([None] * T, [0] * T, shots, [p.fit for p in parts], [],
                     sorted({s.start for s in shots} - {s.start for s in apply_cuts(found, cuts, T)}), unrelated)
    for k, p in enumerate(parts):
        for i, t in enumerate(p.frames):
            out.shot_of[t] = k
            out.cameras[t] = p.camera(i, cameras[t])
        out.choices += p.choices
    return out


class ShotSolver:
    """Fits and judges the shots of one clip (see :func:`calibrate_clip`): ``data[t]`` each
    frame's observations laid out (None: nothing observed), ``own[t]`` its own camera. Both may be
    changed by the caller between solves (a hand's edit): :meth:`forget` then drops what was
    measured with the old ones. ``stale``: frames whose own camera no longer matches their data
    (edited, not recalibrated yet): they use the shot's camera, which carries the hand's points.
    ``looked``: frames whose camera of their own rests on a second look (not in ``own``): their
    reason says so."""

    def __init__(self, data: list[FrameData | None], own: list[Camera | None], size: tuple[float, float],
                 params: TemporalParams, calib: CalibParams, model: FieldModel, looked: Set[int] = frozenset()):
        self.data, self.own, self.size, self.params, self.calib, self.model = data, own, size, params, calib, model
        self.looked = frozenset(looked)
        self.stale: set[int] = set()
        self._own: dict[int, FrameDistances | None] = {}

    def forget(self, t: int) -> None:
        """Frame ``t``'s data or own camera changed."""
        self._own.pop(t, None)

    def own_distances(self, t: int) -> FrameDistances | None:
        """Frame ``t``'s own camera's distances (measured once: a split judges a frame again)."""
        if t not in self._own:
            d, cam = self.data[t], self.own[t]
            self._own[t] = None if d is None or cam is None else distances(d, cam)
        return self._own[t]

    def detached(self) -> ShotSolver:
        """A copy the caller's later changes to the frames (:attr:`data`, :attr:`own`,
        :attr:`stale`) do not reach: a solve of it can run in another thread while this one takes
        the next edit."""
        out = copy.copy(self)
        out.data, out.own, out.stale, out._own = list(self.data), list(self.own), set(self.stale), dict(self._own)
        return out

    def solve(self, found: Sequence[range], cuts: CutEdits) -> tuple[list[ShotPart], str | None]:
        """The clip's shots from the ``found`` ones and the hand's ``cuts``, each fitted, judged and
        split where that helps; and why the frames are not a clip (None: they are). A clip whose
        shots are mostly single frames is a folder of unrelated pictures: each frame its own
        camera."""
        T = len(self.data)
        shots = apply_cuts(found, cuts, T)
        if T >= MIN_CLIP and len(shots) * MIN_CLIP > T:
            why = f"not a clip: {len(shots)} shots in {T} frames (consecutive frames are unrelated pictures)"
            return [ShotPart(range(t, t + 1), None, [
                CameraChoice("none", "nothing observed on this frame") if self.data[t] is None else
                CameraChoice("own" if self.own[t] is not None else "none", why)]) for t in range(T)], why
        parts: list[ShotPart] = []
        for shot in shots:
            parts += self.split(self.part(shot), cuts.removed, SPLIT_DEPTH)
        return parts, None

    def part(self, frames: range, start: ShotFit | None = None) -> ShotPart:
        """Shot ``frames`` fitted (warm from ``start`` when given) and each frame judged. From the
        frames' own cameras, a shot worse than some of them is fitted again with a prior
        :data:`RELAX` times looser (a camera that moves faster than the prior expects: frames
        sampled sparsely from a video, a whip pan), kept when fewer frames are worse."""
        part = self._fit(frames, start, self.params)
        if start is None and part.worse and part.fit is not None:
            loose = replace(self.params, accel_deg=RELAX * self.params.accel_deg,
                            accel_log_f=RELAX * self.params.accel_log_f)
            other = self._fit(frames, None, loose)
            if other.worse < part.worse:
                return other
        return part

    def window_part(self, part: ShotPart, t: int) -> ShotPart:
        """``part`` solved again after an edit on its frame ``t``, around that frame only
        (:func:`~pnlviz.calib.shot_fit.fit_window`), the frames there judged again: a provisional
        answer, drawn while :meth:`part` solves the whole shot."""
        if part.fit is None:
            raise ValueError("a shot without a fit has no window to solve again")
        i = t - part.frames.start
        fit = fit_window([self.data[u] for u in part.frames], part.fit, i, self.size, self.params, self.calib)
        choices = list(part.choices)
        for j in window_of(i, len(part.frames)):
            choices[j] = self._judge(part.frames.start + j, j, fit)
        return ShotPart(part.frames, fit, alone_kept_by_shot(choices))

    def _fit(self, frames: range, start: ShotFit | None, params: TemporalParams) -> ShotPart:
        fd = [self.data[t] for t in frames]
        own = [self.own[t] for t in frames]
        fit = None
        if start is not None or any(c is not None for c in own):
            fit = fit_shot([None if d is None else d.obs for d in fd], self._start(frames, own, params), self.size,
                           params, self.model, start=start, calib=self.calib, data=fd)
        return ShotPart(frames, fit, alone_kept_by_shot([self._judge(t, i, fit) for i, t in enumerate(frames)]))

    def _start(self, frames: range, own: list[Camera | None], params: TemporalParams) -> list[Camera | None]:
        """The own cameras a cold solve starts from: not the stale ones, not the outliers
        (:func:`start_cameras`), unless that leaves none."""
        fresh = [None if t in self.stale else c for t, c in zip(frames, own)]
        for candidates in (start_cameras(fresh, params), fresh, own):
            if any(c is not None for c in candidates):
                return candidates
        return own

    def _judge(self, t: int, i: int, fit: ShotFit | None) -> CameraChoice:
        if t in self.stale and fit is not None and fit.converged and self.data[t] is not None:
            return CameraChoice("shot", "corrected by hand: the shot's camera carries the hand's points")
        choice = judge_frame(self.data[t], None if fit is None else fit.cameras[i], self.own[t], self.params,
                             self.calib, True if fit is None else fit.converged,
                             shot_distances=None if fit is None or fit.distances is None else fit.distances[i],
                             own_distances=self.own_distances(t))
        if t in self.looked and self.own[t] is None:
            return second_look_choice(choice)
        return choice

    def split(self, part: ShotPart, removed: frozenset[int], depth: int) -> list[ShotPart]:
        """``part`` split where that leaves fewer frames worse off than their own cameras and the
        two parts' cameras stand apart (centres farther apart than ``cut_centre_m``: a cut to
        another camera position, not one camera fitted twice), in parts of :data:`MIN_PART` frames
        at least, never at a cut in ``removed``; each half split again down to ``depth``; else
        ``[part]``."""
        if depth <= 0 or not part.worse or len(part.frames) < 2 * MIN_PART:
            return [part]
        best: tuple[ShotPart, ShotPart] | None = None
        for t in self._candidates(part):
            if t in removed:
                continue
            a, b = self.part(range(part.frames.start, t)), self.part(range(t, part.frames.stop))
            apart = (a.fit is None or b.fit is None
                     or float(np.linalg.norm(a.fit.C - b.fit.C)) > self.params.cut_centre_m)
            if apart and a.worse + b.worse < (part.worse if best is None else best[0].worse + best[1].worse):
                best = (a, b)
        if best is None:
            return [part]
        return self.split(best[0], removed, depth - 1) + self.split(best[1], removed, depth - 1)

    def _candidates(self, part: ShotPart) -> list[int]:
        """Where to try a split: where the frames' own centres change (the split that leaves the
        least sum of distances of each part's centres to their median), and the ends of the
        longest run of frames worse off."""
        lo, hi = part.frames.start + MIN_PART, part.frames.stop - MIN_PART
        out: list[int] = []
        known = [(t, c.C) for t in part.frames if (c := self.own[t]) is not None]
        costs = {}
        for t in range(lo, hi + 1):
            a = np.array([C for u, C in known if u < t])
            b = np.array([C for u, C in known if u >= t])
            if len(a) and len(b):
                costs[t] = float(np.linalg.norm(a - np.median(a, axis=0), axis=1).sum()
                                 + np.linalg.norm(b - np.median(b, axis=0), axis=1).sum())
        if costs:
            out.append(min(costs, key=lambda t: costs[t]))
        worse = [c.use == "own" for c in part.choices]
        runs, i = [], 0
        while i < len(worse):
            j = i
            while j < len(worse) and worse[j] == worse[i]:
                j += 1
            if worse[i]:
                runs.append((j - i, i, j))
            i = j
        if runs:
            _, i, j = max(runs)
            out += [part.frames.start + i, part.frames.start + j]
        return [t for t in dict.fromkeys(out) if lo <= t <= hi]


def start_cameras(own: Sequence[Camera | None], params: TemporalParams) -> list[Camera | None]:
    """The frames' own cameras to start a shot's solve from, without those whose centre is
    farther than ``cut_centre_m`` from the shot's median centre (a frame with few or wrong
    keypoints: its neighbours place it)."""
    known = [c.C for c in own if c is not None]
    if not known:
        return list(own)
    centre = np.median(np.array(known), axis=0)
    return [c if c is not None and np.linalg.norm(c.C - centre) <= params.cut_centre_m else None for c in own]


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


def calibrate_clip_frames(inputs: Sequence[FrameInputs | None], settings: FrameSettings, *,
                          cameras: Sequence[Camera | None] | None = None,
                          changes: Sequence[float | None] | None = None,
                          model: FieldModel | None = None, cuts: CutEdits = CutEdits(),
                          temporal: TemporalParams = TemporalParams()) -> ClipCalibration:
    """A clip as ``pnlviz calibrate --temporal`` calibrates it: ``inputs`` are the frames'
    :class:`pnlviz.calib.frame.FrameInputs` in time order (None: unreadable), all of one size, and
    ``settings`` their :class:`~pnlviz.calib.frame.FrameSettings`. The per-frame cameras (computed
    with :func:`~pnlviz.calib.frame.calibrate_frame` unless given), the frames' observations, and
    :func:`calibrate_clip` with the shot's lens fitted the way the frames' calibration fits it (no
    k1 for detections whose detector says ``refine_k1: false``). The shots fit each frame's
    detections above the detector's first thresholds (:func:`pnlviz.calib.looks.for_shot`): a
    frame those change has no camera of its own there (its first reading gave none: that is why
    it holds a second look)."""
    from .frame import calib_params, calibrate_frame
    from .looks import shot_observations

    model = model or load_field_model()
    sizes = {(i.size[0], i.size[1]) for i in inputs if i is not None}
    if len(sizes) != 1:
        raise ValueError("the frames of a clip must have one size")
    if cameras is None:
        cameras = [calibrate_frame(i, settings, model).camera if i is not None else None for i in inputs]
    found = [(None, None, False) if i is None else shot_observations(i, settings, model) for i in inputs]
    calib = calib_params(settings, next((g for _, g, _ in found if g is not None), None))
    looked = {t for t, (_, _, second) in enumerate(found) if second}
    cameras = [None if t in looked else c for t, c in enumerate(cameras)]
    obs = [o for o, _, _ in found]
    params = replace(temporal, fit_k1=calib.refine_k1)
    result = calibrate_clip(obs, list(cameras), sizes.pop(), params, changes=changes, model=model, calib=calib,
                            cuts=cuts, looked=looked)
    return ClipCalibration(list(cameras), obs, result)
