"""A second look at a frame's detections: which reading of the detector's heatmaps a frame keeps.

A detector with a ``second_look`` (the light default model: keypoints 0.2 and lines 0.3, against
0.3 and 0.4 for its first reading) hands over with a frame's detections a second reading of the
same heatmaps at those lower thresholds, when that finds more (``Predictions.second``). The frame
keeps its first reading unless that gives no camera and the second one does. A frame that
calibrates keeps exactly what it had; one that would get no camera is read from the network's
weaker peaks, which often hold the lines and points a close view shows. Their scores stay in the
detections, so a point under the first thresholds can be told apart.

The look is decided by calibrating, not by counting points. Reading again every frame with fewer
than 4 keypoints took the camera from frames that had one (``docs/detector.md``). So whoever
keeps detections (``pnlviz detect``, the app's background detection, the benchmarks) calls
:func:`take_look` before keeping them: a zip holds one reading.

A shot never sees a second look (:func:`for_shot`). Its frames are carried by their neighbours:
a central view whose first reading gives no camera is placed within a pixel or two by its shot,
while the camera its weaker peaks fit alone is often far off (clip 113 of ``bench_clip_edits.py``:
cameras standing on the pitch 4.6 m up; the shot model then took 348 edits instead of 27). The
detector states its first thresholds with its calibration settings (``shot_min_score``), and the
shot fits each frame's detections scoring at least those: the first reading again.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from typing import Any

from pnlviz.calib.frame import FrameInputs, FrameSettings, calib_params, calibrate_frame, observations_for
from pnlviz.calib.inputs import Detections
from pnlviz.calib.observations import Observations
from pnlviz.calib.params import CalibParams
from pnlviz.field.model import FieldModel

__all__ = ["confident", "detect_kept", "for_shot", "kept_reading", "second_look_count", "shot_observations",
           "take_look"]


def take_look(pred: Detections, size: tuple[int, int], detection_settings: Mapping | None = None,
              model: FieldModel | None = None) -> tuple[Detections, bool]:
    """The reading of a frame's detections to keep (without its ``second``), and whether it is the
    second one. ``size``: (W, H) of the frame; ``detection_settings``: the calibration settings
    the detector states for its detections (``Detector.calibration``). Calibrated as ``pnlviz
    calibrate --detections`` does by default (PnL on, the detector's settings applied)."""
    second = getattr(pred, "second", None)
    if second is None:
        return pred, False
    first = _alone(pred)
    settings = FrameSettings(source="detections", detection_settings=dict(detection_settings or {}))
    if calibrate_frame(FrameInputs(size, detections=first), settings, model).ok:
        return first, False
    if calibrate_frame(FrameInputs(size, detections=second), settings, model).ok:
        return _alone(second), True
    return first, False


def kept_reading(pred: Detections, image, detector) -> Detections:
    """``detector``'s detections ``pred`` of a BGR ``image`` as they are kept: the first reading,
    or the second where only that gives a camera (:func:`take_look` with the detector's
    calibration settings)."""
    return take_look(pred, (image.shape[1], image.shape[0]), detector.calibration)[0]


def detect_kept(detector, image) -> Detections:
    """One BGR image's detections as they are kept (:func:`kept_reading`)."""
    return kept_reading(detector.detect([image])[0], image, detector)


def _alone(pred):
    """``pred``'s reading without a second one attached."""
    return _reading(pred, pred.keypoints, pred.lines)


def _reading(like: Detections, keypoints: Mapping, lines: Mapping) -> Detections:
    """Detections of ``like``'s kind (:class:`pnlviz.data.Predictions`) holding these."""
    make: Any = type(like)
    return make(keypoints=dict(keypoints), lines=dict(lines))


def confident(pred: Detections, floor: tuple[float, float]) -> Detections:
    """``pred`` without the keypoints scoring under ``floor[0]`` and the lines with an end under
    ``floor[1]``; ``pred`` itself when nothing is under them."""
    kp_min, line_min = (float(v) for v in floor)
    kps = {k: v for k, v in pred.keypoints.items() if v[2] >= kp_min}
    lines = {k: v for k, v in pred.lines.items() if min(v[2], v[5]) >= line_min}
    if len(kps) == len(pred.keypoints) and len(lines) == len(pred.lines):
        return pred
    return _reading(pred, kps, lines)


def for_shot(inputs: FrameInputs, params: CalibParams) -> FrameInputs:
    """A clip frame's inputs as its shot fits them: its detections scoring at least the
    detector's first thresholds (``params.shot_min_score``); ``inputs`` itself when that drops
    nothing (a frame the first reading calibrated, an annotation)."""
    if inputs.detections is None or not any(params.shot_min_score):
        return inputs
    kept = confident(inputs.detections, params.shot_min_score)
    return inputs if kept is inputs.detections else replace(inputs, detections=kept)


def shot_observations(inputs: FrameInputs, settings: FrameSettings,
                      model: FieldModel) -> tuple[Observations | None, str | None, bool]:
    """A clip frame's observations as its shot fits them (:func:`for_shot`), their origin, and
    whether the frame was read a second time (the floor left some of its detections out: its
    first reading gave no camera, so it has none of its own in the clip)."""
    obs, origin = observations_for(inputs, settings.source, model)
    seen = for_shot(inputs, calib_params(settings, origin))
    if seen is inputs:
        return obs, origin, False
    return observations_for(seen, settings.source, model)[0], origin, True


def second_look_count(pred: Detections | None, detection_settings: Mapping) -> int:
    """How many of a frame's detections score under the detector's first thresholds (its
    ``shot_min_score``, in the calibration settings that applied to them): more than 0 only for
    a frame read a second time, whose camera rests on them (the app's card and ``pnlviz
    calibrate --report`` say so)."""
    floor = detection_settings.get("shot_min_score")
    if pred is None or not floor:
        return 0
    kept = confident(pred, (float(floor[0]), float(floor[1])))
    return len(pred.keypoints) + len(pred.lines) - len(kept.keypoints) - len(kept.lines)
