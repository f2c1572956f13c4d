"""Keypoint-label generation from SoccerNet line annotations (paper Sec. III-A) and the heatmap
targets of PnLCalib's two networks (Sec. III-B).

Main entry points (pure functions on numpy arrays and dataclasses; I/O only in ``writer`` and
``cli``):

* :func:`keypoints_from_annotation` -> :class:`KeypointLabels` (sets Kp, Kpe, Kp1, Kp2, Kp3, in
  pixels, with the homography, reprojection errors and rejected candidates);
* :func:`line_extremities` -> ``{line id: LineExtremities}``;
* :func:`heatmap_targets` / :func:`training_targets` -> :class:`HeatmapTargets`;
* :func:`lr_decision`, :func:`mirror_annotation` (left-right disambiguation), :func:`flip_annotation`
  (the labels of a horizontally flipped image);
* :func:`write_labels`, :func:`read_labels`, :func:`labels_to_dict` (JSON schema in ``writer``);
* ``pnlviz labels`` (``cli.add_labels_parser`` / ``cli.run_labels``).
"""

from .catalogue import NETWORK_KEYPOINT_IDS, Catalogue, get_catalogue
from .extremities import line_extremities
from .heatmaps import (
    N_KEYPOINT_CHANNELS, N_LINE_CHANNELS, HeatmapTargets, heatmap_targets, keypoint_mask, training_targets,
)
from .keypoints import annotation_to_pixels, keypoints_from_annotation
from .leftright import (LONGITUDINAL_MAX_DEG, LRDecision, flip_annotation, lr_decision, mirror_annotation,
                        viewing_azimuth_deg)
from .types import SETS, KeypointLabel, KeypointLabels, LabelParams, LineExtremities, RejectedKeypoint
from .writer import labels_from_dict, labels_to_dict, labels_to_json, read_labels, write_labels

__all__ = [
    "Catalogue", "HeatmapTargets", "KeypointLabel", "KeypointLabels", "LONGITUDINAL_MAX_DEG", "LRDecision",
    "LabelParams", "LineExtremities", "N_KEYPOINT_CHANNELS", "N_LINE_CHANNELS", "NETWORK_KEYPOINT_IDS",
    "RejectedKeypoint", "SETS", "annotation_to_pixels", "flip_annotation", "get_catalogue", "heatmap_targets",
    "keypoint_mask", "keypoints_from_annotation", "labels_from_dict", "labels_to_dict", "labels_to_json",
    "line_extremities", "lr_decision", "mirror_annotation", "read_labels", "training_targets",
    "viewing_azimuth_deg", "write_labels",
]
