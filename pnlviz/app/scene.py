"""Where the frame sits in the 3D view: the image plane in front of the estimated camera, and the
maps between its pixels and world points on it."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

FRUSTUM_SCALE = 4.0  # metres: distance of the image plane from the camera in the 3D view
HANDLE_SCALE = FRUSTUM_SCALE * 0.035  # arrows of the drag handles, metres on the image plane


def camera_wxyz(R: np.ndarray) -> np.ndarray:
    """viser orientation (camera-to-world quaternion, w first) of a world-to-camera rotation."""
    x, y, z, w = Rotation.from_matrix(np.asarray(R, float).T).as_quat()
    return np.array([w, x, y, z])


def pixel_to_plane(cam, uv, depth: float = FRUSTUM_SCALE * 0.99) -> np.ndarray:
    """World point on the frustum's image plane (``depth`` in front of the camera) under pixel uv."""
    ray = np.array([(uv[0] - cam.cx) / cam.fx, (uv[1] - cam.cy) / cam.fy, 1.0])
    return cam.C + cam.R.T @ (depth * ray)


def plane_to_pixel(cam, point) -> np.ndarray:
    x = cam.R @ (np.asarray(point, float) - cam.C)
    return np.array([cam.fx * x[0] / x[2] + cam.cx, cam.fy * x[1] / x[2] + cam.cy])


def ray_to_pixel(cam, origin, direction, depth: float = FRUSTUM_SCALE * 0.999) -> np.ndarray | None:
    """Pixel where a click ray meets the frustum's image plane, or None."""
    o = cam.R @ (np.asarray(origin, float) - cam.C)
    d = cam.R @ np.asarray(direction, float)
    if abs(d[2]) < 1e-12:
        return None
    t = (depth - o[2]) / d[2]
    if t <= 0:
        return None
    p = o + t * d
    return np.array([cam.fx * p[0] / p[2] + cam.cx, cam.fy * p[1] / p[2] + cam.cy])
