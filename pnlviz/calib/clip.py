"""A clip under correction: hand edits drive the shot model, so a shot is corrected once, not
every frame.

:class:`ClipSolver` holds a clip in time order: each frame's own observations (detections or an
annotation), the keypoint edits made on its frames (``{"id": [x, y] | None}``, as the edits folder
stores them), each frame's own camera (its per-frame calibration, with its edits), the shots (the
one rule of :mod:`pnlviz.calib.cuts`, as ``pnlviz calibrate --temporal`` finds them: the cuts
found, the hand's :class:`~pnlviz.calib.cuts.CutEdits`, the fit's splits) and one broadcast camera
per shot (:func:`pnlviz.calib.shot_fit.fit_shot`), with the camera each frame uses: its shot's,
unless that is worse than its own on its own observations (:mod:`pnlviz.calib.shot_check`).

* **edits are constraints of the shot**: a point moved or placed on any frame is a pinned keypoint
  of its shot's solve (it weighs ``pin_weight`` times more and is never dropped, as a pin is on a
  single frame, :mod:`pnlviz.calib.pins`); a hidden point leaves the frame's observations. After
  an edit the shot is solved again from its previous solution (a warm start: a few iterations),
  and every frame of it gets its new camera;
* **edits teach the shot which detections to trust**: a detector errs alike on the frames of one
  shot (the same view of the same marking), so a detected keypoint the hand hid, or moved by more
  than :data:`DISTRUST_PX`, on one frame of a shot is left out of the shot's solve on its other
  frames too, and out of their labels (:meth:`ClipSolver.distrusted`), where a point the hand
  placed is carried instead;
* **labels of every frame** (:meth:`ClipSolver.labels`), each with its provenance: the frame's own
  observations (``annotation`` / ``detection``), the hand's (``hand``), and ``shot``: a keypoint
  placed by hand on one frame, carried to the neighbouring frames of its shot through their
  cameras for as long as it stays in view (until it leaves the image, is hidden, or is placed by
  hand again).

Pure (numpy / scipy, no I/O): the app, the export and the benchmark call the same.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from pnlviz.conventions import PROVENANCES
from pnlviz.field.model import FieldModel, load_field_model
from pnlviz.geometry.camera import Camera
from pnlviz.labels.types import Label

from .calibrate import CalibParams, calibrate
from .carried import carried_points
from .cuts import CutEdits, apply_cuts, find_shots
from .observations import Observations
from .problem import FrameData
from .shot import TemporalParams
from .shot_check import CameraChoice
from .shot_fit import ShotFit, distances
from .sources import apply_keypoint_edits
from .temporal import ShotPart, ShotSolver

__all__ = ["DISTRUST_PX", "PROVENANCE", "QUICK_MIN_FRAMES", "ClipSolver", "ShotJob", "carried_points"]

#: a detected keypoint the hand moved farther than this (px at 960 px width) is not trusted on the
#: shot's other frames (3 x the detection noise of :class:`TemporalParams`)
DISTRUST_PX = 4.5

#: where a clip frame's label comes from
PROVENANCE = PROVENANCES

#: a shot this long gets a quick provisional solve around an edit before its full one
#: (:meth:`ClipSolver.quick_solve`; a 64-frame shot's full solve takes about 40 ms)
QUICK_MIN_FRAMES = 64


def _own_camera(params: CalibParams, model: FieldModel, obs: Observations | None) -> Camera | None:
    """A frame's own camera from its observations (None: it has none)."""
    if obs is None or obs.n_keypoints == 0:
        return None
    try:
        r = calibrate(obs, params, model)
    except Exception:  # noqa: BLE001 - a frame without its own camera is placed by its shot
        return None
    return r.camera if r.ok else None


@dataclass
class ShotJob:
    """A full solve of one shot from its state when the job was made (:meth:`ClipSolver.solve_job`):
    :meth:`run` touches nothing of the solver it came from, so it can run outside the caller's
    lock; :meth:`ClipSolver.install` then takes its answer unless the shot changed meanwhile."""

    frames: range
    worker: ShotSolver
    start: ShotFit | None
    #: nothing changed the shot since the job was made (it is still worth running)
    current: Callable[[], bool]
    part: ShotPart | None = None
    seconds: float = 0.0

    def run(self) -> ShotJob:
        t0 = time.perf_counter()
        self.part = self.worker.part(self.frames, start=self.start)
        self.seconds = time.perf_counter() - t0
        return self


@dataclass
class ClipSolver:
    """A clip under correction (see the module docstring). ``observations[t]``: frame t's own
    observations without edits (None: nothing); ``size``: (W, H) of its frames; ``cameras``: the
    frames' own cameras when known (else calibrated here with ``calib_params``); ``changes``: the
    image change from each frame to the next (:func:`pnlviz.calib.temporal.image_changes`);
    ``origins[t]``: what frame t's own labels are called: "annotation" or "detection", or per
    keypoint ``{id: provenance}`` (a frame seen through its annotation and its detections,
    :func:`pnlviz.pipeline.snapshot.provenance`: the one rule a frame's own review uses)."""

    observations: Sequence[Observations | None]
    size: tuple[int, int]
    params: TemporalParams = field(default_factory=TemporalParams)
    calib_params: CalibParams = field(default_factory=CalibParams)
    cameras: Sequence[Camera | None] | None = None
    changes: Sequence[float | None] | None = None
    cuts: CutEdits = field(default_factory=CutEdits)
    origins: Sequence[str | Mapping[int, str]] | None = None
    model: FieldModel | None = None
    #: the keypoint edits made so far: ``{frame: {"id": [x, y] | None}}`` (``cameras``, when given,
    #: are the frames' own cameras with them)
    keypoint_edits: Mapping[int, Mapping[str, Sequence[float] | None]] | None = None
    #: frames whose camera of their own rests on a second look at their detections: ``cameras``
    #: gives them none, their observations hold what the shot fits (:func:`pnlviz.calib.looks.for_shot`)
    looked: frozenset[int] = frozenset()

    def __post_init__(self):
        self.field_model: FieldModel = self.model or load_field_model()
        self.T = len(self.observations)
        self.base = list(self.observations)
        self.edits: dict[int, dict[str, list[float] | None]] = {}
        for t, e in (self.keypoint_edits or {}).items():
            if e:
                self.edits[int(t)] = {str(int(k)): (None if v is None else [float(v[0]), float(v[1])])
                                      for k, v in e.items()}
        data = [self._frame_data(t) for t in range(self.T)]
        own = ([_own_camera(self.calib_params, self.field_model, d.obs if d else None) for d in data]
               if self.cameras is None else list(self.cameras))
        self._solver = ShotSolver(data, own, self.size, self.params, self.calib_params, self.field_model, self.looked)
        #: the shots found (before the hand's cuts; the fit's splits included)
        found = find_shots(own, self.changes, self.params)
        parts, self.unrelated = self._solver.solve(found, self.cuts)
        starts = {s.start for s in found} | ({p.frames.start for p in parts} - {
            s.start for s in apply_cuts(found, self.cuts, self.T)})
        self.found = apply_cuts([range(0, self.T)], CutEdits(frozenset(starts)), self.T)
        self._parts = parts
        self._seconds = [0.0] * len(parts)
        self._labels: dict[int, dict[int, Label]] | None = None
        #: per frame: what its error was measured from (its camera, data and shot distances, held
        #: so that their ids stay theirs) and the error; an entry is good while they are the same
        #: objects (a quick answer changes a window of the shot, not its other frames)
        self._errors: dict[int, tuple[tuple, float]] = {}
        self._carried_by_shot: dict[int, dict[int, dict[int, np.ndarray]]] | None = None
        self._drop: list[frozenset[int]] = [frozenset()] * len(parts)
        #: per shot (by its first frame): when it last changed (a job made before is no answer)
        self._stamps: dict[int, int] = {}
        self._clock = 0
        #: how long the latest :meth:`quick_solve` took (seconds)
        self.quick_seconds = 0.0
        for k in range(len(parts)):  # the edits made before: their shots leave the detections they corrected out
            if self._trust(k):
                self._solve(k, warm=False)

    @property
    def own(self) -> list[Camera | None]:
        """Each frame's own camera (a stale one is recalibrated by :meth:`own_camera`)."""
        return self._solver.own

    # ------------------------------------------------------------------ what the clip is
    @property
    def shots(self) -> list[range]:
        return [p.frames for p in self._parts]

    def shot_of(self, t: int) -> int:
        """The index of frame ``t``'s shot."""
        for k, p in enumerate(self._parts):
            if t in p.frames:
                return k
        raise IndexError(f"frame {t} is not in the clip of {self.T} frames")

    def fit(self, k: int) -> ShotFit | None:
        return self._parts[k].fit

    def solve_seconds(self, k: int) -> float:
        """How long shot ``k``'s latest solve took."""
        return self._seconds[k]

    def choice(self, t: int) -> CameraChoice:
        """Which camera frame ``t`` uses, and why."""
        p = self._parts[self.shot_of(t)]
        return p.choices[t - p.frames.start]

    def camera(self, t: int) -> Camera | None:
        """Frame ``t``'s camera: its shot's (None when the shot has none, or the frame has nothing
        observed), or its own where the shot's is worse (:meth:`choice` says which and why)."""
        p = self._parts[self.shot_of(t)]
        return p.camera(t - p.frames.start, self._solver.own[t])

    def own_camera(self, t: int) -> Camera | None:
        """Frame ``t``'s own camera: its per-frame calibration, with its edits."""
        if t in self._solver.stale:
            self._solver.stale.discard(t)
            d = self._solver.data[t]
            self._solver.own[t] = _own_camera(self.calib_params, self.field_model, d.obs if d is not None else None)
            self._solver.forget(t)
            self._labels = self._carried_by_shot = None  # a frame on its own camera shows another
        return self._solver.own[t]

    def cameras_of(self) -> list[Camera | None]:
        return [self.camera(t) for t in range(self.T)]

    @property
    def keyframes(self) -> list[int]:
        """The frames a hand corrected, in order."""
        return sorted(t for t, e in self.edits.items() if e)

    def frame_observations(self, t: int) -> Observations | None:
        """Frame ``t``'s observations with its edits applied (pins for the points placed by hand)."""
        obs, edits = self.base[t], self.edits.get(t)
        if not edits:
            return obs
        if obs is None:
            W, H = self.size
            obs = Observations(int(W), int(H))
        return apply_keypoint_edits(obs, edits, self.field_model)

    def shown_observations(self, t: int) -> Observations | None:
        """Frame ``t``'s observations as its shot uses and shows them: with its edits, without the
        detections the shot distrusts (:meth:`distrusted`)."""
        data = self._solver.data[t]
        return None if data is None else data.obs

    def distrusted(self, k: int) -> frozenset[int]:
        """The keypoint ids whose detections the hand corrected on a frame of shot ``k`` (hid, or
        moved by more than :data:`DISTRUST_PX`): left out of the shot's solve on its other frames."""
        limit = DISTRUST_PX * float(self.size[0]) / 960.0
        out: set[int] = set()
        for t in self._parts[k].frames:
            edits, base = self.edits.get(t), self.base[t]
            if not edits or base is None:
                continue
            detected = {int(kid): base.kp_xy[i] for i, kid in enumerate(base.kp_ids)
                        if self.provenance(t, int(kid)) == "detection"}
            for key, v in edits.items():
                kid = int(key)
                if kid in detected and (v is None or float(np.hypot(*(np.asarray(v) - detected[kid]))) > limit):
                    out.add(kid)
        return frozenset(out)

    def _trust(self, k: int) -> bool:
        """Shot ``k``'s frames laid out again when its distrusted ids changed; whether they did."""
        drop = self.distrusted(k)
        if drop == self._drop[k]:
            return False
        self._drop[k] = drop
        for t in self._parts[k].frames:
            self._solver.data[t] = self._frame_data(t, drop)
            self._solver.forget(t)
        return True

    def _frame_data(self, t: int, drop: frozenset[int] = frozenset()) -> FrameData | None:
        """Frame ``t``'s observations laid out for the shot's solve, without the detections of
        the ``drop`` ids (the pins stay)."""
        obs = self.frame_observations(t)
        if obs is None:
            return None
        if drop and obs.n_keypoints:
            obs = obs.subset(~np.isin(obs.kp_ids, list(drop)) | obs.pins)
        return FrameData.build(obs, self.field_model)

    # ------------------------------------------------------------------ edits
    def set_edits(self, t: int, edits: Mapping[str, Sequence[float] | None] | None, solve: bool = True) -> int:
        """Frame ``t``'s keypoint edits (``{"id": [x, y] | None}``; None or empty: none): its own
        camera recalibrated when next asked for, its shot solved again (warm) unless ``solve`` is
        off. Returns the shot."""
        t = int(t)
        if edits:
            self.edits[t] = {str(int(k)): (None if v is None else [float(v[0]), float(v[1])]) for k, v in edits.items()}
        else:
            self.edits.pop(t, None)
        k = self.shot_of(t)
        self._changed(k)  # a job made before this edit is no answer to it
        self._solver.data[t] = self._frame_data(t, self._drop[k])
        self._solver.stale.add(t)  # its own camera: recalibrated when asked for (it can take a second)
        self._solver.forget(t)
        self._trust(k)
        if solve:
            self._solve(k, warm=True)
        return k

    def set_keypoint(self, t: int, kid: int, xy: Sequence[float] | None, solve: bool = True) -> int:
        """Keypoint ``kid`` of frame ``t`` moved or placed at ``xy`` (pixels) or hidden (None)."""
        edits: dict[str, Sequence[float] | None] = dict(self.edits.get(t) or {})
        edits[str(int(kid))] = None if xy is None else [float(xy[0]), float(xy[1])]
        return self.set_edits(t, edits, solve)

    def set_cut(self, t: int, cut: bool) -> None:
        """A cut before frame ``t`` added (``cut``) or removed by hand; the shots it touches are
        solved again from the frames' own cameras, the others keep their solution."""
        for k in range(len(self._parts)):  # the shots kept keep a full answer
            self.settle(k)
        self.cuts = self.cuts.with_cut(t, cut)
        old = {(p.frames.start, p.frames.stop): (p, sec) for p, sec in zip(self._parts, self._seconds)}
        parts, seconds = [], []
        for r in apply_cuts(self.found, self.cuts, self.T):
            kept = old.get((r.start, r.stop))
            t0 = time.perf_counter()
            parts.append(kept[0] if kept else self._solver.part(r))
            seconds.append(kept[1] if kept else time.perf_counter() - t0)
        self._parts, self._seconds = parts, seconds
        self._drop = [frozenset()] * len(parts)
        for t in range(self.T):
            self._solver.data[t] = self._frame_data(t)
        for k in range(len(parts)):
            self._changed(k)  # a job made before the cut is no answer to it
            if self._trust(k):
                self._solve(k, warm=False)

    def solve(self, k: int | None = None, warm: bool = True) -> None:
        """Solve shot ``k`` (every shot when None) again."""
        for j in range(len(self._parts)) if k is None else [k]:
            self._solve(j, warm)

    # ------------------------------------------------------------------ an edit's answer in two steps
    def quick_solve(self, t: int) -> bool:
        """After an edit on frame ``t`` (:meth:`set_edits` with ``solve`` off): its shot solved
        again around ``t`` only (:meth:`ShotSolver.window_part`), an answer to draw at once; False
        (nothing done) for a shot shorter than :data:`QUICK_MIN_FRAMES` frames or without a fit,
        which a full solve answers as fast. The shot's fit is ``provisional`` until a full solve
        (:meth:`solve`, :meth:`install`, :meth:`settle`); :attr:`quick_seconds`: how long it took."""
        k = self.shot_of(t)
        p = self._parts[k]
        if len(p.frames) < QUICK_MIN_FRAMES or p.fit is None:
            return False
        t0 = time.perf_counter()
        self._parts[k] = self._solver.window_part(p, t)
        self.quick_seconds = time.perf_counter() - t0
        self._changed(k)
        return True

    def solve_job(self, k: int) -> ShotJob:
        """Shot ``k``'s full solve (warm, from its present answer) as a job to run anywhere."""
        p = self._parts[k]
        frames, stamp = p.frames, self._stamps.get(p.frames.start, 0)

        def current() -> bool:
            return self._stamps.get(frames.start, 0) == stamp and any(q.frames == frames for q in self._parts)

        return ShotJob(frames, self._solver.detached(), p.fit, current)

    def install(self, job: ShotJob) -> bool:
        """Take a :class:`ShotJob`'s answer; False (nothing changes) when its shot changed since
        the job was made (a later edit: its own job answers it) or the job has not run."""
        if job.part is None or not job.current():
            return False
        k = next(j for j, p in enumerate(self._parts) if p.frames == job.frames)
        self._parts[k], self._seconds[k] = job.part, job.seconds
        self._changed(k)
        return True

    def settle(self, k: int) -> None:
        """Shot ``k`` fully solved now if its answer is a quick one (``fit(k).provisional``:
        before its cameras are written down, a review's snapshot, an accepted shot)."""
        fit = self._parts[k].fit
        if fit is not None and fit.provisional:
            self._solve(k, warm=True)

    def _changed(self, k: int) -> None:
        """Shot ``k`` has another answer: what was derived from the old one goes."""
        self._clock += 1
        self._stamps[self._parts[k].frames.start] = self._clock
        self._labels = self._carried_by_shot = None

    # ------------------------------------------------------------------ labels
    def labels(self, t: int) -> dict[int, Label]:
        """Frame ``t``'s labels with provenance (see the module docstring), computed when asked
        for (the points carried through its shot once per shot and solve)."""
        if self._labels is None:
            self._labels = {}
        if t not in self._labels:
            self._labels[t] = self._frame_labels(t)
        return self._labels[t]

    def provenance(self, t: int, kid: int) -> str:
        """What frame ``t``'s own keypoint ``kid`` is called (see ``origins``): "annotation" or
        "detection"."""
        own = self.origins[t] if self.origins is not None else None
        if isinstance(own, Mapping):
            return own.get(kid, "detection")
        return own or "detection"

    def _frame_labels(self, t: int) -> dict[int, Label]:
        obs, cam = self.shown_observations(t), self.camera(t)
        labels: dict[int, Label] = {}
        if obs is not None and obs.n_keypoints:
            res = np.hypot(*(cam.project(obs.kp_xyz) - obs.kp_xy).T) if cam is not None else None
            for i, kid in enumerate(obs.kp_ids.tolist()):
                r = None if res is None or not np.isfinite(res[i]) else float(res[i])
                labels[int(kid)] = Label(float(obs.kp_xy[i, 0]), float(obs.kp_xy[i, 1]), str(obs.kp_sets[i]),
                                         "hand" if obs.pins[i] else self.provenance(t, int(kid)), r)
        k = self.shot_of(t)
        if self._carried_by_shot is None:
            self._carried_by_shot = {}
        if k not in self._carried_by_shot:  # the hand's points carried through the shot, once per solve
            frames = self._parts[k].frames
            cams: list[Camera | None] = [None] * self.T
            for u in frames:
                cams[u] = self.camera(u)
            self._carried_by_shot[k] = carried_points(frames, self.edits, cams, self.field_model)
        for kid, uv in self._carried_by_shot[k].get(t, {}).items():
            if kid not in labels:
                labels[kid] = Label(float(uv[0]), float(uv[1]), self.field_model.keypoints[kid].group, "shot", 0.0)
        return labels

    # ------------------------------------------------------------------ internals
    def frame_error(self, t: int) -> float:
        """What the app ranks frame ``t`` by: the median distance (px) of its observations (each
        keypoint, the farthest point of each line and circle, the left-out ones too) to the camera
        it uses; inf without one. Measured again only when what it is measured from changed (the
        clip's strip asks for every frame on every redraw)."""
        cam, d = self.camera(t), self._solver.data[t]
        p = self._parts[self.shot_of(t)]
        i = t - p.frames.start
        fit, shot_distances, shot = p.fit, None, False
        if p.choices[i].use == "shot" and fit is not None and fit.distances is not None:
            shot_distances, shot = fit.distances[i], True
        key = (cam, d, shot_distances)
        held = self._errors.get(t)
        if held is not None and all(a is b for a, b in zip(held[0], key)):
            return held[1]
        if cam is None or d is None:
            error = float("inf") if cam is None else 0.0
        else:
            m = shot_distances if shot else distances(d, cam)
            r = m.values() if m is not None else np.zeros(0)
            r = np.sort(r[np.isfinite(r)])  # the median of a few values (np.median costs ten times as much)
            error = float(r[(len(r) - 1) // 2] + r[len(r) // 2]) / 2 if len(r) else 0.0
        self._errors[t] = (key, error)
        return error

    def _solve(self, k: int, warm: bool) -> None:
        p = self._parts[k]
        t0 = time.perf_counter()
        start = p.fit if warm and p.fit is not None else None
        self._parts[k] = self._solver.part(p.frames, start=start)
        self._seconds[k] = time.perf_counter() - t0
        self._changed(k)
