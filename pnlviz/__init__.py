"""pnlviz: PnLCalib sports field registration with an interactive inspection and annotation app.

The Python API (:mod:`pnlviz.api`): :func:`keypoints`, :func:`calibrate` -> :class:`Calibration`,
:class:`Camera` (``project``, ``image_to_pitch``, ``homography``), :func:`top_view`,
:func:`open_dataset`, :func:`qa` (a dataset's label errors, ranked), and ``pnlviz.detect(image)``
with ``pip install 'pnlviz[detect]'``.
"""

__version__ = "0.2.0"

from pnlviz.paths import ASSETS_DIR, EXAMPLES_DIR, REPO_ROOT, SAMPLE_DIR  # noqa: E402

# pnlviz.detect(image) is the subpackage pnlviz.detect, callable (see pnlviz/detect/__init__.py)
from pnlviz import detect  # noqa: E402
from pnlviz.api import (  # noqa: E402
    ArgumentError, Calibration, Camera, ClipCalibration, calibrate, calibrate_clip, keypoint_names, keypoints,
    open_dataset, qa, top_view,
)

__all__ = ["ASSETS_DIR", "EXAMPLES_DIR", "REPO_ROOT", "SAMPLE_DIR", "ArgumentError", "Calibration", "Camera",
           "ClipCalibration", "calibrate", "calibrate_clip", "detect", "keypoint_names", "keypoints", "open_dataset",
           "qa", "top_view"]
