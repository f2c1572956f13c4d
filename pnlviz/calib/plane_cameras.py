"""A frame's first cameras from the keypoints of one plane: a RANSAC homography from the plane's
own coordinates to pixels (:func:`plane_homography`), decomposed into a world camera
(:func:`camera_from_plane_homography`). The vote of :mod:`pnlviz.calib.calibrate` chooses among them."""

from __future__ import annotations

import cv2
import numpy as np

from pnlviz.calib.pipeline import plane_frame
from pnlviz.field.model import FieldModel
from pnlviz.geometry.camera import Camera
from pnlviz.geometry.homography import camera_from_ground_homography


def plane_homography(local_xy: np.ndarray, xy: np.ndarray, threshold: float) -> tuple[np.ndarray, np.ndarray] | None:
    """RANSAC homography (OpenCV, least-squares refit on the inliers) from plane coordinates to
    pixels, with its inlier mask; exact for 4 points; None when degenerate."""
    if len(xy) < 4:
        return None
    if len(xy) == 4:
        H, _ = cv2.findHomography(local_xy, xy, 0)
        mask = np.ones(4, bool)
    else:
        H, mask = cv2.findHomography(local_xy, xy, cv2.RANSAC, threshold, maxIters=500, confidence=0.999)
    if H is None or mask is None or mask.sum() < 4:
        return None
    return H, np.asarray(mask).ravel().astype(bool)


def camera_from_plane_homography(H: np.ndarray, plane: str, width: int, height: int,
                                  model: FieldModel) -> Camera | None:
    """Decompose a homography from a plane's local coordinates (see
    :func:`pnlviz.calib.pipeline.plane_frame`) to pixels into a world camera (centred principal
    point, square pixels)."""
    cam = camera_from_ground_homography(H, width, height)
    if cam is None:
        return None
    if plane == "ground":  # its local frame is the world's
        return cam
    B, origin = plane_frame(plane, model)
    # back to the world frame: x_cam = R_l (B (X - o) - C_l) = (R_l B) (X - (o + B^T C_l))
    return cam.with_pose(cam.R @ B, origin + B.T @ cam.C)
