"""The 3D view of one tab: the pitch model (markings, goals, nets), the estimated camera as a
frustum with the frame on it, and a ray from the camera through every keypoint to its place on
the pitch. Nodes are created the first time the tab opens the 3D view, updated in place, and hidden
in the image view (nothing of it is drawn there, not even culled: every frame of the image view
costs only what it shows).
"""

from __future__ import annotations

import functools
import math

import numpy as np
from scipy.spatial.transform import Rotation

from pnlviz.app.overlay import SET_RGB
from pnlviz.field.meshes import goals_mesh, grass_mesh, markings_mesh, nets_mesh

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


@functools.cache
def _pitch_meshes() -> dict:
    """name -> (vertices, faces, RGB, more options) of the pitch model (made once per process).
    The grass sits 1 cm below the markings (z points down) so that they never fight over depth."""
    grass, markings, goals, nets = grass_mesh(), markings_mesh(), goals_mesh(), nets_mesh()
    return {"grass": (np.asarray(grass.vertices) + [0.0, 0.0, 0.01], grass.faces, (40, 110, 50), {"side": "double"}),
            "markings": (markings.vertices, markings.faces, (245, 245, 245), {"side": "double"}),
            "goals": (goals.vertices, goals.faces, (255, 255, 255), {}),
            "nets": (nets.vertices, nets.faces, (200, 200, 210), {"opacity": 0.35, "side": "double"})}


class Scene3D:
    """The pitch, frustum and rays of one tab, under scene path ``root``."""

    def __init__(self, scene, root: str):
        self.scene, self.root = scene, f"{root}/view3d"
        self._frustum = self._rays = self._pitch = None

    def hide(self) -> None:
        for handle in (self._frustum, self._rays, self._pitch):
            if handle is not None:
                handle.visible = False

    def _show_pitch(self) -> None:
        if self._pitch is not None:
            self._pitch.visible = True
            return
        self._pitch = self.scene.add_frame(f"{self.root}/pitch", show_axes=False)
        for name, (vertices, faces, rgb, extra) in _pitch_meshes().items():
            self.scene.add_mesh_simple(f"{self.root}/pitch/{name}", vertices, faces, color=rgb, cast_shadow=False,
                                       receive_shadow=False, **extra)

    def show(self, view, image_rgb: np.ndarray | None) -> None:
        """The frame's camera, its image (when given) and the keypoint rays; nothing without a camera."""
        self._show_pitch()
        cam = view.camera
        if cam is None:
            for handle in (self._frustum, self._rays):
                if handle is not None:
                    handle.visible = False
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
