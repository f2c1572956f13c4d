"""The 3D view of one tab: the estimated camera as a frustum with the frame on it, and a ray from
the camera through every keypoint to its place on the pitch model (the pitch itself is the
server's, shared by every tab). Nodes are created once and updated in place; the frame is drawn on
the frustum only while the tab is in the 3D view.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation

from pnlviz.app.overlay import SET_RGB

FRUSTUM_SCALE = 4.0  # metres: distance of the frustum's image from the camera
FRUSTUM_RGB = (255, 190, 40)
#: where the 3D view starts when a frame has no camera: the whole pitch from high above the main stand
OVERVIEW = {"position": (0.0, 95.0, -70.0), "look_at": (0.0, 0.0, 0.0), "up": (0.0, 0.0, -1.0)}


def camera_wxyz(R: np.ndarray) -> np.ndarray:
    """viser orientation (camera-to-world quaternion, w first) of a world-to-camera rotation."""
    x, y, z, w = Rotation.from_matrix(np.asarray(R, float).T).as_quat()
    return np.array([w, x, y, z])


def behind_camera(cam, back: float = 12.0) -> dict:
    """A viewpoint ``back`` metres behind and above the estimated camera, looking where it looks:
    the frustum, the rays and the pitch in one view."""
    forward = cam.R[2]
    target = cam.C + 30.0 * forward
    position = cam.C - back * forward + np.array([0.0, 0.0, -0.3 * back])
    return {"position": position, "look_at": target, "up": (0.0, 0.0, -1.0)}


class Scene3D:
    """Frustum and rays of one tab, under scene path ``root``."""

    def __init__(self, scene, root: str):
        self.scene, self.root = scene, f"{root}/view3d"
        self._frustum = self._rays = None

    def hide(self) -> None:
        for handle in (self._frustum, self._rays):
            if handle is not None:
                handle.visible = False

    def show(self, view, image_rgb: np.ndarray | None) -> None:
        """The frame's camera, its image (when given) and the keypoint rays; nothing without a camera."""
        cam = view.camera
        if cam is None:
            self.hide()
            return
        W, H = view.size
        fov_y, wxyz = 2 * math.atan((H / 2) / cam.fy), camera_wxyz(cam.R)
        if image_rgb is None:
            image_rgb = np.full((9, 16, 3), 60, np.uint8)
        if self._frustum is None:
            self._frustum = self.scene.add_camera_frustum(
                f"{self.root}/camera", fov=fov_y, aspect=W / H, scale=FRUSTUM_SCALE, image=image_rgb, format="jpeg",
                jpeg_quality=85, wxyz=wxyz, position=cam.C, color=FRUSTUM_RGB)
        else:
            f = self._frustum
            f.fov, f.aspect, f.image, f.wxyz, f.position, f.visible = fov_y, W / H, image_rgb, wxyz, cam.C, True
        obs = view.observations
        if obs is None or not obs.n_keypoints:
            if self._rays is not None:
                self._rays.visible = False
            return
        seg = np.stack([np.repeat(cam.C[None], obs.n_keypoints, 0), obs.kp_xyz], axis=1)
        cols = np.array([SET_RGB.get(str(s), (255, 255, 255)) for s in obs.kp_sets], np.uint8)
        cols = np.repeat(cols[:, None], 2, 1)
        if self._rays is None:
            self._rays = self.scene.add_line_segments(f"{self.root}/rays", seg, cols, thickness=1.5,
                                                      thickness_units="screen")
        else:
            self._rays.points, self._rays.colors, self._rays.visible = seg, cols, True
