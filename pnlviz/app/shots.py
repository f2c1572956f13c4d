"""The shot models of the app's clips (no GUI here): what a clip frame shows is its shot's camera
(:class:`pnlviz.calib.clip.ClipSolver`, built by :func:`pnlviz.pipeline.clip.clip_solver`), and
an edit on any frame of a shot solves the shot again, so every frame of it updates.

A clip's model is built in the background once every frame of the clip has its detections (the
frames' own cameras come from their views: the triage pass has computed most of them); until then
a clip frame shows its own camera. It follows the edits folder: a frame whose keypoint edits
change (an edit, an undo, another tab) is handed to the solver, which solves its shot from the
previous solution (well under a second for a 90-frame shot); new detections of a frame drop the
model, built again. Accepting a shot reviews all its frames at once
(:func:`pnlviz.pipeline.clip.accept_shot`).
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, replace

from pnlviz.calib.calibrate import CalibrationResult
from pnlviz.app.host import FrameHost
from pnlviz.calib.clip import ClipSolver
from pnlviz.pipeline.clip import accept_shot, clip_changes, clip_solver, dataset_clips, set_cut, shot_snapshot

__all__ = ["SHOT_SUBSET", "ClipShots", "ShotPlace"]

#: the ``subset`` of a result that is a clip frame's shot camera (the card says so)
SHOT_SUBSET = "shot"


@dataclass(frozen=True)
class ShotPlace:
    """Where a frame is: its clip, the clip's stems in frame order, its index there, and the
    clip's model (None while it is being built)."""

    clip: str
    stems: list[str]
    t: int
    solver: ClipSolver | None


class ClipShots:
    """The clips' shot models of one session, shared by its tabs: made by
    :class:`pnlviz.app.state.AppState` (:attr:`~pnlviz.app.state.AppState.shots`) with the frames
    as its parts see them (``host``, :class:`pnlviz.app.host.FrameHost`)."""

    def __init__(self, host: FrameHost):
        self.host = host
        self.clips = dataset_clips(host.stems)
        self._where = {s: (name, t) for name, members in self.clips.items() for t, s in enumerate(members)}
        self._solvers: dict[tuple, ClipSolver] = {}
        self._building: set[tuple] = set()
        self._gates: dict[tuple, threading.Lock] = {}
        self._lock = threading.RLock()
        #: ``callback(stems, provisional)`` after a shot was solved again: its frames show another
        #: camera (``provisional``: a quick answer, the full one follows)
        self._shot_listeners: list = []
        #: full solves waiting for :meth:`finish`, ``(model key, model, job)``, per thread: the thread
        #: whose edit made the quick answer runs them (its caller returns with the full answer in)
        self._pending = threading.local()

    def listen(self, callback) -> None:
        """Call ``callback(stems, provisional)`` with the frames of a shot whenever it is solved
        again after an edit (the tabs showing any of them redraw). ``provisional``: the quick answer
        of :meth:`changed`, which the full one follows within a few hundred ms (a tab may draw the
        picture and leave its panel until then)."""
        self._shot_listeners.append(callback)

    def place(self, stem: str, settings, build: bool = True) -> ShotPlace | None:
        """The frame's clip and model (None outside a clip); ``build``: start building the model
        in the background when there is none (once the clip's frames all have detections)."""
        where = self._where.get(stem)
        if where is None:
            return None
        clip, t = where
        key = (clip, settings)
        with self._lock:
            solver = self._solvers.get(key)
            if solver is None and build and key not in self._building and self._ready(clip):
                self._building.add(key)
                threading.Thread(target=self._build, args=(key,), name="pnlviz-shots", daemon=True).start()
        if solver is not None and solver.unrelated:
            return None  # its frames are unrelated pictures: no shot model (each frame its own camera)
        return ShotPlace(clip, self.clips[clip], t, solver)

    def unrelated(self, clip: str) -> str | None:
        """Why ``clip`` turned out not to be a video (its frames are unrelated pictures), once a
        model of it was built; None otherwise."""
        with self._lock:
            return next((s.unrelated for (c, _), s in self._solvers.items() if c == clip and s.unrelated), None)

    def _ready(self, clip: str) -> bool:
        return not any(self.host.needs_detection(s) for s in self.clips[clip])

    def build(self, clip: str, settings) -> ClipSolver:
        """The clip's model under ``settings`` (built now, in this thread, when there is none).

        One model per clip and settings: a caller that comes while another thread builds it waits
        for that build and gets the same model (two builds racing would leave the tabs showing one
        model and the edits going to the other)."""
        key = (clip, settings)
        with self._lock:
            solver = self._solvers.get(key)
            if solver is not None:
                return solver
            gate = self._gates.setdefault(key, threading.Lock())
        with gate:
            with self._lock:
                solver = self._solvers.get(key)
            if solver is not None:
                return solver
            stems = self.clips[clip]
            host = self.host
            cams = []
            for s in stems:
                view = host.view(s, settings, keep=False)
                cams.append(view.result.camera if view.result is not None and view.result.ok else None)
            solver = clip_solver(host.reader, clip, stems, settings, changes=clip_changes(host.reader, stems),
                                 model=host.model, cameras=cams)
            with self._lock:
                self._solvers[key] = solver
                for t, s in enumerate(stems):  # edits made while it was built
                    edits = dict(host.edits.get(s).get("keypoints") or {})
                    if edits != solver.edits.get(t, {}):
                        solver.set_edits(t, edits)
        return solver

    def _build(self, key: tuple) -> None:
        try:
            self.build(*key)
        finally:
            with self._lock:
                self._building.discard(key)
        for s in self.clips[key[0]]:
            self.host.notify(s)  # what the clip's frames show changed: the tabs showing one redraw

    def changed(self, stem: str) -> None:
        """A frame changed (its edits, its review, its detections): its clip's models follow.

        An edit on a long shot is answered twice: here a quick solve around the edited frame
        (:meth:`ClipSolver.quick_solve`), which the tabs on the shot's other frames draw at once;
        the full solve waits for :meth:`finish`."""
        where = self._where.get(stem)
        if where is None:
            return
        clip, t = where
        record = self.host.edits.get(stem)
        solved: set[str] = set()
        quick: set[str] = set()
        with self._lock:
            for key, solver in list(self._solvers.items()):
                if key[0] != clip:
                    continue
                if stem in self.host.reader.detected and not solver.base[t]:  # detections came: built again
                    del self._solvers[key]
                    continue
                edits = dict(record.get("keypoints") or {})
                if edits != solver.edits.get(t, {}):
                    k = solver.set_edits(t, edits, solve=False)
                    if solver.quick_solve(t):
                        self._jobs().append((key, solver, solver.solve_job(k)))
                        quick |= {self.clips[clip][u] for u in solver.shots[k]}
                    else:
                        solver.solve(k)
                        self._after_solve(key, solver, k)
                        solved |= {self.clips[clip][u] for u in solver.shots[k]}
        # the edited frame's tabs redraw as it changed
        self._tell(solved - {stem})
        self._tell(quick - solved - {stem}, provisional=True)

    def finish(self) -> None:
        """The full solves the quick answers of this thread's :meth:`changed` wait for, run outside
        the lock (the tabs draw meanwhile) and taken unless a later edit came first (its own job
        answers it); the tabs on their shots redraw again (usually a fraction of a pixel off the
        quick answer; a few pixels where the edit moved the shot's centre). A solve that fails
        leaves its shot provisional (settled before anything is written down) and the others
        still run; its error is raised after them."""
        jobs, self._pending.jobs = self._jobs(), []
        failed: Exception | None = None
        for key, solver, job in jobs:
            with self._lock:
                if not job.current():
                    continue
            try:
                job.run()
            except Exception as exc:  # noqa: BLE001 - raised below, once the other shots are solved
                failed = failed or exc
                self._tell({self.clips[key[0]][u] for u in job.frames})  # what the quick answer left
                continue
            with self._lock:
                if not solver.install(job):
                    continue
                self._after_solve(key, solver, solver.shot_of(job.frames.start))
            self._tell({self.clips[key[0]][u] for u in job.frames})
        if failed is not None:
            raise failed

    def _jobs(self) -> list[tuple]:
        """This thread's full solves waiting for :meth:`finish`."""
        if not hasattr(self._pending, "jobs"):
            self._pending.jobs = []
        return self._pending.jobs

    def _after_solve(self, key: tuple, solver: ClipSolver, k: int) -> None:
        if key[1] == self.host.default_settings:
            self._refresh_reviewed(key[0], solver, k, key[1])

    def _tell(self, stems: set[str], provisional: bool = False) -> None:
        if stems:
            for callback in list(self._shot_listeners):
                callback(sorted(stems), provisional)

    def _refresh_reviewed(self, clip: str, solver: ClipSolver, k: int, settings) -> None:
        """The frames of shot ``k`` reviewed with their shot record what it shows now."""
        stems = self.clips[clip]
        for t in solver.shots[k]:
            snap = (self.host.edits.get(stems[t]).get("snapshot") or {})
            if snap.get("shot") is not None:  # the tabs are being told already (this runs as they are)
                self.host.write(stems[t], snapshot=shot_snapshot(self.host.reader, solver, clip, stems, t, settings),
                                notify=False)

    def snapshot(self, stem: str, settings) -> dict | None:
        """The review snapshot of a frame reviewed with its shot, as the shot shows it now (None
        outside a clip)."""
        place = self.place(stem, settings, build=False)
        if place is None:
            return None
        self.changed(stem)
        solver = place.solver or self.build(place.clip, settings)
        with self._lock:
            solver.settle(solver.shot_of(place.t))
        return shot_snapshot(self.host.reader, solver, place.clip, place.stems, place.t, settings)

    def shot_view(self, view, settings):
        """``view`` (a frame's own :class:`pnlviz.pipeline.view.FrameView`) as its shot model
        shows it: the shot's camera and the residuals of the frame's points to it; ``view``
        itself outside a clip or while the model is being built."""
        place = self.place(view.stem, settings)
        if place is None or place.solver is None or view.observations is None:
            return view
        choice = place.solver.choice(place.t)
        if choice.use != "shot":
            return replace(view, shot_note=f"the frame's **own camera**: {choice.reason}")
        cam = place.solver.camera(place.t)
        if cam is None:
            return view
        labels = place.solver.labels(place.t)
        residuals = {k: lab.residual for k, lab in labels.items()
                     if lab.residual is not None and lab.provenance != "shot"}
        result = CalibrationResult(estimate=cam, subset=SHOT_SUBSET, point_residuals=residuals,
                                   pinned=[k for k, lab in labels.items() if lab.provenance == "hand"])
        return replace(view, result=result, measured_jac={}, shot_note=f"why the shot's camera here: {choice.reason}")

    def strip(self, stem: str, settings) -> tuple[list[float], list[int], list[int]] | None:
        """The clip's strip under its model: each frame's error to its shot's camera, the cuts
        (first frames of the shots after the first) and the keyframes; None without a model."""
        place = self.place(stem, settings, build=False)
        if place is None or place.solver is None:
            return None
        s = place.solver
        return [s.frame_error(t) for t in range(s.T)], [r.start for r in s.shots[1:]], s.keyframes

    def shot_stems(self, stem: str, settings) -> list[str] | None:
        """The frames of the frame's shot (built now if needed), in frame order; None outside a clip."""
        place = self.place(stem, settings, build=False)
        if place is None:
            return None
        solver = place.solver or self.build(place.clip, settings)
        return [place.stems[t] for t in solver.shots[solver.shot_of(place.t)]]

    def accept(self, stem: str, settings) -> list[str]:
        """Accept the frame's whole shot (built now if needed); the stems reviewed."""
        place = self.place(stem, settings, build=False)
        if place is None:
            return []
        solver = place.solver or self.build(place.clip, settings)
        k = solver.shot_of(place.t)
        with self._lock:
            solver.settle(k)
        return accept_shot(self.host.reader, solver, place.clip, place.stems, k, settings, write=self.host.write)

    def toggle_cut(self, stem: str, settings) -> bool | None:
        """Add a cut before the frame (remove it when there is one); True when there is one now,
        None outside a clip or at its first frame."""
        place = self.place(stem, settings, build=False)
        if place is None or place.t == 0:
            return None
        solver = place.solver or self.build(place.clip, settings)
        cut = place.t not in {r.start for r in solver.shots}
        with self._lock:
            set_cut(self.host.reader, solver, place.clip, place.t, cut)
            for key, other in list(self._solvers.items()):  # the other settings' models follow the saved cuts
                if key[0] == place.clip and other is not solver:
                    del self._solvers[key]
        self._tell(set(place.stems))  # the clip's frames show other shots: every tab on them redraws
        return cut

