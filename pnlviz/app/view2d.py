"""The image view: where a frame's pixels sit in the 3D scene, and the browser camera that looks
at them straight on, as a zoom and a centre.

A frame is drawn on a plane of its own (:class:`ImagePlane`), far below the pitch model (z points
down in the SoccerNet world) and facing a camera that looks along +z, so the pitch is behind that
camera and never shows. Every frame has this plane, calibrated or not. The browser camera over
it is a :class:`View2D`: the image pixel at the centre of the canvas and the zoom, in canvas
pixels per image pixel (1 = native resolution). Both are pure: they map pixels to scene points
and back, and views to camera poses and back; :mod:`pnlviz.app.workspace` puts them on screen.

Pixel convention: integer coordinates are pixel centres (as OpenCV draws and as keypoints are
stored); pixel ``(0, 0)`` covers ``[-0.5, 0.5]^2``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: depth of the image plane (metres below the pitch: out of sight of the 3D view's pitch)
PLANE_Z = 1000.0
#: width of every frame on its plane, in scene units (so a view holds across frames of any size)
PLANE_WIDTH = 16.0
#: vertical field of view of the browser camera in the image view
FOV_Y = math.radians(30.0)
#: zoom limits, canvas pixels per image pixel: out to a quarter of "fit", in to 32x
MAX_ZOOM = 32.0
MIN_ZOOM_OF_FIT = 0.25
#: how far in front of the image a layer of the scene floats (scene units; the camera is >= 0.4
#: away): the points' grab meshes (everything you see over the frame is the page's)
LAYER_DEPTH = {"grab": 0.0005}


@dataclass(frozen=True)
class ImagePlane:
    """A ``W`` x ``H`` frame laid out on the plane z = :data:`PLANE_Z`, centred on the z axis,
    :data:`PLANE_WIDTH` wide; image x along world +x, image y along world +y."""

    W: int
    H: int

    @property
    def scale(self) -> float:
        """Scene units per image pixel."""
        return PLANE_WIDTH / self.W

    @property
    def extent(self) -> tuple[float, float]:
        """(width, height) of the whole frame on the plane, scene units."""
        return PLANE_WIDTH, self.H * self.scale

    def world(self, uv, layer: str | None = None) -> np.ndarray:
        """Scene points of pixels ``uv`` (..., 2), floated towards the camera by ``layer``'s depth."""
        uv = np.asarray(uv, float)
        k = self.scale
        z = PLANE_Z - (LAYER_DEPTH[layer] if layer else 0.0)
        out = np.empty(uv.shape[:-1] + (3,))
        out[..., 0] = k * (uv[..., 0] + 0.5 - self.W / 2)
        out[..., 1] = k * (uv[..., 1] + 0.5 - self.H / 2)
        out[..., 2] = z
        return out

    def pixel(self, xyz) -> np.ndarray:
        """Pixels of scene points (..., 3) on (or floated above) the plane: x and y only."""
        xyz = np.asarray(xyz, float)
        k = self.scale
        return np.stack([xyz[..., 0] / k + self.W / 2 - 0.5, xyz[..., 1] / k + self.H / 2 - 0.5], axis=-1)

    def pixel_on_ray(self, origin, through) -> np.ndarray | None:
        """The pixel where the ray from ``origin`` through ``through`` meets the image plane (the
        exact pixel under the pointer, whatever layer it grabbed), or None if it does not."""
        o, p = np.asarray(origin, float), np.asarray(through, float)
        d = p - o
        if abs(d[2]) < 1e-12:
            return None
        t = (PLANE_Z - o[2]) / d[2]
        if t <= 0:
            return None
        return self.pixel(o + t * d)


@dataclass(frozen=True)
class View2D:
    """The browser camera over an image: the image pixel at the canvas centre and the zoom
    (canvas pixels per image pixel)."""

    cu: float
    cv: float
    zoom: float

    # ------------------------------------------------------------------ construction
    @classmethod
    def fit(cls, plane: ImagePlane, canvas: tuple[int, int], margin: float = 0.96) -> View2D:
        """The whole frame in the canvas (``canvas``: width, height in pixels), centred."""
        Wc, Hc = canvas
        return cls(plane.W / 2 - 0.5, plane.H / 2 - 0.5, margin * min(Wc / plane.W, Hc / plane.H))

    @classmethod
    def from_camera(cls, plane: ImagePlane, position, canvas_height: int, fov: float = FOV_Y) -> View2D:
        """The view of a camera at ``position`` looking straight at the plane."""
        position = np.asarray(position, float)
        d = PLANE_Z - position[2]
        if not (d > 0 and math.isfinite(d)):
            raise ValueError(f"a camera at z = {position[2]:.6g} is not in front of the image plane")
        cu, cv = plane.pixel(position)
        return cls(float(cu), float(cv), plane.scale * canvas_height / (2 * math.tan(fov / 2) * d))

    # ------------------------------------------------------------------ camera
    def distance(self, plane: ImagePlane, canvas_height: int, fov: float = FOV_Y) -> float:
        """How far in front of the plane the camera is for this zoom."""
        return plane.scale * canvas_height / (2 * math.tan(fov / 2) * self.zoom)

    def camera(self, plane: ImagePlane, canvas_height: int, fov: float = FOV_Y) -> tuple[np.ndarray, np.ndarray]:
        """(position, look_at) of the camera; it looks along +z with the image's y down, i.e.
        orientation ``wxyz = (1, 0, 0, 0)`` in viser's OpenCV convention."""
        at = plane.world([self.cu, self.cv])
        position = at - [0.0, 0.0, self.distance(plane, canvas_height, fov)]
        return position, at

    # ------------------------------------------------------------------ screen
    def to_pixel(self, screen, canvas: tuple[int, int]) -> np.ndarray:
        """Image pixel under canvas point ``screen`` (pixels from the canvas's top-left corner)."""
        Wc, Hc = canvas
        s = np.asarray(screen, float)
        return np.stack([self.cu + (s[..., 0] - Wc / 2) / self.zoom, self.cv + (s[..., 1] - Hc / 2) / self.zoom], -1)

    def to_screen(self, uv, canvas: tuple[int, int]) -> np.ndarray:
        """Canvas point of image pixel ``uv`` (the inverse of :meth:`to_pixel`)."""
        Wc, Hc = canvas
        uv = np.asarray(uv, float)
        return np.stack([Wc / 2 + (uv[..., 0] - self.cu) * self.zoom, Hc / 2 + (uv[..., 1] - self.cv) * self.zoom], -1)

    # ------------------------------------------------------------------ moves
    def zoomed(self, factor: float, at=None, limits: tuple[float, float] | None = None) -> View2D:
        """Zoom by ``factor`` keeping image pixel ``at`` (default: the centre) where it is on
        screen; ``limits``: (min, max) zoom."""
        lo, hi = limits or (0.0, MAX_ZOOM)
        zoom = float(np.clip(self.zoom * factor, lo, hi))
        if at is None:
            return View2D(self.cu, self.cv, zoom)
        au, av = float(at[0]), float(at[1])
        r = self.zoom / zoom
        return View2D(au + (self.cu - au) * r, av + (self.cv - av) * r, zoom)

    def panned(self, du: float, dv: float) -> View2D:
        """The image moved by (du, dv) image pixels under a fixed canvas (the centre moves back)."""
        return View2D(self.cu - du, self.cv - dv, self.zoom)

    def clamped(self, plane: ImagePlane, canvas: tuple[int, int]) -> View2D:
        """This view with the zoom within limits and the frame's centre never pushed off-screen."""
        fit = View2D.fit(plane, canvas).zoom
        zoom = float(np.clip(self.zoom, MIN_ZOOM_OF_FIT * fit, max(MAX_ZOOM, fit)))
        cu = float(np.clip(self.cu, -0.5, plane.W - 0.5))
        cv = float(np.clip(self.cv, -0.5, plane.H - 0.5))
        return View2D(cu, cv, zoom)

    def relative(self, plane: ImagePlane, canvas: tuple[int, int]) -> tuple[float, float, float]:
        """The view as fractions of the frame and of its fit zoom (holds across frame sizes)."""
        return (self.cu + 0.5) / plane.W, (self.cv + 0.5) / plane.H, self.zoom / View2D.fit(plane, canvas).zoom

    @classmethod
    def from_relative(cls, rel: tuple[float, float, float], plane: ImagePlane, canvas: tuple[int, int]) -> View2D:
        fu, fv, fz = rel
        return cls(fu * plane.W - 0.5, fv * plane.H - 0.5, fz * View2D.fit(plane, canvas).zoom)


def placed(plane: ImagePlane | None) -> ImagePlane:
    """The plane a frame is shown on, once one is (what is drawn over a frame comes after it)."""
    assert plane is not None, "no frame shown yet"
    return plane


def snap(uv, points, segments, radius: float) -> tuple[np.ndarray, str | None]:
    """``uv`` moved onto the nearest of ``points`` (N, 2) within ``radius``, else onto the nearest
    point of ``segments`` (M, 2, 2) within ``radius``, else left where it is. Returns the pixel and
    what it snapped to ("point", "line" or None)."""
    uv = np.asarray(uv, float)
    pts = np.asarray(points, float).reshape(-1, 2)
    if len(pts):
        d = np.hypot(*(pts - uv).T)
        i = int(np.argmin(d))
        if d[i] <= radius:
            return pts[i].copy(), "point"
    seg = np.asarray(segments, float).reshape(-1, 2, 2)
    if len(seg):
        a, b = seg[:, 0], seg[:, 1]
        ab = b - a
        t = np.clip(np.einsum("ij,ij->i", uv - a, ab) / np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-12), 0.0, 1.0)
        foot = a + t[:, None] * ab
        d = np.hypot(*(foot - uv).T)
        i = int(np.argmin(d))
        if d[i] <= radius:
            return foot[i], "line"
    return uv.copy(), None
