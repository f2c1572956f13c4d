"""Pure I/O for pnlviz: SoccerNet datasets and annotations, camera JSON zips, PnLCalib 2D
prediction zips, WC14 homographies, atomic and streaming writes, output path checks.

Every problem with an input file raises :class:`DataError` with a one-line message
``"<file>: <problem>"``. Input sizes are capped (:mod:`pnlviz.data.limits`).
"""

from .annotations import (
    COORD_RANGE,
    Annotation,
    annotation_to_json,
    from_pixels,
    parse_annotation,
    parse_annotation_bytes,
    read_annotation,
    to_pixels,
    write_annotation,
)
from .atomic import atomic_open, atomic_write_bytes, atomic_write_text
from .cameras import (
    REQUIRED_CAMERA_KEYS,
    camera_member_name,
    camera_stem,
    read_camera_json,
    read_camera_zip,
    read_cameras,
    validate_camera_dict,
    write_camera_json,
    write_camera_zip,
)
from .dataset import IMAGE_EXTENSIONS, Dataset, Frame, decode_image
from .splits import SplitDataset, open_dataset
from .errors import DataError
from .homographies import parse_homographies, read_homographies, write_homographies
from .layout import natural_key, sort_stems
from .limits import MAX_IMAGE_BYTES, MAX_IMAGE_PIXELS, MAX_JSON_BYTES
from .outputs import OutputError, check_output
from .predictions import (
    KEYPOINT_IDS,
    LINE_IDS,
    Predictions,
    parse_predictions,
    parse_predictions_bytes,
    predictions_info_path,
    predictions_to_json,
    read_predictions,
    read_predictions_info,
    write_predictions,
    write_predictions_info,
)
from .zipwriter import LineStream, ZipStream

__all__ = [
    "COORD_RANGE",
    "IMAGE_EXTENSIONS",
    "KEYPOINT_IDS",
    "LINE_IDS",
    "MAX_IMAGE_BYTES",
    "MAX_IMAGE_PIXELS",
    "MAX_JSON_BYTES",
    "REQUIRED_CAMERA_KEYS",
    "Annotation",
    "DataError",
    "Dataset",
    "Frame",
    "LineStream",
    "OutputError",
    "Predictions",
    "ZipStream",
    "annotation_to_json",
    "atomic_open",
    "atomic_write_bytes",
    "atomic_write_text",
    "camera_member_name",
    "camera_stem",
    "check_output",
    "decode_image",
    "from_pixels",
    "natural_key",
    "open_dataset",
    "SplitDataset",
    "parse_annotation",
    "parse_annotation_bytes",
    "parse_homographies",
    "parse_predictions",
    "parse_predictions_bytes",
    "predictions_info_path",
    "predictions_to_json",
    "read_annotation",
    "read_camera_json",
    "read_camera_zip",
    "read_cameras",
    "read_homographies",
    "read_predictions",
    "read_predictions_info",
    "sort_stems",
    "to_pixels",
    "validate_camera_dict",
    "write_annotation",
    "write_camera_json",
    "write_camera_zip",
    "write_homographies",
    "write_predictions",
    "write_predictions_info",
]
