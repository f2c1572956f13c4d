"""Every geometry function that takes arrays refuses another shape with the argument's name, and
never reshapes it into something else (an (N, 2) array read as fewer 3-D points)."""

from __future__ import annotations

import numpy as np
import pytest

from pnlviz import ArgumentError
from pnlviz.geometry import angles, conics, distance, homography, polylines, projection, so3
from pnlviz.geometry.camera import Camera

CAM = Camera.from_look_at((0, 50, -20), (0, 0, 0), hfov_deg=40, width=960, height=540, k1=-0.05)
P6x2 = np.zeros((6, 2))  # six 2-D points: read as 3-D, they would be four
P4x3 = np.ones((4, 3))

CASES = [
    ("X", lambda: CAM.to_camera(P6x2)),
    ("xn", lambda: CAM.distort(P4x3)),
    ("xd", lambda: CAM.undistort(P4x3)),
    ("uv", lambda: CAM.pixel_rays(P4x3)),
    ("uv", lambda: CAM.back_project_to_ground(np.zeros((2, 3, 1)))),
    ("uv", lambda: CAM.lens_inverts(P4x3)),
    ("X", lambda: projection.to_camera(P6x2, np.eye(3), np.zeros(3))),
    ("C", lambda: projection.to_camera(P4x3, np.eye(3), np.zeros(2))),
    ("R", lambda: projection.to_camera(P4x3, np.stack([np.eye(3)] * 3), np.zeros(3))),  # one per point: 4
    ("Xc", lambda: projection.camera_to_pixels(P6x2, np.eye(3), 1000.0, 1.0, 480.0, 270.0, 0.0)),
    ("pts", lambda: projection.undistort_k1(P4x3, 1000.0, 1.0, 480.0, 270.0, 0.0)),
    ("xh", lambda: projection.dehomogenize(P6x2)),
    ("pts", lambda: homography.apply_homography(np.eye(3), P4x3)),
    ("H", lambda: homography.apply_homography(np.eye(2), P6x2)),
    ("H", lambda: homography.normalize_homography(np.ones(9))),
    ("H_field_to_image", lambda: homography.camera_from_ground_homography(np.ones((2, 3)), 960, 540)),
    ("pts", lambda: distance.closest_on_polyline(P4x3, P6x2)),
    ("poly", lambda: distance.closest_on_polyline(P6x2, np.zeros((1, 2)))),
    ("R", lambda: angles.pan_tilt_roll_from_rotation(np.eye(2))),
    ("target", lambda: angles.look_at_rotation(np.zeros(3), np.ones(2))),
    ("w", lambda: so3.so3_exp(np.zeros(4))),
    ("points", lambda: conics.fit_line(P4x3)),
    ("points", lambda: conics.fit_ellipse(np.zeros(10))),
    ("l1", lambda: conics.intersect_lines(np.ones(2), np.ones(3))),
    ("p", lambda: polylines.segment_in_image(np.zeros(3), np.zeros(2), 960, 540)),
    ("uv", lambda: polylines.clip_polyline(P4x3, np.ones(4, bool), 960, 540)),
    ("valid", lambda: polylines.clip_polyline(P6x2, np.ones(4, bool), 960, 540)),
]


@pytest.mark.parametrize("name,call", CASES, ids=[f"{i}-{n}" for i, (n, _) in enumerate(CASES)])
def test_a_wrong_shape_is_refused_by_name(name, call):
    with pytest.raises(ArgumentError) as info:
        call()
    assert str(info.value).startswith(f"{name}:"), str(info.value)


def test_the_right_shapes_still_work():
    X = np.array([[0.0, 0.0, 0.0], [10.0, 5.0, 0.0]])
    uv = CAM.project(X)
    np.testing.assert_allclose(CAM.back_project_to_ground(uv)[:, :2], X[:, :2], atol=1e-6)
    assert projection.to_camera(X, np.stack([CAM.R, CAM.R]), CAM.C).shape == (2, 3)
    np.testing.assert_allclose(homography.apply_homography(np.eye(3), uv), uv)
