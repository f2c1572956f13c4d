"""The app's state without any GUI: the dataset, per-frame calibrations (computed on demand and
cached), review statuses and the edits store. The viser server (:mod:`pnlviz.app.server`) and the
tests drive the same object.

Edits never touch the source data: they live in an edits folder beside it
(``<data>.edits/`` by default), one JSON file per frame written atomically, so a crash mid-write
leaves the previous state intact and a restart restores everything.
"""

from __future__ import annotations

import hashlib
import json
import os
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from pnlviz.calib.calibrate import CalibParams, CalibrationResult, calibrate
from pnlviz.calib.inputs import observations_from_annotation, observations_from_predictions
from pnlviz.calib.observations import Observations
from pnlviz.data import DataError, atomic_write_text, open_dataset, read_predictions, read_predictions_info
from pnlviz.data.annotations import annotation_to_json, parse_annotation
from pnlviz.geometry.camera import Camera

REVIEW_STATES = ("accepted", "corrected", "rejected")
SOURCES = ("annotation", "detections", "both")
EVAL_SIZE = (960, 540)


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
    """Everything the app shows for one frame under the current settings."""

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


def _mirror_ids() -> dict[int, int]:
    """Keypoint id -> the id at the point mirrored through the pitch centre ((x, y) -> (-x, -y))."""
    from pnlviz.field.model import load_field_model

    model = load_field_model()
    ids = model.keypoint_ids
    xyz = model.keypoint_xyz(ids)
    out = {}
    for i, p in zip(ids, xyz):
        d = np.linalg.norm(xyz - p * [-1, -1, 1], axis=1)
        j = int(np.argmin(d))
        if d[j] < 1e-6:
            out[int(i)] = int(ids[j])
    return out


def merge_observations(ann: Observations, det: Observations) -> Observations:
    """Annotation and detections together. PnLCalib's networks name the sides so that the goal
    nearest the camera is the left one, annotations name the true sides: when the detections
    agree better with the annotation mirrored (keypoints with the same ids, median distance),
    their ids and line classes are mirrored first. The annotation wins where both have a point."""
    from pnlviz.field.names import MIRROR

    mirror = _mirror_ids()
    ann_xy = dict(zip(ann.kp_ids.tolist(), ann.kp_xy))
    det_xy = dict(zip(det.kp_ids.tolist(), det.kp_xy))

    def disagreement(mapping) -> float:
        d = [np.linalg.norm(ann_xy[i] - det_xy[j]) for i, j in mapping.items() if i in ann_xy and j in det_xy]
        return float(np.median(d)) if d else np.inf

    if disagreement({i: mirror.get(i, -1) for i in ann_xy}) < disagreement({i: i for i in ann_xy}):
        ids = np.array([mirror.get(int(i), int(i)) for i in det.kp_ids], int)
        lines = {MIRROR[k]: v for k, v in det.lines.items()}
        from pnlviz.field.model import load_field_model

        det = Observations(det.width, det.height, ids, det.kp_xy, load_field_model().keypoint_xyz(ids, pnlcalib=True),
                           det.kp_sets, det.kp_main, lines, det.circles)
    keep = ~np.isin(det.kp_ids, ann.kp_ids)
    return Observations(ann.width, ann.height, np.concatenate([ann.kp_ids, det.kp_ids[keep]]),
                        np.vstack([ann.kp_xy, det.kp_xy[keep]]), np.vstack([ann.kp_xyz, det.kp_xyz[keep]]),
                        np.concatenate([ann.kp_sets, det.kp_sets[keep]]), np.concatenate([ann.kp_main, det.kp_main[keep]]),
                        {**det.lines, **ann.lines}, ann.circles)


def apply_keypoint_edits(obs: Observations, overrides: dict) -> Observations:
    """Observations with keypoint edits applied: ``{"id": [x, y]}`` moves or adds a keypoint (at
    the catalogue position), ``{"id": null}`` removes it (not visible)."""
    from pnlviz.field.model import load_field_model

    model = load_field_model()
    ids, xy = list(obs.kp_ids), [tuple(p) for p in obs.kp_xy]
    sets, main = list(obs.kp_sets), list(obs.kp_main)
    for key, value in overrides.items():
        kid = int(key)
        if kid in ids:
            i = ids.index(kid)
            for lst in (ids, xy, sets, main):
                lst.pop(i)
        if value is not None:
            ids.append(kid)
            xy.append((float(value[0]), float(value[1])))
            group = model.keypoints[kid].group
            sets.append(group)
            main.append(group == "Kp")
    ids_arr = np.array(ids, int)
    return Observations(obs.width, obs.height, ids_arr, np.array(xy, float).reshape(-1, 2), model.keypoint_xyz(ids_arr),
                        np.array(sets, dtype="<U3"), np.array(main, bool), obs.lines, obs.circles)


class EditsStore:
    """One JSON file per frame in ``root/frames/``: review status and edited annotation."""

    def __init__(self, root: Path):
        self.root = Path(root)
        self.frames = self.root / "frames"
        self.frames.mkdir(parents=True, exist_ok=True)
        self._lock = threading.Lock()
        self._cache: dict[str, dict] = {}
        for p in self.frames.glob("*.json"):
            try:
                self._cache[p.stem] = json.loads(p.read_text())
            except (OSError, json.JSONDecodeError):
                continue  # a damaged edit file is ignored, never fatal

    def get(self, stem: str) -> dict:
        return dict(self._cache.get(stem, {}))

    def update(self, stem: str, **changes) -> dict:
        with self._lock:
            rec = dict(self._cache.get(stem, {}))
            for k, v in changes.items():
                if v is None:
                    rec.pop(k, None)
                else:
                    rec[k] = v
            rec["updated"] = time.time()
            atomic_write_text(self.frames / f"{stem}.json", json.dumps(rec, indent=1))
            self._cache[stem] = rec
            return rec

    def review(self, stem: str) -> str | None:
        return self._cache.get(stem, {}).get("review")

    def counts(self) -> dict[str, int]:
        out = {s: 0 for s in REVIEW_STATES}
        for rec in self._cache.values():
            if rec.get("review") in out:
                out[rec["review"]] += 1
        return out


class AppState:
    """Dataset + settings + calibration cache + edits. Thread-safe for the server's callbacks."""

    def __init__(self, data: Path, *, detections: Path | None = None, edits: Path | None = None,
                 size: tuple[int, int] = EVAL_SIZE, detector=None, source: str | None = None):
        self.data = Path(data)
        self.ds = open_dataset(self.data)
        if not len(self.ds):
            raise DataError(str(self.data), "no frames (expected <stem>.jpg / <stem>.json files)")
        self.predictions = read_predictions(detections) if detections else None
        #: a pnlviz.detect.run.Detector run on demand (in the background by the server) for frames
        #: without detections in the zip; its results join ``detected``
        self.detector = detector
        self.detected: dict[str, object] = {}
        if detector is not None and self.predictions is None:
            self.predictions = {}
        #: calibration settings for frames calibrated from detections alone: recorded beside the
        #: prediction zip by ``pnlviz detect``, else the detector's own (the light model's sidecar)
        self.detection_settings = dict((read_predictions_info(detections).get("calibration") if detections else None)
                                       or getattr(detector, "calibration", None) or {})
        CalibParams().updated(self.detection_settings)  # unknown names fail here, not on the first frame
        self.edits = EditsStore(edits or default_edits_dir(self.data))
        self.size = size
        self.stems = list(self.ds.stems)
        # start on the first frame with an image, the most telling one
        self.index = next((i for i, s in enumerate(self.stems) if self.ds.frame(s).has_image), 0)
        self.pnl = True
        self.alpha = 0.6
        # the keypoint source: "both" once there are detections, unless the caller says otherwise
        self.source = source or ("annotation" if self.predictions is None else "both")
        self._cache: dict[tuple, FrameView] = {}
        self._lock = threading.RLock()
        self._images: dict[str, np.ndarray | None] = {}
        self._undo: dict[str, list[dict]] = {}
        self._redo: dict[str, list[dict]] = {}

    # ------------------------------------------------------------------ settings
    @property
    def stem(self) -> str:
        return self.stems[self.index]

    def applied_detection_settings(self, origin: str | None) -> dict:
        """The detector's calibration settings when they apply: observations from detections
        alone, with PnL on (without PnL there is nothing they change)."""
        return self.detection_settings if origin == "detections" and self.pnl else {}

    def params(self, origin: str | None = None) -> CalibParams:
        """The calibration settings for observations from ``origin`` (see :meth:`_observations`)."""
        p = CalibParams(alpha=self.alpha).updated(self.applied_detection_settings(origin))
        if not self.pnl:
            p = CalibParams(pnl=False, refine_focal=False, refine_k1=False)
        return p

    def _key(self, stem: str) -> tuple:
        rec = self.edits.get(stem)
        edit = {k: rec[k] for k in ("annotation", "keypoints") if rec.get(k) is not None}
        return stem, self.pnl, round(self.alpha, 4), self.source, json.dumps(edit, sort_keys=True) if edit else None

    def go(self, index: int) -> str:
        self.index = int(np.clip(index, 0, len(self.stems) - 1))
        return self.stem

    def find(self, stem: str) -> int | None:
        try:
            return self.stems.index(stem.strip())
        except ValueError:
            return None

    # ------------------------------------------------------------------ frames
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

    def image(self, stem: str | None = None) -> np.ndarray | None:
        """The frame's pixels (BGR), decoded on demand; a few recent ones are kept."""
        stem = stem or self.stem
        with self._lock:
            if stem in self._images:
                return self._images[stem]
        try:
            img = self.ds.image(stem) if self.ds.frame(stem).has_image else None
        except DataError:
            img = None
        with self._lock:
            self._images[stem] = img
            while len(self._images) > 8:
                self._images.pop(next(iter(self._images)))
        return img

    def view(self, stem: str | None = None) -> FrameView:
        """The frame's view under the current settings (cached). Never raises on bad data."""
        stem = stem or self.stem
        key = self._key(stem)
        with self._lock:
            if key in self._cache:
                return self._cache[key]
        view = self._compute(stem)
        with self._lock:
            self._cache[key] = view
        return view

    def _compute(self, stem: str) -> FrameView:
        from pnlviz.metrics.soccernet import evaluate_frame

        idx = self.stems.index(stem)
        t0 = time.perf_counter()
        try:
            image = self.ds.frame(stem).has_image
            size = (self.ds.image_size(stem) or self.size) if image else self.size
            ann = self.annotation(stem)
            ref = self.ds.camera_dict(stem)
            ref = Camera.from_soccernet(ref).scaled(*size) if ref is not None else None
        except DataError as exc:
            return FrameView(stem, idx, False, self.size, None, None, None, error=str(exc))
        obs, origin = self._observations(stem, ann, size)
        if obs is None:
            return FrameView(stem, idx, image, size, ann, None, None, error="nothing to calibrate from",
                             ms=1e3 * (time.perf_counter() - t0), reference_camera=ref)
        try:
            result = calibrate(obs, self.params(origin))
        except Exception as exc:  # shown in the panel; the rest of the dataset keeps working
            return FrameView(stem, idx, image, size, ann, obs, None, error=f"internal error: {exc}", reference_camera=ref,
                             origin=origin)
        jac = {}
        if result.ok and ann:
            fr = evaluate_frame(result.camera.scaled(*EVAL_SIZE), ann)
            jac = {t: fr.accuracy(t) for t in (5, 10, 20)}
        detections = self.detections_for(stem)
        return FrameView(stem, idx, image, size, ann, obs, result, jac, ms=1e3 * (time.perf_counter() - t0),
                         reference_camera=ref, detections=detections, origin=origin)

    def _observations(self, stem: str, ann, size) -> tuple[Observations | None, str | None]:
        """The observations to calibrate from and where they came from ("annotation",
        "detections", "both", "edits" when only dragged keypoints exist, or None)."""
        obs, origin = self._base_observations(stem, ann, size)
        overrides = self.edits.get(stem).get("keypoints")
        if not overrides:
            return obs, origin
        if obs is None:
            obs, origin = Observations(*size), "edits"
        return apply_keypoint_edits(obs, overrides), origin

    def _base_observations(self, stem: str, ann, size) -> tuple[Observations | None, str | None]:
        W, H = size
        pred = self.detections_for(stem)
        use_ann = ann is not None and self.source in ("annotation", "both")
        # a frame with no annotation falls back to its detections under "annotation"
        use_det = pred is not None and (self.source in ("detections", "both") or not use_ann)
        if use_ann and use_det:
            return merge_observations(observations_from_annotation(ann, W, H)[0],
                                      observations_from_predictions(pred, W, H)), "both"
        if use_ann:
            return observations_from_annotation(ann, W, H)[0], "annotation"
        if use_det:
            return observations_from_predictions(pred, W, H), "detections"
        return None, None

    # ------------------------------------------------------------------ review and edits
    def set_review(self, status: str | None, stem: str | None = None) -> None:
        if status is not None and status not in REVIEW_STATES:
            raise ValueError(f"review status must be one of {REVIEW_STATES}")
        self.edits.update(stem or self.stem, review=status)

    def set_annotation(self, annotation: dict[str, np.ndarray], stem: str | None = None) -> None:
        """Store an edited annotation (autosaved at once) and mark the frame corrected."""
        stem = stem or self.stem
        self._record(stem, annotation=annotation_to_json(annotation))

    # one user action = one undo step; the edit record (annotation, keypoint overrides) is
    # autosaved at once, the undo history lives as long as the server
    def _record(self, stem: str, **changes) -> None:
        rec = self.edits.get(stem)
        before = {k: rec.get(k) for k in ("annotation", "keypoints")}
        with self._lock:
            self._undo.setdefault(stem, []).append(before)
            self._redo.pop(stem, None)
        self.edits.update(stem, review="corrected", **changes)

    def move_keypoint(self, kid: int, x: float, y: float, stem: str | None = None) -> None:
        """Put keypoint ``kid`` at pixel (x, y) of the frame (adds it if it was missing)."""
        stem = stem or self.stem
        kps = dict(self.edits.get(stem).get("keypoints") or {})
        kps[str(int(kid))] = [float(x), float(y)]
        self._record(stem, keypoints=kps)

    def hide_keypoint(self, kid: int, stem: str | None = None) -> None:
        """Mark keypoint ``kid`` not visible: it leaves the calibration and the labels."""
        stem = stem or self.stem
        kps = dict(self.edits.get(stem).get("keypoints") or {})
        kps[str(int(kid))] = None
        self._record(stem, keypoints=kps)

    def move_line_point(self, name: str, index: int, x: float, y: float, stem: str | None = None) -> None:
        """Move point ``index`` of annotated class ``name`` to pixel (x, y)."""
        stem = stem or self.stem
        ann = {k: v.copy() for k, v in (self.annotation(stem) or {}).items()}
        W, H = self.view(stem).size
        ann[name][index] = [x / (W - 1), y / (H - 1)]
        self._record(stem, annotation=annotation_to_json(ann))

    def undo(self, stem: str | None = None) -> bool:
        return self._step(stem or self.stem, self._undo, self._redo)

    def redo(self, stem: str | None = None) -> bool:
        return self._step(stem or self.stem, self._redo, self._undo)

    def _step(self, stem: str, source: dict, target: dict) -> bool:
        with self._lock:
            if not source.get(stem):
                return False
            state = source[stem].pop()
            rec = self.edits.get(stem)
            target.setdefault(stem, []).append({k: rec.get(k) for k in ("annotation", "keypoints")})
        self.edits.update(stem, annotation=state["annotation"], keypoints=state["keypoints"])
        return True

    def review_progress(self) -> tuple[int, int]:
        return sum(self.edits.counts().values()), len(self.stems)

    def cached_views(self) -> list[FrameView]:
        with self._lock:
            return [v for k, v in self._cache.items() if k == self._key(k[0])]
