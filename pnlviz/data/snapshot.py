"""A review snapshot: what the annotator saw when a frame was reviewed, kept in the frame's edit
record (``"snapshot"``), so that an export needs the data and the edits folder alone.

Layout::

    {"settings": {"source": "annotation"|"detections"|"both", "pnl": bool, "alpha": float},
     "detection_settings": {CalibParams field: value},   # the detector's, as they applied
     "detections": {PnLCalib frame object} | null,       # the detections used, if any
     "size": [W, H],                                     # the frame's pixels
     "edits": "<digest of the record's annotation and keypoints>",
     "labels": {"<id>": {"x", "y", "set", "provenance": "annotation"|"detection"|"hand"|"shot",
                         "residual": px | null}},        # pixels of the frame
     "camera": {SoccerNet camera at 960x540} | null,
     "failure": "why no camera" | null,
     "shot": {"clip": name, "shot": index, "first": stem, "last": stem} | absent,
     "slips": {"<id>": px | null} | absent}             # hand points the rest of the frame disagrees with

"slips": the keypoints a hand placed farther than the outlier gate from the camera the frame's
other observations give (:func:`pnlviz.calib.pins.slips`): kept as placed (the hand rules), said
when the frame was reviewed and carried into the export's manifest.

"shot" is there when the frame was reviewed with its shot (a clip's shot model,
:mod:`pnlviz.pipeline.clip`): the camera is the shot's, and a label of provenance "shot" is a
point placed by hand on another frame of the shot, carried here through the shot's cameras.

Pure format: building one from a frame's view is :mod:`pnlviz.pipeline.snapshot`'s job.
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Mapping
from typing import Any

from pnlviz.data.errors import DataError
from pnlviz.data.jsonio import as_number, describe
from pnlviz.data.predictions import parse_predictions
from pnlviz.conventions import PROVENANCES as _PROVENANCES, SOURCES

PROVENANCES = _PROVENANCES
SNAPSHOT_SOURCES = SOURCES


def edits_digest(record: Mapping) -> str:
    """A digest of what a record changes in a frame (its annotation and keypoint edits): a
    snapshot holds the one it was taken with, so a record changed since is told apart."""
    edit = {k: record.get(k) for k in ("annotation", "keypoints")}
    return hashlib.sha1(json.dumps(edit, sort_keys=True, separators=(",", ":")).encode()).hexdigest()[:16]


def _number(value: Any, what: str, source: str, optional: bool = False) -> float | None:
    if value is None and optional:
        return None
    v = as_number(value)
    if v is None or not math.isfinite(v):
        raise DataError(source, f"snapshot: {what} must be a finite number, got {describe(value)}")
    return v


def _labels(obj: Any, source: str) -> dict:
    if not isinstance(obj, Mapping):
        raise DataError(source, f'snapshot: "labels" must be an object of id -> label, got {describe(obj)}')
    out = {}
    for key, label in obj.items():
        if not str(key).isdigit() or not 1 <= int(key) <= 73:
            raise DataError(source, f"snapshot: keypoint id {str(key)[:20]!r} is not in the catalogue (1..73)")
        if not isinstance(label, Mapping) or label.get("provenance") not in PROVENANCES:
            raise DataError(source, f"snapshot: label {key} needs x, y, set and a provenance of "
                                    f"{', '.join(PROVENANCES)}, got {describe(label)}")
        out[str(int(key))] = {"x": _number(label.get("x"), f"label {key} x", source),
                              "y": _number(label.get("y"), f"label {key} y", source),
                              "set": str(label.get("set", ""))[:8], "provenance": label["provenance"],
                              "residual": _number(label.get("residual"), f"label {key} residual", source, True)}
    return out


def validate_snapshot(obj: Any, source: str) -> dict:
    """A checked copy of a review snapshot (see the module docstring); DataError otherwise."""
    if not isinstance(obj, Mapping):
        raise DataError(source, f"a snapshot must be a JSON object, got {describe(obj)}")
    settings = obj.get("settings")
    if not isinstance(settings, Mapping) or settings.get("source") not in SNAPSHOT_SOURCES:
        raise DataError(source, f'snapshot: "settings" needs a source of {", ".join(SNAPSHOT_SOURCES)}')
    size = obj.get("size")
    if not isinstance(size, list) or len(size) != 2 or not all(isinstance(v, int) and v >= 2 for v in size):
        raise DataError(source, f'snapshot: "size" must be [W, H], got {describe(size)}')
    ds = obj.get("detection_settings") or {}
    if not isinstance(ds, Mapping):
        raise DataError(source, f'snapshot: "detection_settings" must be an object, got {describe(ds)}')
    detections = obj.get("detections")
    if detections is not None:
        parse_predictions(detections, source)
    camera = obj.get("camera")
    if camera is not None and not isinstance(camera, Mapping):
        raise DataError(source, f'snapshot: "camera" must be a SoccerNet camera object, got {describe(camera)}')
    failure = obj.get("failure")
    out = {"settings": {"source": settings["source"], "pnl": bool(settings.get("pnl", True)),
                        "alpha": _number(settings.get("alpha", 0.6), "alpha", source)},
           "detection_settings": dict(ds), "detections": detections, "size": list(size),
           "edits": str(obj.get("edits", ""))[:64], "labels": _labels(obj.get("labels") or {}, source),
           "camera": None if camera is None else dict(camera),
           "failure": None if failure is None else str(failure)[:500]}
    shot = obj.get("shot")
    if shot is not None:
        index = as_number(shot.get("shot")) if isinstance(shot, Mapping) else None
        if index is None or not math.isfinite(index):
            raise DataError(source, f'snapshot: "shot" must be an object with the shot\'s index, got {describe(shot)}')
        out["shot"] = {"clip": str(shot.get("clip", ""))[:200], "shot": int(index),
                       "first": str(shot.get("first", ""))[:200], "last": str(shot.get("last", ""))[:200]}
    slips = obj.get("slips")
    if slips is not None:
        if not isinstance(slips, Mapping) or len(slips) > 73:
            raise DataError(source, f'snapshot: "slips" must be an object {{id: px}}, got {describe(slips)}')
        kept: dict[str, float | None] = {}
        for k, v in slips.items():
            px = None if v is None else as_number(v)  # null: the rest of the frame puts it off the camera
            if not str(k).isdigit() or not 1 <= int(k) <= 73 or (v is not None and (px is None or not px >= 0)):
                raise DataError(source, f'snapshot: "slips" must map keypoint ids to pixels, got {describe({k: v})}')
            kept[str(int(k))] = None if px is None else float(px)
        out["slips"] = kept
    return out
