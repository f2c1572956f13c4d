"""The pitch: class names, the model loaded from ``assets/field_model``, and 3D meshes."""

from pnlviz.field.model import Arc, FieldModel, FieldModelError, Keypoint, Segment, load_field_model, pitch_grid
from pnlviz.field.names import (
    ALL_CLASSES, CIRCLE_CLASSES, CLASS_TO_LINE_ID, FLIP_X, IGNORED_CLASSES, LINE_ID_TO_CLASS, MIRROR,
    MODEL_CLASSES, STRAIGHT_CLASSES, canonical_class_name, close_class_names,
)

__all__ = [
    "ALL_CLASSES", "Arc", "CIRCLE_CLASSES", "CLASS_TO_LINE_ID", "FLIP_X", "FieldModel", "FieldModelError",
    "IGNORED_CLASSES", "Keypoint", "LINE_ID_TO_CLASS", "MIRROR", "MODEL_CLASSES", "STRAIGHT_CLASSES",
    "Segment", "canonical_class_name", "close_class_names", "load_field_model", "pitch_grid",
]
