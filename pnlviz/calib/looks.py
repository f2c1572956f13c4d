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
"""

from __future__ import annotations

from collections.abc import Mapping

from pnlviz.calib.frame import FrameInputs, FrameSettings, calibrate_frame
from pnlviz.calib.inputs import Detections
from pnlviz.field.model import FieldModel

__all__ = ["take_look"]


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


def _alone(pred):
    """``pred``'s reading without a second one attached."""
    return type(pred)(keypoints=pred.keypoints, lines=pred.lines)
