"""A frame's labels as an export writes them: each keypoint with its provenance (annotation,
detection, hand) and its residual to the frame's camera; the review snapshot that records them
when a frame is reviewed (:func:`take_snapshot`, format in :mod:`pnlviz.data.snapshot`); the
labels of a reviewed frame from its snapshot (:func:`reviewed_labels`) and of an unreviewed one
from its view (:func:`view_labels`); the outlier gate (:func:`gate`).

A reviewed frame exports what the annotator saw: the snapshot's labels and camera as they were,
or, when the record was changed since (by another program), the frame recalibrated from the
snapshot's detections and settings with the record's edits. A reviewed frame without a snapshot
(a record of an older version) is calibrated from its annotation and edits, never from
detections nobody saw. No app state here: ``pnlviz export`` and the app's button call the same.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace

import numpy as np

from pnlviz.calib.frame import FrameSettings, calibrate_frame
from pnlviz.calib.inputs import observations_from_annotation
from pnlviz.calib.observations import Observations
from pnlviz.conventions import EVAL_SIZE
from pnlviz.conventions import REVIEWED as _REVIEWED
from pnlviz.data.predictions import parse_predictions, predictions_to_json
from pnlviz.data.snapshot import edits_digest
from pnlviz.field.model import FieldModel, load_field_model
from pnlviz.geometry.camera import Camera
from pnlviz.labels.types import Label

#: the outlier gate: a visible point farther than this from its frame's camera, in pixels at
#: 960x540 (scaled with the frame's diagonal), is exported as flagged, not as ground truth
GATE_PX = 10.0
REVIEWED = _REVIEWED


@dataclass
class FrameLabels:
    """What an export writes of a frame. ``camera``: SoccerNet camera at 960x540 (None without
    one); ``basis``: "snapshot" (as reviewed), "snapshot inputs" (recalibrated from the
    snapshot's detections and settings), "edits" (a reviewed frame without a snapshot),
    "unreviewed"."""

    size: tuple[int, int]
    labels: dict[int, Label]
    camera: dict | None
    failure: str | None
    basis: str
    error: str | None = None


def gate_threshold(size: tuple[int, int], gate_px: float = GATE_PX) -> float:
    """The gate in pixels of a frame of ``size``: ``gate_px`` at 960x540, scaled with the diagonal."""
    return float(gate_px) * math.hypot(*size) / math.hypot(*EVAL_SIZE)


def inside(label: Label, size: tuple[int, int]) -> bool:
    return bool(0 <= label.x < size[0] and 0 <= label.y < size[1])


def gate(fl: FrameLabels, gate_px: float = GATE_PX) -> dict[int, float]:
    """The flagged points of a frame: id -> residual (px, inf when the camera does not see it) of
    every point inside the image farther than the gate from the frame's camera, unless a hand
    placed or moved it. A frame without a camera flags nothing (there is nothing to check against)."""
    if fl.camera is None:
        return {}
    limit = gate_threshold(fl.size, gate_px)
    out = {}
    for kid, label in fl.labels.items():
        r = math.inf if label.residual is None else label.residual
        if label.provenance != "hand" and inside(label, fl.size) and r > limit:
            out[kid] = r
    return out


def residuals(camera: Camera | None, obs: Observations) -> np.ndarray:
    """Each keypoint's distance (px) to its projection by ``camera`` (NaN: behind it; all NaN
    without a camera)."""
    if camera is None or not obs.n_keypoints:
        return np.full(obs.n_keypoints, np.nan)
    uv = camera.project(obs.kp_xyz)
    return np.hypot(*(uv - obs.kp_xy).T)


def provenance(obs: Observations, origin: str | None, annotation, keypoint_edits: Mapping | None,
               model: FieldModel) -> list[str]:
    """Where each keypoint of ``obs`` came from: "hand" (placed or moved), "annotation" or
    "detection" (with both, the annotation wins where it has the point)."""
    hand = {int(k) for k, v in (keypoint_edits or {}).items() if v is not None}
    annotated: set[int] = set()
    if origin == "both" and annotation:
        annotated = set(observations_from_annotation(annotation, obs.width, obs.height, model=model)[0].kp_ids.tolist())
    out = []
    for kid in obs.kp_ids.tolist():
        if kid in hand or origin == "edits":
            out.append("hand")
        elif origin == "annotation" or kid in annotated:
            out.append("annotation")
        else:
            out.append("detection")
    return out


def labels_of(obs: Observations | None, origin: str | None, annotation, keypoint_edits: Mapping | None,
              camera: Camera | None, model: FieldModel) -> dict[int, Label]:
    """The labels of observations, with provenance and residuals to ``camera``."""
    if obs is None:
        return {}
    res = residuals(camera, obs)
    prov = provenance(obs, origin, annotation, keypoint_edits, model)
    out = {}
    for kid, (x, y), s, p, r in zip(obs.kp_ids.tolist(), obs.kp_xy, obs.kp_sets, prov, res):
        out[int(kid)] = Label(float(x), float(y), str(s), p, None if camera is None else
                              (float(r) if np.isfinite(r) else None))
    return out


def _camera_json(camera: Camera | None) -> dict | None:
    return None if camera is None else camera.scaled(*EVAL_SIZE).to_soccernet()


def review_snapshot(record: Mapping, labels: Mapping[int, Label], camera: Camera | None, failure: str | None, *,
                    settings, detection_settings: Mapping, size, detections=None, shot: Mapping | None = None) -> dict:
    """The one builder of a review snapshot (format: :mod:`pnlviz.data.snapshot`), whoever
    reviews: a frame's own view (:func:`take_snapshot`) or a clip's shot model
    (:func:`pnlviz.pipeline.clip.shot_snapshot`). ``record``: the frame's edit record (its edits'
    digest is kept); ``labels``: what an export writes; ``camera`` (None: ``failure`` says why);
    ``settings``: the app's :class:`pnlviz.pipeline.settings.Settings`; ``detections``: the ones
    the labels used (None: none); ``shot``: where a shot-reviewed frame's shot is."""
    snap = {"settings": _settings_key(settings),
            "detection_settings": dict(detection_settings), "size": [int(v) for v in size],
            "detections": predictions_to_json(detections) if detections is not None else None,
            "edits": edits_digest(record),
            "labels": {str(k): {"x": v.x, "y": v.y, "set": v.set, "provenance": v.provenance, "residual": v.residual}
                       for k, v in labels.items()},
            "camera": _camera_json(camera),
            "failure": None if camera is not None else failure}
    if shot is not None:
        snap["shot"] = dict(shot)
    return snap


def take_snapshot(view, record: Mapping, detection_settings: Mapping, model: FieldModel | None = None) -> dict:
    """The review snapshot of a frame's ``view`` (a :class:`pnlviz.pipeline.view.FrameView`
    computed with ``record``'s edits): its labels, their provenance, the detections it used
    and the settings, the camera."""
    model = model or load_field_model()
    camera = view.result.camera if view.result is not None and view.result.ok else None
    used = view.detections is not None and view.origin in ("detections", "both")
    labels = labels_of(view.observations, view.origin, view.annotation, record.get("keypoints"), camera, model)
    failure = view.result.failure if view.result is not None else "nothing to calibrate from"
    return review_snapshot(record, labels, camera, failure, settings=view.settings,
                           detection_settings=detection_settings, size=view.size,
                           detections=view.detections if used else None)


def hand_slips(view, frame_settings, model: FieldModel | None = None, gate_px: float = GATE_PX,
               kids=None) -> dict[int, float]:
    """The hand-placed keypoints of ``view`` (``kids``: these only) farther than the outlier gate
    (``gate_px`` at 960x540, scaled to the frame) from the camera the frame's other observations
    give, calibrated as the view was (``frame_settings``, :class:`pnlviz.calib.frame.FrameSettings`):
    id -> px (:func:`pnlviz.calib.pins.slips`). Per hand point judged, one solve from the view's
    camera without that point (:func:`pnlviz.calib.calibrate.refit`; a calibration, without the
    search from broadcast priors, where the view has no camera: a prior's camera is no evidence
    against the hand, and each search costs about 0.8 s, on every release)."""
    from pnlviz.calib.calibrate import calibrate, refit
    from pnlviz.calib.frame import calib_params
    from pnlviz.calib.pins import slips

    obs = view.observations
    if obs is None or not obs.pins.any():
        return {}
    model = model or load_field_model()
    params = replace(calib_params(frame_settings, view.origin), prior_search=False)

    full = view.result.camera if view.result is not None and view.result.ok else None

    def fit(o):  # from the frame's own camera when it has one: one solve, not a calibration
        result = calibrate(o, params, model) if full is None else refit(o, full, params, model)
        return result.camera if result.ok else None

    return slips(obs, fit, gate_threshold(tuple(view.size), gate_px), kids)


def _settings_key(settings) -> dict:
    """What a snapshot records of the settings it was taken under."""
    return {"source": settings.source, "pnl": settings.pnl, "alpha": settings.alpha}


def recorded_slips(record: Mapping, settings) -> dict[int, float] | None:
    """The slips a reviewed frame's snapshot already judged (id -> px, ``inf`` off camera) when it
    was taken of these edits under these settings (:class:`pnlviz.pipeline.settings.Settings`) from
    the frame's own view; None when it was not (judge them: :func:`hand_slips`)."""
    snap = record.get("snapshot")
    if snap is None or snap.get("shot") is not None or snap.get("edits") != edits_digest(record) \
            or snap.get("settings") != _settings_key(settings):
        return None
    return {int(k): float("inf") if v is None else float(v) for k, v in (snap.get("slips") or {}).items()}


def _from_snapshot(snap: Mapping) -> FrameLabels:
    labels = {int(k): Label(v["x"], v["y"], v["set"], v["provenance"], v["residual"])
              for k, v in snap["labels"].items()}
    return FrameLabels(tuple(snap["size"]), labels, snap["camera"], snap["failure"], "snapshot")


def snapshot_flags(record: Mapping, gate_px: float = GATE_PX) -> tuple[dict[int, float], float]:
    """The points a frame's review snapshot would export flagged (id -> residual) and the gate in
    the frame's pixels; nothing without a snapshot."""
    snap = record.get("snapshot")
    if snap is None:
        return {}, gate_threshold(EVAL_SIZE, gate_px)
    fl = _from_snapshot(snap)
    return gate(fl, gate_px), gate_threshold(fl.size, gate_px)


def reviewed_labels(reader, stem: str, record: Mapping, model: FieldModel | None = None) -> FrameLabels:
    """A reviewed frame's labels (see the module docstring) from the reader's data and edits
    folder alone: never from detections the reader has that were not on screen."""
    model = model or load_field_model()
    snap = record.get("snapshot")
    if snap is not None and snap.get("edits") == edits_digest(record):
        return _from_snapshot(snap)
    read = reader.read(stem)
    if read.inputs is None:
        return FrameLabels(reader.size, {}, None, read.error, "edits", error=read.error)
    if snap is not None:
        dets = parse_predictions(snap["detections"]) if snap.get("detections") is not None else None
        settings = FrameSettings(pnl=snap["settings"]["pnl"], alpha=snap["settings"]["alpha"],
                                 source=snap["settings"]["source"], detection_settings=snap["detection_settings"])
        basis = "snapshot inputs"
    else:
        dets, settings, basis = None, FrameSettings(source="annotation"), "edits"
    inputs = replace(read.inputs, detections=dets)
    fc = calibrate_frame(inputs, settings, model)
    camera = fc.camera
    labels = labels_of(fc.observations, fc.origin, inputs.annotation, inputs.keypoint_edits, camera, model)
    failure = None if fc.failure is None else fc.failure.message  # a frame has a failure when not ok
    internal = fc.failure.message if fc.failure is not None and fc.failure.code == "internal" else None
    return FrameLabels(inputs.size, labels, _camera_json(camera), failure, basis, error=read.image_error or internal)


def view_labels(view, record: Mapping, model: FieldModel | None = None) -> FrameLabels:
    """An unreviewed frame's labels from its view (the reader's detections and settings)."""
    model = model or load_field_model()
    camera = view.result.camera if view.result is not None and view.result.ok else None
    labels = labels_of(view.observations, view.origin, view.annotation, record.get("keypoints"), camera, model)
    failure = None if camera is not None else (view.result.failure if view.result is not None else None)
    return FrameLabels(tuple(view.size), labels, _camera_json(camera), failure, "unreviewed", error=view.error)


__all__ = ["GATE_PX", "REVIEWED", "FrameLabels", "Label", "gate", "gate_threshold", "labels_of", "provenance",
           "residuals", "review_snapshot", "reviewed_labels", "snapshot_flags", "take_snapshot", "view_labels",
           "hand_slips"]
