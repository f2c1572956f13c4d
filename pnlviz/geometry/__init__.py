"""Camera model, projections, evaluator-compatible polyline clipping and conics."""

from pnlviz.geometry.camera import (
    MIN_DEPTH, Camera, look_at_rotation, pan_tilt_roll_from_rotation, rotation_from_pan_tilt_roll,
)
from pnlviz.geometry.polylines import clip_polyline, project_polylines, visible_pitch

__all__ = [
    "MIN_DEPTH", "Camera", "clip_polyline", "look_at_rotation", "pan_tilt_roll_from_rotation",
    "project_polylines", "rotation_from_pan_tilt_roll", "visible_pitch",
]
