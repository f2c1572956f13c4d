"""Triage over the whole dataset: a small summary of every frame's calibration (calibrated or
why not, worst and median residual, JaC@5), what the filters, the counts and the sorts use, and
the background pass that detects (when a detector is there) and calibrates every frame once,
keeping only those summaries in memory.

Both are cached on disk in the edits folder's ``cache/`` (safe to delete): ``summaries.jsonl``
(one summary per line, the last line of a frame wins) and ``detections.jsonl`` (the detector's
results, one frame per line, read back on demand through an index of offsets: a 23,000-frame
dataset keeps offsets in memory, not detections). A pass that was stopped resumes where it was:
a frame whose summary still matches its settings, its edits and whether it has detections is
not calibrated again.
"""

from __future__ import annotations

import json
import math
import threading
import time
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from pnlviz.app.host import FrameHost
from pnlviz.calib.solver import Cancelled, cancellable
from pnlviz.data import DataError
from pnlviz.data.edits_layout import EditsLayout
from pnlviz.data.predictions import parse_predictions, predictions_to_json
from pnlviz.data.state_files import JsonLinesFile, state_folder



@dataclass(frozen=True)
class FrameSummary:
    """What triage keeps of a frame's view: ``ok`` (it has a camera), why not (``failure``), its
    largest and median residual (px; 0 without any), JaC@5 against its annotation (None without),
    and the ``token`` of the inputs it was computed from (:func:`summary_token`)."""

    stem: str
    ok: bool
    failure: str | None
    worst: float
    median: float
    jac5: float | None
    token: str
    suspect: float | None = None  #: the label-error finder's score (pnlviz.calib.qa; None: not judged)
    suspect_note: str | None = None  #: its worst finding, in words

    @property
    def error(self) -> float:
        """The clip strip's error: the median residual, ``inf`` without a camera."""
        return self.median if self.ok else math.inf


def summary_from_json(obj) -> FrameSummary | None:
    """A summary as kept in ``summaries.jsonl``, None for anything else (a damaged line)."""
    def number(v, optional: bool = False) -> bool:
        return (optional and v is None) or (type(v) in (int, float) and math.isfinite(v))

    def text(v, optional: bool = False) -> bool:
        return (optional and v is None) or (isinstance(v, str) and len(v) <= 10000)

    if not isinstance(obj, dict) or set(obj) - set(FrameSummary.__dataclass_fields__):
        return None
    ok = (text(obj.get("stem")) and type(obj.get("ok")) is bool and text(obj.get("failure"), True)
          and number(obj.get("worst")) and number(obj.get("median")) and number(obj.get("jac5"), True)
          and text(obj.get("token")) and number(obj.get("suspect"), True) and text(obj.get("suspect_note"), True))
    return FrameSummary(**obj) if ok else None


def summary_token(settings, digest: str, has_detections: bool) -> str:
    """What a summary depends on: the settings, the frame's edits (their ``digest``,
    :func:`pnlviz.data.snapshot.edits_digest`), whether it has detections."""
    return f"{settings.source}|{int(settings.pnl)}|{settings.alpha:g}|{digest}|{int(has_detections)}"


def same_inputs(token: str, other: str) -> bool:
    """Two tokens with the same settings and edits (whether detections came since aside): a
    summary stays shown until the frame is calibrated again, never discarded."""
    return token.rsplit("|", 1)[0] == other.rsplit("|", 1)[0]


def summarize(view, token: str, judge: bool = False) -> FrameSummary:
    """A frame's view (:class:`pnlviz.pipeline.view.FrameView`) as a summary; with ``judge``, its
    annotation judged by the label-error finder too (:func:`suspect_score`)."""
    result = view.result
    ok = result is not None and result.ok
    r = list(result.point_residuals.values()) + list(result.line_residuals.values()) if ok else []
    failure = None if ok else (view.error or (result.failure if result is not None else "nothing to calibrate from"))
    suspect, note = suspect_score(view) if judge else (None, None)
    return FrameSummary(view.stem, ok, failure, float(max(r)) if r else 0.0, float(np.median(r)) if r else 0.0,
                        view.jac.get(5) if ok else None, token, suspect, note)


#: what :func:`judge_view` returns, asked not to judge, for a frame not judged yet
NOT_JUDGED = object()


def judge_view(view, judge: bool = True):
    """The label-error finder's verdict on the frame's annotation (its edits applied) and its
    detections, exactly as ``pnlviz qa`` judges the frame with the same inputs
    (:func:`pnlviz.calib.qa.check_frame` with its own calibration, so a frame whose annotation
    gives no camera is judged too: a class that breaks it is found by leaving each out); None for
    a frame without an annotation. Without ``judge``, only a verdict already reached (else
    :data:`NOT_JUDGED`: judging costs one to 26 calibrations). Raises what the finder raises."""
    from pnlviz.calib.qa import check_frame

    if not view.annotation:
        return None
    key = _judge_key(view)
    with _JUDGED_LOCK:
        if key in _JUDGED:
            return _JUDGED[key]
    if not judge:
        return NOT_JUDGED
    qa = check_frame(view.annotation, tuple(view.size), view.detections)
    with _JUDGED_LOCK:
        _JUDGED[key] = qa
        while len(_JUDGED) > 512:
            _JUDGED.popitem(last=False)
    return qa


#: the verdicts of the frames judged lately, by what they depend on: a keypoint dragged changes
#: neither the annotation nor the detections, so the frame is not judged again (it costs one to
#: 26 calibrations)
_JUDGED: OrderedDict = OrderedDict()
_JUDGED_LOCK = threading.Lock()


def _judge_key(view) -> tuple:
    """What the label-error finder's verdict on a view depends on: its annotation, its size, its
    detections."""
    import hashlib

    h = hashlib.sha1()
    for name in sorted(view.annotation):
        h.update(name.encode())
        h.update(np.ascontiguousarray(np.asarray(view.annotation[name], float)).tobytes())
    dets = "" if view.detections is None else json.dumps(predictions_to_json(view.detections), sort_keys=True)
    h.update(dets.encode())
    return h.hexdigest(), tuple(view.size)


def fix_frame(state, stem: str, settings=None):
    """Apply the suggested fix of the frame's worst finding that has one (the label-error
    finder's, on the frame as the tab shows it) as an ordinary annotation edit, undoable like
    any other: the finding, or None when there is nothing to fix (a frame without an annotation
    is not judged)."""
    from pnlviz.calib.qa import apply_fix

    view = state.view(stem, settings)
    qa = judge_view(view)
    finding = next((f for f in qa.findings if f.fix is not None), None) if qa is not None else None
    if finding is not None and finding.fix is not None:
        state.set_annotation(stem, apply_fix(view.annotation, finding.fix))
    return finding


def suspect_score(view) -> tuple[float | None, str | None]:
    """The label-error finder's score of a frame's annotation, and its worst finding in words
    (:func:`judge_view`: what ``pnlviz qa`` says of it); (None, None) for a frame it does not judge."""
    try:
        qa = judge_view(view)
    except Exception:  # noqa: BLE001 - a bug here must not stop the background pass: the frame is not judged
        return None, None
    if qa is None:
        return None, None
    return round(qa.score, 3), (qa.findings[0].message if qa.findings else None)


class DetectionCache:
    """The detector's results by stem, on disk (``detections.jsonl``), a few kept in memory: a
    mapping as :class:`pnlviz.pipeline.FrameReader` looks detections up (``get``, ``in``)."""

    def __init__(self, path: Path | None, warnings: list[str] | None = None, keep: int = 64):
        self._file = JsonLinesFile(path, [] if warnings is None else warnings)
        self._where: dict[str, tuple[int, int]] = {}
        self._recent: OrderedDict[str, object] = OrderedDict()
        self._memory: dict[str, object] = {}  # without a file (read-only edits folder)
        self._keep = keep
        self._lock = threading.Lock()
        for offset, length, obj in self._file.lines():
            if isinstance(obj, dict) and isinstance(obj.get("stem"), str):
                self._where[obj["stem"]] = (offset, length)

    def __contains__(self, stem) -> bool:
        return stem in self._where or stem in self._memory

    def __len__(self) -> int:
        return len(set(self._where) | set(self._memory))

    def __setitem__(self, stem: str, pred) -> None:
        where = self._file.append({"stem": stem, "detections": predictions_to_json(pred)})
        with self._lock:
            if where is None:
                self._memory[stem] = pred
            else:
                self._where[stem] = where
                self._remember(stem, pred)

    def _remember(self, stem: str, pred) -> None:
        self._recent[stem] = pred
        self._recent.move_to_end(stem)
        while len(self._recent) > self._keep:
            self._recent.popitem(last=False)

    def get(self, stem, default=None):
        with self._lock:
            if stem in self._memory:
                return self._memory[stem]
            if stem in self._recent:
                return self._recent[stem]
            where = self._where.get(stem)
        if where is None:
            return default
        try:
            pred = parse_predictions(self._file.read(*where)["detections"], str(self._file.path))
        except (OSError, ValueError, KeyError, DataError):
            return default
        with self._lock:
            self._remember(stem, pred)
        return pred

    def __getitem__(self, stem):
        pred = self.get(stem)
        if pred is None:
            raise KeyError(stem)
        return pred


class SummaryStore:
    """Every frame's latest summary (in memory: small) and its file (``summaries.jsonl``)."""

    def __init__(self, path: Path | None, warnings: list[str] | None = None):
        warnings = [] if warnings is None else warnings
        self._file = JsonLinesFile(path, warnings)
        self._by_stem: dict[str, FrameSummary] = {}
        n = bad = 0
        for _, _, obj in self._file.lines():
            n += 1
            s = summary_from_json(obj)
            if s is None:
                bad += 1
                continue
            self._by_stem[s.stem] = s
        if bad:
            warnings.append(f"{path}: {bad} line(s) that are not frame summaries skipped")
        if n > 2 * len(self._by_stem) + 100:  # mostly superseded lines: keep the latest of each frame
            self._file.rewrite(asdict(s) for s in self._by_stem.values()
                               if all(not isinstance(v, float) or math.isfinite(v) for v in asdict(s).values()))

    def get(self, stem: str) -> FrameSummary | None:
        return self._by_stem.get(stem)

    def put(self, summary: FrameSummary) -> None:
        if self._by_stem.get(summary.stem) == summary:
            return
        self._by_stem[summary.stem] = summary
        obj = asdict(summary)
        if not all(isinstance(v, (str, bool, type(None))) or math.isfinite(v) for v in obj.values()):
            return  # not kept on disk: computed again next time
        self._file.append(obj)

    def __len__(self) -> int:
        return len(self._by_stem)


def cache_paths(edits_root: Path, writable: bool, warnings: list[str]) -> tuple[Path | None, Path | None]:
    """Where the summaries and the detections are kept (None, None for a read-only folder)."""
    if not writable:
        return None, None
    layout = EditsLayout(edits_root)
    state_folder(layout.cache, warnings)
    return layout.summaries, layout.detections


@dataclass
class PassProgress:
    """Where the background pass is: frames done of ``total``, detected, without a camera."""

    total: int
    done: int = 0
    detected: int = 0
    failed: int = 0
    started: float = 0.0
    finished: bool = False

    def text(self) -> str:
        dt = time.perf_counter() - self.started
        head = "triage done" if self.finished else "triage (background)"
        # "calibrated" would count the frames that failed too ("4/4 calibrated, 4 without a camera")
        return (f"{head}: {self.done}/{self.total} frames, {self.done - self.failed} with a camera, "
                f"{self.failed} without" + (f", {self.detected} detected" if self.detected else "") + f" · {dt:.0f} s")


#: how often the background pass gives up one frame because a tab acted before it runs that frame
#: to its end (:func:`_calibrate_yielding`)
YIELDS_PER_FRAME = 3


def run_pass(triage: "Triage", stop: threading.Event, say: Callable[[str], None], every: int = 10) -> PassProgress:
    """Detect (when the state has a detector) and calibrate every frame of the triage's state
    under its default settings, keeping summaries only; frames whose summary is up to date are
    skipped. ``say``: the progress line, every ``every`` frames and at the end. Before each frame
    it has work for (a detection, a calibration) it waits for a pause in the tabs' actions (the
    state's :class:`pnlviz.app.activity.UserActivity`); a resumed pass reads its stored summaries
    without waiting."""
    host = triage.host
    progress = PassProgress(len(host.stems), started=time.perf_counter())
    for i, stem in enumerate(host.stems):
        detect, fresh = host.needs_detection(stem), triage.up_to_date(stem)
        if detect:
            triage.wait_quiet(stop)  # work to do: the tab the user is on goes first
            detect = host.needs_detection(stem)  # a tab may have had it detected meanwhile
        if stop.is_set():
            return progress
        if detect:
            try:
                triage.run_detector(stem)
                progress.detected += 1
            except Exception:  # noqa: BLE001 - a frame the detector fails on is calibrated without
                pass
            fresh = triage.up_to_date(stem)  # its token holds whether it has detections
        stored = triage.store.get(stem) if fresh else None  # up to date: stored
        summary = stored if stored is not None else _calibrate_yielding(triage, stem, stop)
        if summary is None:  # stopped while it waited for the tabs
            return progress
        progress.done += 1
        progress.failed += not summary.ok
        if i % every == 0 or i == len(host.stems) - 1:
            say(progress.text())
        time.sleep(0)
    progress.finished = True
    say(progress.text())
    return progress


def _calibrate_yielding(triage: "Triage", stem: str, stop: threading.Event) -> FrameSummary | None:
    """The pass's calibration of one frame (:meth:`Triage.calibrate`), given up the moment a tab
    acts (``triage.user_busy``: its solves stop at their next iteration, nothing is kept) and
    taken again from the start once the tabs are quiet. A tab that has not been quiet for the
    longest wait (:meth:`pnlviz.app.activity.UserActivity.wait_quiet`) no longer stops it (a clip
    played for minutes does not stop the pass for good), nor does a frame given up
    :data:`YIELDS_PER_FRAME` times (the pass takes its frames in order: a frame longer than the
    user's pauses would hold it up for as long as the user works). None: ``stop`` was set while it
    waited.

    The pass started a frame only after a pause, and then ran it to its end: a drag that began
    during one of its longer frames (the label-error finder costs one to 26 calibrations) shared
    the interpreter and a core with it throughout, and the point's previews took several times
    as long."""
    given_up = 0
    while True:
        triage.wait_quiet(stop)  # the tab the user is on goes first (at once when it is quiet)
        if stop.is_set():
            return None
        busy = triage.user_busy
        if busy is None or busy() or given_up == YIELDS_PER_FRAME:
            # no tabs to give way to, a tab busy past the longest wait, or given up as often as it may be
            return triage.calibrate(stem)
        try:
            with cancellable(busy):
                return triage.calibrate(stem)
        except Cancelled:
            given_up += 1
            triage.yielded += 1


class Triage:
    """The summaries of the session's frames (``host``, :class:`pnlviz.app.host.FrameHost`), kept
    up to date as views are computed (``store``: where they are kept), and the background pass,
    which waits for the tabs with ``wait_quiet(stop)``, gives a frame up when ``user_busy()``
    says a tab acts, and detects with ``run_detector(stem)``.
    Made by :class:`pnlviz.app.state.AppState`, which gives it these and nothing else."""

    def __init__(self, host: FrameHost, store: SummaryStore, *, wait_quiet: Callable[[threading.Event], object],
                 run_detector: Callable[[str], None], user_busy: Callable[[], bool] | None = None):
        self.host = host
        self.store = store
        self.wait_quiet = wait_quiet
        self.run_detector = run_detector
        #: whether a tab is at work (an action running or just ended): the pass gives its frame up
        #: then (None: it never does)
        self.user_busy = user_busy
        #: frames the pass gave up because a tab acted (each taken again later)
        self.yielded = 0
        self.progress: PassProgress | None = None

    def has_detections(self, stem: str) -> bool:
        reader = self.host.reader
        return reader.predictions is not None and (stem in reader.predictions or stem in reader.detected)

    def token(self, stem: str, settings=None) -> str:
        return summary_token(settings or self.host.default_settings, self.host.edits.digest(stem),
                             self.has_detections(stem))

    def note(self, view, judge: bool = False) -> FrameSummary | None:
        """Keep the summary of a view just computed under the default settings; ``judge``: with
        the label-error finder's score (the background pass; not after each edit, which must stay
        quick)."""
        if view.settings != self.host.default_settings:
            return None
        summary = summarize(view, self.token(view.stem), judge=judge)
        old = None if judge else self.store.get(view.stem)
        if old is not None and old.token == summary.token and old.suspect is not None:  # same inputs: same verdict
            summary = replace(summary, suspect=old.suspect, suspect_note=old.suspect_note)
        self.store.put(summary)
        return summary

    def lookup(self, stem: str, settings=None) -> FrameSummary | None:
        """The frame's summary under ``settings``: the stored one while the frame's edits are the
        same (detections that came since aside) for the default settings, else of its view if
        computed."""
        settings = settings or self.host.default_settings
        if settings != self.host.default_settings:  # other settings: the views computed under them
            view = self.host.cached_view(stem, settings)
            return summarize(view, "") if view is not None else None
        summary = self.store.get(stem)  # noted whenever a view under the default settings is computed
        return summary if summary is not None and same_inputs(summary.token, self.token(stem)) else None

    def summaries(self, settings=None) -> dict[str, FrameSummary]:
        """Every frame's summary that is known (see :meth:`lookup`), by stem."""
        out = {}
        for stem in self.host.stems:
            s = self.lookup(stem, settings)
            if s is not None:
                out[stem] = s
        return out

    def up_to_date(self, stem: str) -> bool:
        summary = self.store.get(stem)
        return summary is not None and summary.token == self.token(stem)

    def run(self, stop: threading.Event, say: Callable[[str], None]) -> PassProgress:
        """The background pass (:func:`run_pass`)."""
        self.progress = run_pass(self, stop, say)
        return self.progress

    def calibrate(self, stem: str) -> FrameSummary:
        """The frame calibrated under the default settings, its summary kept (the view is not)."""
        view = self.host.view(stem, keep=False)  # noted there, judged (a view not kept: the pass's)
        stored = self.store.get(stem)
        return stored if stored is not None and stored.token == self.token(stem) else \
            summarize(view, self.token(stem), judge=True)


__all__ = ["DetectionCache", "FrameSummary", "PassProgress", "SummaryStore", "Triage", "cache_paths", "run_pass",
           "fix_frame", "judge_view", "same_inputs", "summarize", "summary_token", "suspect_score"]
