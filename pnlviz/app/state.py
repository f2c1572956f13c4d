"""The app's state without any GUI: the dataset, per-frame calibrations (computed on demand by
the engine's pipeline, :mod:`pnlviz.pipeline`, and cached per setting), the detector's results,
review statuses and edits. The viser server
(:mod:`pnlviz.app.server`), its browser tabs and the tests drive the same object.

Nothing here knows which frame a tab shows: every call names its frame (``stem``) and the
settings it is seen with (:class:`Settings`), so two annotators on two frames never touch each
other's work. Edits never touch the source data: they live in an edits folder
(:mod:`pnlviz.data.edits`), validated, written atomically, one frame's read-modify-write at a
time.
"""

from __future__ import annotations

import functools
import json
import threading
from collections.abc import Callable
from pathlib import Path

import numpy as np

from pnlviz.calib.frame import SOURCES, detection_settings_apply
from pnlviz.calib.looks import take_look
from pnlviz.conventions import EVAL_SIZE
from pnlviz.data import DataError
from pnlviz.data.annotations import annotation_to_json, parse_annotation
from pnlviz.data.edit_changes import move_line_point, set_keypoint
from pnlviz.data.edits import (
    REVIEW_STATES,
    EditError,
    EditsStore,
    check_keypoint_id,
    check_position,
)
from pnlviz.field.model import load_field_model
from pnlviz.app.activity import UserActivity
from pnlviz.app.host import FrameHost
from pnlviz.app.shots import ClipShots
from pnlviz.app.triage import DetectionCache, SummaryStore, Triage, cache_paths
from pnlviz.pipeline import FrameReader, FrameView, Settings, frame_view

#: views kept in memory (the frames on screen and around them; the whole dataset is in summaries)
VIEW_CACHE = 256

__all__ = ["AppState", "EditError", "FrameView", "REVIEW_STATES", "SOURCES", "Settings"]


def _view_key(edits: EditsStore, stem: str, settings: Settings, keypoints: dict | None = None) -> tuple:
    """The cache key of a frame's view: its settings and its edits (``keypoints``: these keypoint
    edits instead of the saved ones)."""
    rec = dict(edits.get(stem))
    if keypoints is not None:
        rec["keypoints"] = keypoints
    edit = {k: rec[k] for k in ("annotation", "keypoints") if rec.get(k) is not None}
    return stem, settings, json.dumps(edit, sort_keys=True) if edit else None


@functools.cache
def _malloc_trim():
    """glibc's ``malloc_trim``, or None. Loaded by its soname, never through
    ``ctypes.util.find_library``: that runs ``ldconfig`` in a child process, and a child forked
    while another thread hands the edits folder over holds its lock for a moment (a second app
    on the same folder was refused under load)."""
    import ctypes

    try:
        return ctypes.CDLL("libc.so.6").malloc_trim
    except (OSError, AttributeError):
        return None


def _return_free_memory() -> None:
    """Give the memory freed by the caches back to the system: glibc keeps freed small blocks in
    its heap (the process would stay at its peak); ``malloc_trim`` returns them. A no-op elsewhere."""
    import gc

    gc.collect()
    trim = _malloc_trim()
    if trim is not None:
        trim(0)


class AppState:
    """Dataset + calibration cache + detections + edits; thread-safe for the server's callbacks.

    The frames are read by a :class:`pnlviz.pipeline.FrameReader` (:attr:`reader`) and their views
    computed by :func:`pnlviz.pipeline.frame_view`, as ``pnlviz calibrate`` and export do; this
    object keeps them per setting, previews drags, runs the on-demand detector and applies edits.
    ``writable=False`` opens the edits read-only; otherwise this process holds the edits folder
    until :meth:`close`.
    """

    def __init__(self, data: Path, *, detections: Path | None = None, edits: Path | None = None,
                 size: tuple[int, int] = EVAL_SIZE, detector=None, source: str | None = None, writable: bool = True,
                 force_edits: bool = False, detector_settings: Path | None = None):
        self.data = Path(data)
        self.detections_path = None if detections is None else Path(detections)
        #: the detector's settings file (``--detector-settings``; None: the one beside the detections)
        self.detector_settings_path = detector_settings
        self.model = load_field_model()
        #: the edits folder was adopted although it was made for other pictures (--force-edits)
        self.force_edits = force_edits
        self.reader = FrameReader.open(self.data, detections=detections, edits=edits, size=size, writable=writable,
                                       detector_settings=getattr(detector, "calibration", None),
                                       force_edits=force_edits, settings_file=detector_settings)
        #: a detector (pnlviz.detect.worker.DetectorProcess) run on demand, in the background, for
        #: frames without detections in the zip; its results join ``detected``
        self.detector = detector
        if detector is not None and self.reader.predictions is None:
            self.reader.predictions = {}
        edits_store = self.reader.edits
        assert edits_store is not None  # FrameReader.open always opens the edits folder
        self.ds, self.edits, self.size = self.reader.ds, edits_store, size
        self.stems = self.reader.stems
        summaries, detections = cache_paths(edits_store.root, writable, edits_store.warnings)
        if detector is not None:  # the detector's results, kept on disk beside the summaries
            self.reader.detected = DetectionCache(detections, edits_store.warnings)
        self.predictions, self.detected = self.reader.predictions, self.reader.detected
        #: the settings a new tab starts with: "both" once there are detections, unless told otherwise
        self.default_settings = Settings(source=source or self.reader.default_settings().source)
        #: the frames as the session's parts see them (they get this, never the session)
        self.host = FrameHost(self.stems, self.reader, edits_store, self.model, self.default_settings, self.view,
                              self.cached_view, self.needs_detection, self.write, self.notify)
        #: the tabs' actions mark it; the background pass waits for a pause in them
        self.activity = UserActivity()
        #: every frame's calibration summary and the background pass
        self.triage = Triage(self.host, SummaryStore(summaries, edits_store.warnings),
                             wait_quiet=self.activity.wait_quiet, run_detector=self.run_detector,
                             user_busy=self.activity.busy)
        self._shots: ClipShots | None = None
        self._shots_lock = threading.Lock()
        #: the frame a new tab opens: the first with an image, the most telling one
        self.first_index = next((i for i, s in enumerate(self.stems) if self.ds.frame(s).has_image), 0)
        self._cache: dict[tuple, FrameView] = {}
        #: per frame, the last preview (while a point is dragged) under the cache key the frame
        #: will have if that position is released: the release then costs no recalibration
        self._previews: dict[str, tuple[tuple, FrameView]] = {}
        self._lock = threading.RLock()
        self._images: dict[str, np.ndarray | None] = {}
        #: why an image could not be decoded (stem -> one line), once it was tried
        self.image_errors: dict[str, str] = {}
        self._listeners: list[Callable[[str], None]] = []

    def release_caches(self) -> None:
        """Drop the frames' views, previews and images (no tab shows them any more); the triage
        summaries, the edits and the detections stay."""
        with self._lock:
            self._cache.clear()
            self._previews.clear()
            self._images.clear()
        _return_free_memory()

    def close(self) -> None:
        """Release the edits folder (and stop the detector, when it runs in a process)."""
        self.edits.close()
        close = getattr(self.detector, "close", None)
        if close is not None:
            close()

    def __enter__(self) -> AppState:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # ------------------------------------------------------------------ frames
    def index_of(self, stem: str) -> int:
        """The frame's position; EditError for a stem the dataset does not have."""
        try:
            return self.reader.index_of(stem)
        except (KeyError, TypeError):
            raise EditError(f"no frame {str(stem)[:60]!r} in {self.data.name}") from None

    def find(self, stem: str) -> int | None:
        try:
            return self.reader.index_of(str(stem).strip())
        except KeyError:
            return None

    def frame_size(self, stem: str) -> tuple[int, int]:
        """(W, H) of the frame's image, else (no image, or one that cannot be read) the size
        frames without an image are shown at."""
        return self.reader.frame_size(stem)

    @functools.cached_property
    def clips(self) -> dict[str, list[int]]:
        """The dataset's named clips (:func:`pnlviz.app.timeline.clip_index`), found once for all
        tabs (60-90 ms for 23,000 stems)."""
        from pnlviz.app.timeline import clip_index

        return clip_index(self.stems)

    @property
    def problems(self) -> list[str]:
        """Files of the dataset that are not used (names that are not UTF-8, a second file for
        the same frame...), one line each."""
        return [str(e) for e in self.ds.rejected]

    def needs_detection(self, stem: str) -> bool:
        return (self.detector is not None and self.ds.frame(stem).has_image and stem not in self.detected
                and stem not in (self.predictions or {}))

    def run_detector(self, stem: str) -> None:
        """Detect on one frame (slow with the published networks: seconds); cached."""
        img = self.image(stem)
        if img is None:
            return
        pred, _ = take_look(self.detector.detect([img])[0], (img.shape[1], img.shape[0]),
                            self.reader.detection_settings, self.model)
        self.detected[stem] = pred
        with self._lock:
            # views the detections change are computed again; the others stay (a frame calibrated
            # from its annotation alone keeps its camera), and its summary stays until replaced
            for key in [k for k, v in self._cache.items() if k[0] == stem and not
                        (v.settings.source == "annotation" and v.origin == "annotation")]:
                del self._cache[key]
            self._previews.pop(stem, None)
        self.notify(stem)

    def image(self, stem: str) -> np.ndarray | None:
        """The frame's pixels (BGR), decoded on demand; a few recent ones are kept."""
        with self._lock:
            if stem in self._images:
                return self._images[stem]
        try:
            img = self.ds.image(stem) if self.ds.frame(stem).has_image else None
        except DataError as exc:  # the card says why the frame shows no pixels
            self.image_errors[stem] = str(exc)
            img = None
        with self._lock:
            self._images[stem] = img
            while len(self._images) > 8:
                self._images.pop(next(iter(self._images)))
        return img

    # ------------------------------------------------------------------ calibration
    def applied_detection_settings(self, origin: str | None, settings: Settings) -> dict:
        """The detector's calibration settings when they apply (see
        :func:`pnlviz.calib.frame.detection_settings_apply`)."""
        return dict(detection_settings_apply(origin, self.reader.frame_settings(settings)))

    def view(self, stem: str, settings: Settings | None = None, *, keep: bool = True) -> FrameView:
        """The frame's view under ``settings`` (default: :attr:`default_settings`), cached (not
        kept when computed with ``keep=False``: for one pass over many frames; the
        :data:`VIEW_CACHE` latest are kept), its summary noted (:class:`pnlviz.app.triage.Triage`).
        Never raises on bad data."""
        settings = settings or self.default_settings
        self.index_of(stem)
        key = _view_key(self.edits, stem, settings)
        with self._lock:
            if key in self._cache:
                return self._cache[key]
            preview = self._previews.pop(stem, None)
            # the position a drag just previewed, released (and no detections came meanwhile)
            if preview is not None and preview[0] == key and preview[1].detections is self.reader.detections(stem):
                self._cache[key] = preview[1]
                return preview[1]
        view = frame_view(self.reader, stem, settings, self.model)
        if keep:
            with self._lock:
                self._cache[key] = view
                while len(self._cache) > VIEW_CACHE:
                    self._cache.pop(next(iter(self._cache)))
        self.triage.note(view, judge=not keep)  # the background pass's views are judged, not each edit's
        return view

    def cached_view(self, stem: str, settings: Settings | None = None) -> FrameView | None:
        """The frame's view under ``settings`` if it is computed already, else None (nothing is
        computed: for displays of many frames, such as the clip timeline)."""
        key = _view_key(self.edits, stem, settings or self.default_settings)
        with self._lock:
            return self._cache.get(key)

    def preview(self, stem: str, settings: Settings, kid: int, x: float, y: float) -> FrameView:
        """The frame as it would be with keypoint ``kid`` at (x, y), calibrated (for feedback while
        a point is dragged): not saved; kept until the frame's next view, which it is if that
        position is then released."""
        kid = check_keypoint_id(kid)
        self.index_of(stem)
        x, y = check_position(x, y, self.frame_size(stem), stem)
        edits = {**(self.edits.get(stem).get("keypoints") or {}), str(kid): [x, y]}
        key = _view_key(self.edits, stem, settings, keypoints=edits)
        with self._lock:
            if key in self._cache:
                return self._cache[key]
        view = frame_view(self.reader, stem, settings, self.model, keypoint_edits=edits)
        with self._lock:
            self._previews[stem] = (key, view)
        return view

    @property
    def shots(self) -> ClipShots:
        """The clips' shot models (:class:`pnlviz.app.shots.ClipShots`), made on first use; from
        then on they follow every change of their frames before the tabs redraw."""
        with self._shots_lock:
            if self._shots is None:
                self._shots = ClipShots(self.host)
                self.subscribe(self._shots.changed, first=True)  # the shot solved again before the tabs redraw
            return self._shots

    # ------------------------------------------------------------------ change notices
    def subscribe(self, callback: Callable[[str], None], first: bool = False) -> None:
        """Call ``callback(stem)`` after every change to a frame (edit, review, new detections);
        ``first``: before the listeners already there (a model the others read follows first)."""
        if first:
            self._listeners.insert(0, callback)
        else:
            self._listeners.append(callback)

    def notify(self, stem: str, changed: bool = True) -> bool:
        """Tell the listeners (the shot models, then every tab) that ``stem`` shows something else
        now (when ``changed``), then run the shots' full solves waiting behind quick answers
        (:meth:`pnlviz.app.shots.ClipShots.finish`: the tabs redraw again); returns ``changed``."""
        if changed:
            for callback in list(self._listeners):
                callback(stem)
            if self._shots is not None:
                self._shots.finish()  # the shots' full solves after the quick answers drawn
        return changed

    # ------------------------------------------------------------------ review and edits
    def write(self, stem: str, change: Callable[[dict], None] | None = None, *, corrected: bool = True,
              settings: Settings | None = None, merge: object = None,
              snapshot: dict | Callable[[dict], dict | None] | None = None, notify: bool = True) -> bool:
        """The one door for a change to a frame's edit record, whoever makes it (a drag, a review,
        an accepted shot, a fix of the label-error finder): ``change(record)`` as one user action,
        one undo step, validated and written at once (:meth:`pnlviz.data.edits.EditsStore.act`;
        ``corrected``: the frame becomes "corrected"; ``merge``: see there), with ``snapshot`` when
        given (a shot's; a function of the record as changed, for one made from it); then every tab
        is told (:meth:`notify`; ``notify`` False: a snapshot refreshed while they are being told
        already); then, without a ``snapshot`` given, the review snapshot of what the frame shows
        under ``settings`` when it is reviewed (:meth:`snapshot`), taken before this returns, even
        when a listener fails. No tab shows the snapshot, so the tabs draw first: the hand sees its
        edit without waiting for it, and a clip's shot is fully solved before it (the snapshot of a
        frame reviewed with its shot needs no solve of its own). True when the record changed."""
        self.index_of(stem)
        with self.edits.lock(stem):  # the change and the snapshot that goes with it are one
            changed = change is not None and self.edits.act(stem, change, corrected=corrected, merge=merge)
            snap = snapshot(self.edits.get(stem)) if callable(snapshot) else snapshot
            if snap is not None and snap != self.edits.get(stem).get("snapshot"):
                self.edits.update(stem, snapshot=snap)
                changed = True
        try:
            if notify:
                self.notify(stem, changed)
        finally:  # a listener's error (a shot's failed solve) still leaves the snapshot of the change
            if snapshot is None and changed:
                self.snapshot(stem, settings)
        return changed

    def snapshot(self, stem: str, settings: Settings | None = None) -> dict | None:
        """Record in a reviewed (accepted or corrected) frame's edit record what it shows under
        ``settings`` (default: :attr:`default_settings`): its labels with their provenance, the
        detections and settings used, the camera (:func:`pnlviz.pipeline.snapshot.take_snapshot`),
        which is what an export of the frame writes. Returns the snapshot (None: not reviewed)."""
        from pnlviz.pipeline.snapshot import REVIEWED, hand_slips, take_snapshot

        with self.edits.lock(stem):  # the view and the record it is taken with are one
            record = self.edits.get(stem)
            if record.get("review") not in REVIEWED:
                return None
            snap = None
            if (record.get("snapshot") or {}).get("shot") is not None:  # reviewed with its shot: as it shows now
                snap = self.shots.snapshot(stem, settings or self.default_settings)
            if snap is None:
                view = self.view(stem, settings or self.default_settings)
                snap = take_snapshot(view, record, self.applied_detection_settings(view.origin, view.settings),
                                     self.model)
                slips = hand_slips(view, self.reader.frame_settings(view.settings), self.model)
                if slips:  # hand points the rest of the frame disagrees with: said, and in the manifest
                    snap["slips"] = {str(k): (v if v != float("inf") else None) for k, v in sorted(slips.items())}
            if snap != record.get("snapshot"):
                self.edits.update(stem, snapshot=snap)
        return snap

    def set_review(self, stem: str, status: str | None, settings: Settings | None = None) -> None:
        """Set the frame's review status; accepting it (or marking it corrected) records what
        it shows under ``settings``, what its export writes."""
        if status is not None and status not in REVIEW_STATES:
            raise EditError(f"review status must be one of {', '.join(REVIEW_STATES)} or none, "
                            f"got {str(status)[:20]!r}")
        if status == "corrected" and self.edits.review(stem) == "corrected":
            self.edits.keep_review(stem)  # set by the edits, now confirmed by hand: undo keeps it
        self.write(stem, lambda rec: rec.__setitem__("review", status), corrected=False, settings=settings)

    def set_annotation(self, stem: str, annotation: dict[str, np.ndarray]) -> None:
        """Store an edited annotation (autosaved at once) and mark the frame corrected."""
        try:
            text = annotation_to_json(annotation)
            parse_annotation(text)
        except DataError as exc:
            raise EditError(exc.problem) from None
        self.write(stem, lambda rec: rec.__setitem__("annotation", text))

    def move_keypoint(self, stem: str, kid: int, x: float, y: float, settings: Settings | None = None,
                      merge: object = None) -> None:
        """Put keypoint ``kid`` at pixel (x, y) of the frame (adds it if it was missing);
        ``merge``: see :meth:`pnlviz.data.edits.EditsStore.act` (nudges of one point: one step)."""
        kid = check_keypoint_id(kid)
        self.index_of(stem)
        xy = check_position(x, y, self.frame_size(stem), stem)
        self.write(stem, lambda rec: set_keypoint(rec, kid, xy), settings=settings, merge=merge)

    def hide_keypoint(self, stem: str, kid, settings: Settings | None = None) -> None:
        """Mark keypoint ``kid`` not visible: it leaves the calibration and the labels (``kid``: an
        id, or several ids hidden in one step, e.g. the points the outlier gate flags)."""
        kids = [check_keypoint_id(k) for k in (kid if isinstance(kid, (list, tuple, set, frozenset)) else [kid])]

        def change(rec: dict) -> None:
            for k in kids:
                set_keypoint(rec, k, None)

        self.write(stem, change, settings=settings)

    def hide_flagged(self, stem: str, kids, settings: Settings | None = None) -> bool:
        """Hide keypoints ``kids`` (those the outlier gate flags on a reviewed frame) from its
        labels, as reviewed: its review status and the camera its snapshot holds stay (the points
        were never ground truth, and the camera the annotator confirmed does not move); one undo
        step, which brings them back. A frame without a snapshot: as :meth:`hide_keypoint`."""
        from pnlviz.data.snapshot import edits_digest

        ids = sorted({check_keypoint_id(k) for k in kids})
        snap = self.edits.get(stem).get("snapshot")
        if snap is None:
            self.hide_keypoint(stem, ids, settings)
            return True

        def change(rec: dict) -> None:
            for k in ids:
                set_keypoint(rec, k, None)

        def without(record: dict) -> dict:
            current = record.get("snapshot") or snap
            labels = {k: v for k, v in (current.get("labels") or {}).items() if int(k) not in ids}
            return {**current, "labels": labels, "edits": edits_digest(record)}

        return self.write(stem, change, corrected=False, settings=settings, snapshot=without)

    def move_line_point(self, stem: str, name: str, index: int, x: float, y: float,
                        settings: Settings | None = None) -> None:
        """Move point ``index`` of annotated class ``name`` to pixel (x, y)."""
        self.index_of(stem)
        size = self.frame_size(stem)
        xy = check_position(x, y, size, stem)
        self.write(stem, lambda rec: move_line_point(rec, lambda: self.ds.annotation(stem), stem, name, index, xy,
                                                     size), settings=settings)

    def undo(self, stem: str, settings: Settings | None = None, back: bool = True) -> bool:
        """Take back the frame's last change (whoever made it), or with ``back`` False do again
        the last one taken back; False if there is none."""
        self.index_of(stem)
        changed = self.edits.step(stem, back=back)  # the record's own history: the door's other side
        if changed:
            self.snapshot(stem, settings)
        return self.notify(stem, changed)

    def redo(self, stem: str, settings: Settings | None = None) -> bool:
        return self.undo(stem, settings, back=False)

