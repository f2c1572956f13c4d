"""Metrics: the SoccerNet camera-calibration score (JaC@t, completeness CR, final score FS; equal
to the official evaluator, see :mod:`pnlviz.metrics.soccernet`) and the WC14 / TS-WorldCup
homography metrics (IoU part / whole, projection and reprojection errors, see
:mod:`pnlviz.metrics.homography`). ``pnlviz eval`` lives in :mod:`pnlviz.commands.evaluate`.

The names below are imported on first use, so that ``pnlviz.commands.evaluate`` (and the command line)
starts without loading OpenCV.
"""

from __future__ import annotations

import importlib

_EXPORTS = {
    "soccernet": ("DEFAULT_THRESHOLDS", "FrameResult", "Matching", "Summary", "ThresholdScore", "evaluate_dataset",
                  "evaluate_frame", "point_to_polyline_distance"),
    "homography": ("HomographyFrameResult", "HomographySummary", "evaluate_homographies", "evaluate_homography",
                   "homography_from_camera", "iou_part", "iou_whole", "projection_error", "reprojection_error"),
}
_WHERE = {name: module for module, names in _EXPORTS.items() for name in names}
__all__ = sorted(_WHERE)


def __getattr__(name: str):
    if name not in _WHERE:
        raise AttributeError(f"module 'pnlviz.metrics' has no attribute {name!r}")
    value = getattr(importlib.import_module(f"pnlviz.metrics.{_WHERE[name]}"), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))
