"""The app's state without any GUI: the dataset, per-frame calibrations (computed on demand and
cached per setting), the detector's results, review statuses and edits. The viser server
(:mod:`pnlviz.app.server`), its browser tabs and the tests drive the same object.

Nothing here knows which frame a tab shows: every call names its frame (``stem``) and the
settings it is seen with (:class:`Settings`), so two annotators on two frames never touch each
other's work. Edits never touch the source data: they live in an edits folder
(:mod:`pnlviz.app.edits`), validated, written atomically, one frame's read-modify-write at a
time.
"""

from __future__ import annotations

import functools
import hashlib
import json
import math
import os
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from pnlviz.app.edits import HISTORY_LIMIT, REVIEW_STATES, UNDOABLE, EditsStore, keypoint_ids
from pnlviz.calib.calibrate import CalibParams, CalibrationResult
from pnlviz.calib.frame import SOURCES, FrameInputs, FrameSettings, calibrate_frame, detection_settings_apply
from pnlviz.calib.observations import Observations
from pnlviz.conventions import DEFAULT_ALPHA, EVAL_SIZE
from pnlviz.data import DataError, open_dataset, read_predictions, read_predictions_info
from pnlviz.data.annotations import annotation_to_json, parse_annotation
from pnlviz.field.model import load_field_model
from pnlviz.geometry.camera import Camera

__all__ = ["AppState", "EditError", "FrameView", "REVIEW_STATES", "SOURCES", "Settings", "default_edits_dir"]

#: how far outside the frame a keypoint may be placed, as a fraction of its size (as the
#: annotations' coordinate range allows: -0.5..1.5)
PLACEMENT_MARGIN = 0.5


class EditError(ValueError):
    """An edit that cannot be applied (unknown frame or id, a position off the frame, ...)."""


@dataclass(frozen=True)
class Settings:
    """How a frame is calibrated: PnL on or off, its line weight, and the keypoint source."""

    pnl: bool = True
    alpha: float = DEFAULT_ALPHA
    source: str = "annotation"

    def __post_init__(self):
        if self.source not in SOURCES:
            raise ValueError(f"keypoint source must be one of {SOURCES}, got {self.source!r}")
        if not (isinstance(self.alpha, (int, float)) and math.isfinite(self.alpha) and 0.0 <= self.alpha <= 1.0):
            raise ValueError(f"alpha must be a number in [0, 1], got {self.alpha!r}")
        object.__setattr__(self, "alpha", round(float(self.alpha), 4))
        object.__setattr__(self, "pnl", bool(self.pnl))


def default_edits_dir(data: Path) -> Path:
    """``<data>.edits`` beside a folder or zip: never inside or over the source. When that folder
    cannot be written (read-only data), ``~/.pnlviz/edits/<name>-<hash of the path>``."""
    data = Path(data).resolve()
    name = data.name[:-4] if data.suffix == ".zip" else data.name
    beside = data.parent / f"{name}.edits"
    if beside.is_dir() and os.access(beside, os.W_OK) or not beside.exists() and os.access(data.parent, os.W_OK):
        return beside
    digest = hashlib.sha1(str(data).encode()).hexdigest()[:10]
    return Path.home() / ".pnlviz" / "edits" / f"{name}-{digest}"


@dataclass
class FrameView:
    """Everything the app shows for one frame under one setting."""

    stem: str
    index: int
    has_image: bool  # the pixels are not kept here (23k cached views must fit in memory): AppState.image()
    size: tuple[int, int]  # (W, H) of the image or of the --size fallback
    annotation: dict[str, np.ndarray] | None
    observations: Observations | None
    result: CalibrationResult | None
    jac: dict[int, float] = field(default_factory=dict)  # JaC@5/10/20 against the annotation
    error: str | None = None  # a problem reading the frame
    ms: float = 0.0
    reference_camera: Camera | None = None  # a known camera (e.g. synthetic ground truth), scaled to the frame
    detections: object | None = None  # the frame's PnLCalib detections (pnlviz.data.Predictions), if any
    origin: str | None = None  # where the observations came from: annotation, detections, both or edits
    settings: Settings = Settings()

    @property
    def camera(self) -> Camera | None:
        """The camera to show the frame with: the calibration's, else the known one."""
        if self.result is not None and self.result.ok:
            return self.result.camera
        return self.reference_camera


class _Unchanged(Exception):
    """Raised inside an edit transaction that changes nothing: no write, no undo step."""


class AppState:
    """Dataset + calibration cache + detections + edits; thread-safe for the server's callbacks.

    ``writable=False`` opens the edits read-only (``pnlviz export``); otherwise this process
    holds the edits folder until :meth:`close`.
    """

    def __init__(self, data: Path, *, detections: Path | None = None, edits: Path | None = None,
                 size: tuple[int, int] = EVAL_SIZE, detector=None, source: str | None = None, writable: bool = True):
        self.data = Path(data)
        self.model = load_field_model()
        self.ds = open_dataset(self.data)
        if not len(self.ds):
            raise DataError(str(self.data), "no frames (expected <stem>.jpg / <stem>.json files)")
        self.predictions = read_predictions(detections) if detections else None
        #: a detector (pnlviz.detect.worker.DetectorProcess) run on demand, in the background, for
        #: frames without detections in the zip; its results join ``detected``
        self.detector = detector
        self.detected: dict[str, object] = {}
        if detector is not None and self.predictions is None:
            self.predictions = {}
        #: calibration settings for frames calibrated from detections alone: recorded beside the
        #: prediction zip by ``pnlviz detect``, else the detector's own (the light model's sidecar)
        self.detection_settings = dict((read_predictions_info(detections).get("calibration") if detections else None)
                                       or getattr(detector, "calibration", None) or {})
        CalibParams().updated(self.detection_settings)  # unknown names fail here, not on the first frame
        self.size = size
        self.stems = list(self.ds.stems)
        self._index = {s: i for i, s in enumerate(self.stems)}
        #: the settings a new tab starts with: "both" once there are detections, unless told otherwise
        self.default_settings = Settings(source=source or ("annotation" if self.predictions is None else "both"))
        self.edits = EditsStore(edits or default_edits_dir(self.data), writable=writable)
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
            return self._index[stem]
        except (KeyError, TypeError):
            raise EditError(f"no frame {str(stem)[:60]!r} in {self.data.name}") from None

    def find(self, stem: str) -> int | None:
        return self._index.get(str(stem).strip())

    def frame_size(self, stem: str) -> tuple[int, int]:
        """(W, H) of the frame's image, else (no image, or one that cannot be read) the size
        frames without an image are shown at."""
        try:
            if self.ds.frame(stem).has_image:
                return self.ds.image_size(stem) or self.size
        except DataError:
            pass
        return self.size

    def image_problem(self, stem: str) -> str | None:
        """Why the frame's image cannot be used (one line), None when it can or there is none."""
        try:
            if self.ds.frame(stem).has_image:
                self.ds.image_size(stem)
        except DataError as exc:
            return str(exc)
        return None

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

    def annotation(self, stem: str) -> dict[str, np.ndarray] | None:
        """The edited annotation if any, else the source one."""
        edit = self.edits.get(stem).get("annotation")
        if edit is not None:
            return parse_annotation(edit, f"{self.edits.frames / stem}.json")
        return self.ds.annotation(stem)

    def detections_for(self, stem: str):
        """The frame's detections: from the prediction zip, else from the detector if it ran."""
        if self.predictions is None:
            return None
        return self.predictions.get(stem) or self.detected.get(stem)

    def needs_detection(self, stem: str) -> bool:
        return (self.detector is not None and self.ds.frame(stem).has_image and stem not in self.detected
                and stem not in (self.predictions or {}))

    def run_detector(self, stem: str) -> None:
        """Detect on one frame (slow with the published networks: seconds); cached."""
        img = self.image(stem)
        if img is None:
            return
        pred = self.detector.detect([img])[0]
        with self._lock:
            self.detected[stem] = pred
            # views computed before the detections existed are stale
            for key in [k for k in self._cache if k[0] == stem]:
                del self._cache[key]
            self._previews.pop(stem, None)
        self._changed(stem)

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
    def frame_settings(self, settings: Settings) -> FrameSettings:
        """A tab's choices, with the detector's own settings, as the engine takes them."""
        return FrameSettings(pnl=settings.pnl, alpha=settings.alpha, source=settings.source,
                             detection_settings=self.detection_settings)

    def applied_detection_settings(self, origin: str | None, settings: Settings) -> dict:
        """The detector's calibration settings when they apply (see
        :func:`pnlviz.calib.frame.detection_settings_apply`)."""
        return dict(detection_settings_apply(origin, self.frame_settings(settings)))

    def _key(self, stem: str, settings: Settings, keypoints: dict | None = None) -> tuple:
        """The cache key of the frame's view: its settings and its edits (``keypoints``: these
        keypoint edits instead of the saved ones)."""
        rec = dict(self.edits.get(stem))
        if keypoints is not None:
            rec["keypoints"] = keypoints
        edit = {k: rec[k] for k in ("annotation", "keypoints") if rec.get(k) is not None}
        return stem, settings, json.dumps(edit, sort_keys=True) if edit else None

    def view(self, stem: str, settings: Settings | None = None, *, keep: bool = True) -> FrameView:
        """The frame's view under ``settings`` (default: :attr:`default_settings`), cached (not
        kept when computed with ``keep=False``: for one pass over many frames, an export). Never
        raises on bad data."""
        settings = settings or self.default_settings
        key = self._key(stem, settings)
        with self._lock:
            if key in self._cache:
                return self._cache[key]
            preview = self._previews.pop(stem, None)
            # the position a drag just previewed, released (and no detections came meanwhile)
            if preview is not None and preview[0] == key and preview[1].detections is self.detections_for(stem):
                self._cache[key] = preview[1]
                return preview[1]
        view = self._compute(stem, settings)
        if keep:
            with self._lock:
                self._cache[key] = view
        return view

    def cached_view(self, stem: str, settings: Settings | None = None) -> FrameView | None:
        """The frame's view under ``settings`` if it is computed already, else None (nothing is
        computed: for displays of many frames, such as the clip timeline)."""
        key = self._key(stem, settings or self.default_settings)
        with self._lock:
            return self._cache.get(key)

    def cached_views(self, settings: Settings | None = None) -> list[FrameView]:
        """The views computed so far under ``settings`` for the frames as they are now."""
        settings = settings or self.default_settings
        with self._lock:
            items = list(self._cache.items())
        return [v for k, v in items if k[1] == settings and k == self._key(k[0], settings)]

    def preview(self, stem: str, settings: Settings, kid: int, x: float, y: float) -> FrameView:
        """The frame as it would be with keypoint ``kid`` at (x, y), calibrated (for feedback while
        a point is dragged): not saved; kept until the frame's next view, which it is if that
        position is then released."""
        kid, (x, y) = self._check_id(kid), self._check_position(stem, x, y)
        edits = {**(self.edits.get(stem).get("keypoints") or {}), str(kid): [x, y]}
        key = self._key(stem, settings, keypoints=edits)
        with self._lock:
            if key in self._cache:
                return self._cache[key]
        view = self._compute(stem, settings, keypoint_edits=edits)
        with self._lock:
            self._previews[stem] = (key, view)
        return view

    def _compute(self, stem: str, settings: Settings, keypoint_edits: dict | None = None) -> FrameView:
        """Read the frame's inputs (the only I/O here), then the engine's one path per frame."""
        from pnlviz.metrics.soccernet import evaluate_frame

        idx = self.index_of(stem)
        try:
            image_error = self.image_problem(stem)  # shown, and the frame is calibrated as one without an image
            image = self.ds.frame(stem).has_image and image_error is None
            size = self.frame_size(stem)
            ann = self.annotation(stem)
            ref = self.ds.camera_dict(stem)
            ref = Camera.from_soccernet(ref).scaled(*size) if ref is not None else None
        except DataError as exc:
            return FrameView(stem, idx, False, self.size, None, None, None, error=str(exc), settings=settings)
        if keypoint_edits is None:
            keypoint_edits = self.edits.get(stem).get("keypoints")
        inputs = FrameInputs(size, ann, self.detections_for(stem), keypoint_edits)
        fc = calibrate_frame(inputs, self.frame_settings(settings), self.model)
        # nothing to calibrate from is not an error of the frame: the card asks for keypoints
        engine_error = fc.failure.message if fc.failure is not None and fc.failure.code == "internal" else None
        jac = {}
        if fc.ok and ann:
            fr = evaluate_frame(fc.result.camera.scaled(*EVAL_SIZE), ann)
            jac = {t: fr.accuracy(t) for t in (5, 10, 20)}
        return FrameView(stem, idx, image, size, ann, fc.observations, fc.result, jac,
                         error=image_error or engine_error,
                         ms=fc.ms, reference_camera=ref, detections=inputs.detections, origin=fc.origin,
                         settings=settings)

    # ------------------------------------------------------------------ change notices
    def subscribe(self, callback: Callable[[str], None]) -> None:
        """Call ``callback(stem)`` after every change to a frame (edit, review, new detections)."""
        self._listeners.append(callback)

    def _changed(self, stem: str) -> None:
        for callback in list(self._listeners):
            callback(stem)

    # ------------------------------------------------------------------ review and edits
    def _check_position(self, stem: str, x, y) -> tuple[float, float]:
        self.index_of(stem)
        W, H = self.frame_size(stem)
        try:
            x, y = float(x), float(y)
        except (TypeError, ValueError):
            raise EditError(f"a position must be two numbers, got {x!r}, {y!r}") from None
        m = PLACEMENT_MARGIN
        if not (math.isfinite(x) and math.isfinite(y) and -m * W <= x <= (1 + m) * W and -m * H <= y <= (1 + m) * H):
            raise EditError(f"position ({x:.6g}, {y:.6g}) is off the {W}x{H} frame of {stem} "
                            "by more than half its size")
        return x, y

    @staticmethod
    def _check_id(kid) -> int:
        try:
            kid = int(kid)
        except (TypeError, ValueError):
            raise EditError(f"keypoint id must be a whole number, got {str(kid)[:20]!r}") from None
        if kid not in keypoint_ids():
            raise EditError(f"keypoint id {kid} is not in the catalogue (1..73)")
        return kid

    def _edit(self, stem: str, change: Callable[[dict], None], *, corrected: bool = True) -> None:
        """One user action on one frame: ``change(record)`` under the frame's lock, one undo
        step (saved in the record, so it outlives the server), autosaved at once (an OSError of
        the write reaches the caller, nothing changes)."""
        self.index_of(stem)
        try:
            with self.edits.edit(stem) as rec:
                before = {k: rec.get(k) for k in UNDOABLE}
                change(rec)
                if corrected:
                    rec["review"] = "corrected"
                step = {k: before[k] for k in UNDOABLE if rec.get(k) != before[k]}
                if not step:
                    raise _Unchanged
                history = rec.get("history") or {}
                rec["history"] = {"undo": (history.get("undo", []) + [step])[-HISTORY_LIMIT:], "redo": []}
        except _Unchanged:
            return
        self._changed(stem)

    def set_review(self, stem: str, status: str | None) -> None:
        if status is not None and status not in REVIEW_STATES:
            raise EditError(f"review status must be one of {', '.join(REVIEW_STATES)} or none, "
                            f"got {str(status)[:20]!r}")
        self._edit(stem, lambda rec: rec.__setitem__("review", status), corrected=False)

    def set_annotation(self, stem: str, annotation: dict[str, np.ndarray]) -> None:
        """Store an edited annotation (autosaved at once) and mark the frame corrected."""
        try:
            text = annotation_to_json(annotation)
            parse_annotation(text)
        except DataError as exc:
            raise EditError(exc.problem) from None
        self._edit(stem, lambda rec: rec.__setitem__("annotation", text))

    def move_keypoint(self, stem: str, kid: int, x: float, y: float) -> None:
        """Put keypoint ``kid`` at pixel (x, y) of the frame (adds it if it was missing)."""
        kid, (x, y) = self._check_id(kid), self._check_position(stem, x, y)
        self._edit(stem, lambda rec: rec.__setitem__("keypoints", {**(rec.get("keypoints") or {}), str(kid): [x, y]}))

    def hide_keypoint(self, stem: str, kid: int) -> None:
        """Mark keypoint ``kid`` not visible: it leaves the calibration and the labels."""
        kid = self._check_id(kid)
        self._edit(stem, lambda rec: rec.__setitem__("keypoints", {**(rec.get("keypoints") or {}), str(kid): None}))

    def move_line_point(self, stem: str, name: str, index: int, x: float, y: float) -> None:
        """Move point ``index`` of annotated class ``name`` to pixel (x, y)."""
        x, y = self._check_position(stem, x, y)
        W, H = self.frame_size(stem)

        def change(rec):
            edited = rec.get("annotation")
            ann = parse_annotation(edited) if edited is not None else self.ds.annotation(stem)
            if not ann or name not in ann or not (0 <= int(index) < len(ann[name])):
                raise EditError(f"{stem} has no point {index} on {str(name)[:40]!r}")
            ann[name][int(index)] = [x / (W - 1), y / (H - 1)]
            rec["annotation"] = annotation_to_json(ann)

        self._edit(stem, change)

    def undo(self, stem: str) -> bool:
        """Take back the frame's last change (whoever made it); False if there is none."""
        return self._step(stem, "undo", "redo")

    def redo(self, stem: str) -> bool:
        return self._step(stem, "redo", "undo")

    def history(self, stem: str) -> tuple[int, int]:
        """(undo steps, redo steps) the frame has."""
        h = self.edits.get(stem).get("history") or {}
        return len(h.get("undo", [])), len(h.get("redo", []))

    def _step(self, stem: str, source: str, target: str) -> bool:
        self.index_of(stem)
        try:
            with self.edits.edit(stem) as rec:
                history = rec.get("history") or {}
                steps = list(history.get(source, []))
                if not steps:
                    raise _Unchanged
                step = steps.pop()
                back = {k: rec.get(k) for k in step}
                rec.update(step)
                rec["history"] = {source: steps, target: (list(history.get(target, [])) + [back])[-HISTORY_LIMIT:]}
        except _Unchanged:
            return False
        self._changed(stem)
        return True

    def review_progress(self) -> tuple[int, int]:
        return sum(self.edits.counts().values()), len(self.stems)
