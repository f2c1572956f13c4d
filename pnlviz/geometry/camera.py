"""Pinhole camera in the SoccerNet convention, with SoccerNet's lens distortion model.

``x_cam = R (X - C)``: ``R`` rotates world into camera coordinates (camera x right, y down, z
forward) and ``C`` is the camera centre in the world (metres, z down). ``K`` has square pixels by
default and zero skew. Distortion follows the SoccerNet evaluator (and OpenCV's rational + thin
prism model): radial ``k1..k6`` (numerator k1..k3, denominator k4..k6), tangential ``p1, p2``,
thin prism ``s1..s4``.

SoccerNet camera JSON: ``pan_degrees, tilt_degrees, roll_degrees, position_meters,
x_focal_length, y_focal_length, principal_point, radial_distortion, tangential_distortion,
thin_prism_distortion`` with ``R^T = Rz(pan) Rx(tilt) Rz(roll)``. The evaluator takes the image
width as ``2 * principal_point[0]``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike

from pnlviz.errors import ArgumentError
from pnlviz.geometry.angles import look_at_rotation, pan_tilt_roll_from_rotation, rotation_from_pan_tilt_roll
from pnlviz.geometry.shapes import as_points

#: Points closer to the camera plane than this (metres along the optical axis) are not projected;
#: the SoccerNet evaluator uses the same bound.
MIN_DEPTH = 1e-3


def _frozen_zeros(n: int) -> np.ndarray:
    z = np.zeros(n)
    z.setflags(write=False)
    return z


#: shared read-only defaults: no lens distortion
_NO_RADIAL, _NO_TANGENTIAL, _NO_THIN_PRISM = _frozen_zeros(6), _frozen_zeros(2), _frozen_zeros(4)


#: a camera's centre farther than this (metres) from the pitch's centre is not a broadcast camera
MAX_CAMERA_DISTANCE_M = 10_000.0
#: a pixel whose ground point is farther than this (metres) from the pitch is not on the pitch
#: (:meth:`Camera.image_to_pitch`: rays grazing the horizon meet the ground kilometres away)
MAX_PITCH_DISTANCE_M = 1_000.0


def _numbers(d: Mapping[str, Any], key: str, n: int | None, *, positive: bool = False,
             optional: bool = False) -> np.ndarray:
    """``d[key]``: ``n`` finite numbers (one number when ``n`` is None), positive with
    ``positive``; zeros when ``optional`` and missing; ArgumentError naming the key otherwise."""
    if key not in d:
        if optional:
            return np.zeros(n or 1)
        raise ArgumentError(f"camera[{key!r}]: missing (a SoccerNet camera dict has it)")
    value = d[key]
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ArgumentError(f"camera[{key!r}]: expected {'a number' if n is None else f'{n} numbers'}, "
                            f"got {str(value)[:60]!r}") from None
    if value is None or isinstance(value, (bool, np.bool_, str, bytes)) or arr.shape != (() if n is None else (n,)):
        raise ArgumentError(f"camera[{key!r}]: expected {'a number' if n is None else f'{n} numbers'}, "
                            f"got {str(value)[:60]!r}")
    if not np.all(np.isfinite(arr)):
        raise ArgumentError(f"camera[{key!r}]: must be finite, got {str(value)[:60]!r}")
    if positive and not np.all(arr > 0):
        raise ArgumentError(f"camera[{key!r}]: must be positive, got {str(value)[:60]!r}")
    return arr.reshape(-1)


def _image_size_arg(width, height, image_size) -> tuple[float, float] | None:
    """(width, height) from ``image_size`` or ``width`` and ``height`` (one way only), checked."""
    if image_size is not None and (width is not None or height is not None):
        raise ArgumentError("image_size: give the size once, as image_size or as width and height")
    if image_size is None and width is None and height is None:
        return None
    if image_size is None:
        # from_soccernet(d, (w, h)): the size as one argument, as the contract writes it
        image_size = width if height is None and isinstance(width, (tuple, list, np.ndarray)) else (width, height)
    try:
        w, h = (float(v) for v in image_size)
    except (TypeError, ValueError):
        raise ArgumentError(f"image_size: expected (width, height), got {image_size!r:.60}") from None
    if not (math.isfinite(w) and math.isfinite(h) and w > 0 and h > 0):
        raise ArgumentError(f"image_size: expected a positive (width, height), got {image_size!r:.60}")
    return w, h


@dataclass(frozen=True)
class Camera:
    """A calibrated camera for an image of ``width`` x ``height`` pixels: focal lengths ``fx``,
    ``fy`` and principal point ``cx``, ``cy`` in pixels, rotation ``R`` (3, 3) world -> camera,
    centre ``C`` (3,) in metres (SoccerNet's world frame), and SoccerNet's lens terms. Immutable:
    equal cameras compare and hash alike (:meth:`allclose` for a tolerance).

    >>> cam = Camera.from_look_at((0, 50, -20), (0, 0, 0), hfov_deg=40, width=960, height=540)
    >>> cam.width, cam.height, round(cam.fx, 1), cam.C.tolist()
    (960, 540, 1318.8, [0.0, 50.0, -20.0])
    """

    fx: float
    fy: float
    cx: float
    cy: float
    R: np.ndarray  # (3, 3) world -> camera
    C: np.ndarray  # (3,) camera centre in world metres
    width: float
    height: float
    radial: np.ndarray = field(default_factory=lambda: _NO_RADIAL)
    tangential: np.ndarray = field(default_factory=lambda: _NO_TANGENTIAL)
    thin_prism: np.ndarray = field(default_factory=lambda: _NO_THIN_PRISM)
    # which lens terms are set (derived in __post_init__, not an argument, not compared)
    _lens: Literal["none", "k1", "full"] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        for name, shape in (("R", (3, 3)), ("C", (3,)), ("radial", (6,)), ("tangential", (2,)), ("thin_prism", (4,))):
            value = getattr(self, name)
            if isinstance(value, np.ndarray) and value.base is None and not value.flags.writeable and value.dtype == float:
                if value.shape != shape:
                    raise ValueError(f"Camera.{name} must have shape {shape}, got {value.shape}")
                continue  # already a frozen array (another camera's): shared, never changed
            arr = np.array(value, dtype=float)
            if arr.shape != shape:
                raise ValueError(f"Camera.{name} must have shape {shape}, got {arr.shape}")
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        # which lens terms are set, for a fast distortion on the common cases (not a field)
        rest = ((self.tangential is not _NO_TANGENTIAL and self.tangential.any())
                or (self.thin_prism is not _NO_THIN_PRISM and self.thin_prism.any()) or self.radial[1:].any())
        object.__setattr__(self, "_lens", "full" if rest else "k1" if self.radial[0] != 0.0 else "none")

    # ------------------------------------------------------------------ comparison
    def _values(self) -> tuple:
        return (self.fx, self.fy, self.cx, self.cy, self.width, self.height, self.R, self.C, self.radial,
                self.tangential, self.thin_prism)

    def __eq__(self, other: object) -> bool:
        """Exactly the same camera (every parameter equal); :meth:`allclose` for a tolerance."""
        if not isinstance(other, Camera):
            return NotImplemented
        return all(np.array_equal(a, b) for a, b in zip(self._values(), other._values()))

    def __hash__(self) -> int:
        """Cameras are immutable (frozen, read-only arrays): hashable, equal cameras alike."""
        return hash(tuple(np.asarray(v, float).tobytes() for v in self._values()))

    def allclose(self, other: "Camera", *, rtol: float = 1e-9, atol: float = 1e-9) -> bool:
        """Every parameter of ``other`` within ``atol + rtol * |value|`` of this camera's (as
        :func:`numpy.allclose`; pixels, metres and the rotation's entries alike).

        >>> cam = Camera.from_look_at((0, 50, -20), (0, 0, 0), hfov_deg=40, width=960, height=540)
        >>> back = Camera.from_soccernet(cam.to_soccernet())  # through SoccerNet's angles and back
        >>> cam == back, cam.allclose(back, atol=1e-6)
        (False, True)
        """
        if not isinstance(other, Camera):
            raise ArgumentError(f"other: expected a Camera, got {type(other).__name__}")
        return all(np.allclose(a, b, rtol=rtol, atol=atol) for a, b in zip(self._values(), other._values()))

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_look_at(cls, position, target, *, hfov_deg: float, width: float, height: float,
                     roll_deg: float = 0.0, k1: float = 0.0) -> "Camera":
        """Square-pixel camera at ``position`` (metres) looking at ``target``, with centred
        principal point, horizontal field of view ``hfov_deg``, ``roll_deg`` about its axis and
        radial distortion ``k1``.

        >>> cam = Camera.from_look_at((0, 50, -20), (0, 0, 0), hfov_deg=40, width=960, height=540)
        >>> round(cam.hfov_deg, 6), cam.project([0.0, 0.0, 0.0]).round(6).tolist()
        (40.0, [480.0, 270.0])
        """
        f = (width / 2.0) / math.tan(math.radians(hfov_deg) / 2.0)
        radial = np.zeros(6)
        radial[0] = k1
        return cls(f, f, width / 2.0, height / 2.0, look_at_rotation(position, target, math.radians(roll_deg)),
                   np.asarray(position, float), width, height, radial)

    @classmethod
    def from_soccernet(cls, d: Mapping[str, Any], width: float | tuple[float, float] | None = None,
                       height: float | None = None, *,
                       image_size: tuple[float, float] | None = None) -> "Camera":
        """From a SoccerNet camera dict, made for an image of twice its principal point (as the
        official evaluator takes it). ``image_size`` (width, height), or ``width`` and ``height``:
        the size of the image it is used on; the camera is scaled to it when it differs (a camera
        written at 960x540 used on the 1920x1080 frame), and a size of another aspect is refused
        (a swapped (height, width), or a camera of another picture); ``from_soccernet(d, (w, h))``
        takes the size as one argument too. Every field is checked
        (:class:`pnlviz.ArgumentError` naming the key): the angles finite, the focal lengths and
        principal point finite and positive, the position finite and within
        :data:`MAX_CAMERA_DISTANCE_M` of the pitch's centre, the distortion terms (optional) of
        their lengths and finite.

        >>> d = Camera.from_look_at((0, 50, -20), (0, 0, 0), hfov_deg=40, width=960, height=540).to_soccernet()
        >>> bool(Camera.from_soccernet(d, image_size=(1920, 1080)).fx == 2 * Camera.from_soccernet(d).fx)
        True
        """
        if not isinstance(d, Mapping):
            raise ArgumentError(f"camera: expected a SoccerNet camera dict, got {type(d).__name__}")
        pp = _numbers(d, "principal_point", 2, positive=True)
        angles = [math.radians(_numbers(d, k, None)[0]) for k in ("pan_degrees", "tilt_degrees", "roll_degrees")]
        C = _numbers(d, "position_meters", 3)
        if np.max(np.abs(C)) > MAX_CAMERA_DISTANCE_M or float(np.linalg.norm(C)) > MAX_CAMERA_DISTANCE_M:
            raise ArgumentError(f"camera['position_meters']: [{', '.join(f'{v:.6g}' for v in C)}] is farther than "
                                f"{MAX_CAMERA_DISTANCE_M / 1000:g} km from the pitch")
        fx, fy = _numbers(d, "x_focal_length", None, positive=True)[0], _numbers(d, "y_focal_length", None, positive=True)[0]
        lens = [_numbers(d, k, n, optional=True) for k, n in (("radial_distortion", 6), ("tangential_distortion", 2),
                                                              ("thin_prism_distortion", 4))]
        cam = cls(fx, fy, pp[0], pp[1], rotation_from_pan_tilt_roll(*angles), C, 2 * pp[0], 2 * pp[1], *lens)
        size = _image_size_arg(width, height, image_size)
        if size is None or (abs(size[0] - cam.width) < 1e-6 and abs(size[1] - cam.height) < 1e-6):
            return cam
        made = cam.width / cam.height
        if abs(size[0] / size[1] - made) > 0.01 * made:
            raise ArgumentError(f"image_size: {size[0]:g}x{size[1]:g} is not the aspect of the image the camera was "
                                f"made for ({cam.width:g}x{cam.height:g}, twice its principal point): "
                                f"a swapped (height, width), or another picture's camera?")
        return cam.scaled(*size)

    def to_soccernet(self) -> dict:
        """SoccerNet camera dict (plus ``rotation_matrix``, as PnLCalib writes it), for an image
        of twice its principal point.

        >>> cam = Camera.from_look_at((0, 50, -20), (0, 0, 0), hfov_deg=40, width=960, height=540)
        >>> d = cam.to_soccernet()
        >>> d["position_meters"], d["principal_point"], round(d["tilt_degrees"], 2)
        ([0.0, 50.0, -20.0], [480.0, 270.0], 68.2)
        """
        pan, tilt, roll = pan_tilt_roll_from_rotation(self.R)
        return {
            "pan_degrees": math.degrees(pan),
            "tilt_degrees": math.degrees(tilt),
            "roll_degrees": math.degrees(roll),
            "position_meters": [float(v) for v in self.C],
            "x_focal_length": float(self.fx),
            "y_focal_length": float(self.fy),
            "principal_point": [float(self.cx), float(self.cy)],
            "radial_distortion": [float(v) for v in self.radial],
            "tangential_distortion": [float(v) for v in self.tangential],
            "thin_prism_distortion": [float(v) for v in self.thin_prism],
            "rotation_matrix": self.R.tolist(),
        }

    # ------------------------------------------------------------------ derived matrices
    @property
    def K(self) -> np.ndarray:
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def t(self) -> np.ndarray:
        """Translation of ``x_cam = R X + t``."""
        return -self.R @ self.C

    @property
    def P(self) -> np.ndarray:
        """3x4 projection matrix ``K R [I | -C]`` (no distortion)."""
        return self.K @ np.hstack([self.R, self.t[:, None]])

    def ground_homography(self) -> np.ndarray:
        """3x3 homography from ground-plane points (X, Y, 1) at z = 0 to pixels (no distortion)."""
        P = self.P
        return P[:, [0, 1, 3]]

    @property
    def hfov_deg(self) -> float:
        return math.degrees(2 * math.atan(self.width / (2 * self.fx)))

    @property
    def pan_tilt_roll_deg(self) -> tuple[float, float, float]:
        pan, tilt, roll = pan_tilt_roll_from_rotation(self.R)
        return math.degrees(pan), math.degrees(tilt), math.degrees(roll)

    @property
    def has_distortion(self) -> bool:
        return self._lens != "none"

    def scaled(self, width: float, height: float) -> "Camera":
        """The same camera for the image resized to ``width`` x ``height``.

        >>> cam = Camera.from_look_at((0, 50, -20), (0, 0, 0), hfov_deg=40, width=960, height=540)
        >>> cam.scaled(1920, 1080).project([0.0, 0.0, 0.0]).round(6).tolist()
        [960.0, 540.0]
        """
        sx, sy = width / self.width, height / self.height
        return replace(self, fx=self.fx * sx, fy=self.fy * sy, cx=self.cx * sx, cy=self.cy * sy,
                       width=float(width), height=float(height))

    def with_pose(self, R: np.ndarray, C: np.ndarray) -> "Camera":
        return replace(self, R=np.asarray(R, float), C=np.asarray(C, float))

    # ------------------------------------------------------------------ projection
    def to_camera(self, X: np.ndarray) -> np.ndarray:
        """World points (N, 3) -> camera coordinates (N, 3); another shape: ArgumentError."""
        return (as_points(X, 3, "X") - self.C) @ self.R.T

    def distort(self, xn: np.ndarray) -> np.ndarray:
        """Apply the lens model to normalised image points (N, 2); another shape: ArgumentError."""
        xn = as_points(xn, 2, "xn")
        if self._lens == "none":
            return xn
        x, y = xn[:, 0], xn[:, 1]
        r2 = x * x + y * y
        if self._lens == "k1":  # what the general model gives with the other terms zero, exactly
            return xn * (1 + r2 * self.radial[0])[:, None]
        k, p, s = self.radial, self.tangential, self.thin_prism
        num = 1 + r2 * (k[0] + r2 * (k[1] + r2 * k[2]))
        den = 1 + r2 * (k[3] + r2 * (k[4] + r2 * k[5]))
        f = num / den
        xd = x * f + 2 * p[0] * x * y + p[1] * (r2 + 2 * x * x) + s[0] * r2 + s[1] * r2 * r2
        yd = y * f + 2 * p[1] * x * y + p[0] * (r2 + 2 * y * y) + s[2] * r2 + s[3] * r2 * r2
        return np.stack([xd, yd], axis=1)

    def undistort(self, xd: np.ndarray, iterations: int = 20) -> np.ndarray:
        """Normalised distorted points (N, 2) -> undistorted normalised points, by Newton's method
        on :meth:`distort` (vectorised 2x2 solves; converges to ~1e-14 for broadcast lenses).
        Another shape: ArgumentError."""
        xd = as_points(xd, 2, "xd")
        if not self.has_distortion:
            return xd
        x = xd.copy()
        eps = 1e-7
        for _ in range(iterations):
            r = self.distort(x) - xd
            if np.nanmax(np.abs(r), initial=0.0) < 1e-14:
                break
            jx = (self.distort(x + [eps, 0]) - self.distort(x - [eps, 0])) / (2 * eps)
            jy = (self.distort(x + [0, eps]) - self.distort(x - [0, eps])) / (2 * eps)
            det = jx[:, 0] * jy[:, 1] - jy[:, 0] * jx[:, 1]
            with np.errstate(divide="ignore", invalid="ignore"):
                dx = (jy[:, 1] * r[:, 0] - jy[:, 0] * r[:, 1]) / det
                dy = (-jx[:, 1] * r[:, 0] + jx[:, 0] * r[:, 1]) / det
            x = x - np.stack([dx, dy], axis=1)
        return x

    def project(self, world: ArrayLike, *, distort: bool = True) -> np.ndarray:
        """Pixels (N, 2) of world points ``world`` (N, 3) (metres, SoccerNet's frame); one point
        (3,) gives one pixel (2,). A point behind the camera (depth <= :data:`MIN_DEPTH`) gets
        NaN. ``distort``: through the lens (False: the pinhole only). Any other shape is refused
        (ArgumentError naming ``world``); :meth:`project_with_depth` gives the depths too.

        >>> cam = Camera.from_look_at((0, 50, -20), (0, 0, 0), hfov_deg=40, width=960, height=540)
        >>> cam.project([0.0, 0.0, 0.0]).round(6).tolist()  # the point it looks at: the image centre
        [480.0, 270.0]
        """
        arr = np.asarray(world, float)
        if arr.shape == (3,):
            return self.project_with_depth(arr[None], distort=distort)[0][0]
        return self.project_with_depth(arr, distort=distort)[0]

    def project_with_depth(self, world: ArrayLike, *, distort: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """Pixels (N, 2) and depths (N,) (metres along the optical axis) of world points (N, 3);
        points at depth <= :data:`MIN_DEPTH` (behind or on the camera plane) get NaN pixels.

        >>> cam = Camera.from_look_at((0, 50, -20), (0, 0, 0), hfov_deg=40, width=960, height=540)
        >>> uv, depth = cam.project_with_depth([[0, 0, 0], [0, 100, 0]])  # the second is behind it
        >>> uv.round(3).tolist(), depth.round(3).tolist()
        ([[480.0, 270.0], [nan, nan]], [53.852, -38.996])
        """
        X = np.asarray(world, float)
        if X.ndim != 2 or X.shape[1] != 3:
            raise ArgumentError(f"world: expected points (N, 3) in metres, got an array of shape {X.shape}")
        Xc = self.to_camera(X)
        z = Xc[:, 2]
        ok = z > MIN_DEPTH
        with np.errstate(all="ignore"):  # the points behind are computed too, then set to NaN
            xn = Xc[:, :2] / z[:, None]
            if distort:
                xn = self.distort(xn)
            uv = xn * (self.fx, self.fy) + (self.cx, self.cy)
        uv[~ok] = np.nan
        return uv, z

    def pitch_to_image(self, xy: ArrayLike) -> np.ndarray:
        """Pixels (N, 2) of pitch positions ``xy`` (N, 2) in metres on the ground (z = 0): the
        inverse of :meth:`image_to_pitch`; one position (2,) gives one pixel (2,). NaN behind the
        camera; other shapes refused (ArgumentError naming ``xy``).

        >>> cam = Camera.from_look_at((0, 50, -20), (0, 0, 0), hfov_deg=40, width=960, height=540)
        >>> cam.pitch_to_image([[0, 0], [11, 0]]).round(1).tolist()  # the centre spot, 11 m to the right
        [[480.0, 270.0], [749.4, 270.0]]
        """
        arr = np.asarray(xy, float)
        if arr.shape == (2,):
            return self.pitch_to_image(arr[None])[0]
        if arr.ndim != 2 or arr.shape[1] != 2:
            raise ArgumentError(f"xy: expected pitch positions (N, 2) or one (2,), got an array of shape {arr.shape}")
        return self.project(np.column_stack([arr, np.zeros(len(arr))]))

    def pixel_rays(self, uv: ArrayLike) -> np.ndarray:
        """Unit world directions (N, 3) of the rays through pixels ``uv`` (N, 2), distortion removed
        (another shape: ArgumentError)."""
        uv = as_points(uv, 2, "uv", "pixels")
        xd = np.stack([(uv[:, 0] - self.cx) / self.fx, (uv[:, 1] - self.cy) / self.fy], axis=1)
        xn = self.undistort(xd)
        d = np.hstack([xn, np.ones((len(xn), 1))]) @ self.R  # R^T applied to row vectors
        return d / np.linalg.norm(d, axis=1, keepdims=True)

    def back_project_to_ground(self, uv: ArrayLike, z: float = 0.0) -> np.ndarray:
        """World points (N, 3) where the rays through ``uv`` meet the plane z = ``z``; NaN where the
        ray does not reach it in front of the camera."""
        d = self.pixel_rays(uv)
        with np.errstate(divide="ignore", invalid="ignore"):
            s = (z - self.C[2]) / d[:, 2]
        s = np.where(s > 0, s, np.nan)
        return self.C + s[:, None] * d

    def image_to_pitch(self, uv: ArrayLike) -> np.ndarray:
        """Where on the pitch (the ground plane z = 0, metres, SoccerNet's centre-origin frame) the
        pixels ``uv`` (N, 2) of this image are: (N, 2), lens distortion undone. NaN for a pixel
        whose ray does not meet the ground in front of the camera (above the horizon), meets it
        farther than :data:`MAX_PITCH_DISTANCE_M` from the pitch (a ray grazing the horizon: no
        pitch point), or where the lens model does not invert (far outside the image a distortion
        folds back, and a pixel there has no ray). The point a player stands on is the bottom
        middle of the player's box. One pixel (2,) gives one point (2,); any other shape than
        (N, 2) or (2,) is refused (ArgumentError naming ``uv``).

        >>> cam = Camera.from_look_at((0, 50, -20), (0, 0, 0), hfov_deg=40, width=960, height=540)
        >>> cam.image_to_pitch([[480, 270], [480, 0]]).round(3).tolist()  # image centre, top middle
        [[0.0, 0.0], [0.0, -60.812]]
        """
        arr = np.asarray(uv, float)
        if arr.shape == (2,):
            return self.image_to_pitch(arr[None])[0]
        if arr.ndim != 2 or arr.shape[1] != 2:
            raise ArgumentError(f"uv: expected pixels (N, 2) or one pixel (2,), got an array of shape {arr.shape}")
        out = self.back_project_to_ground(arr)[:, :2]
        with np.errstate(invalid="ignore"):
            far = np.hypot(np.maximum(np.abs(out[:, 0]) - 52.5, 0), np.maximum(np.abs(out[:, 1]) - 34.0, 0))
            out[~(far <= MAX_PITCH_DISTANCE_M)] = np.nan
        out[~self.lens_inverts(arr)] = np.nan
        return out

    def lens_inverts(self, uv: np.ndarray, samples: int = 33) -> np.ndarray:
        """(N,) whether the lens model maps a ray to each pixel of ``uv`` (N, 2) one way: the
        undistorted point distorts back to the pixel, and on the way from the image centre to it
        the distortion keeps moving outwards (beyond where it turns, the model folds back and the
        same pixel has a second, wrong ray). Another shape: ArgumentError."""
        uv = as_points(uv, 2, "uv", "pixels")
        if not self.has_distortion:
            return np.all(np.isfinite(uv), axis=1)
        xd = np.stack([(uv[:, 0] - self.cx) / self.fx, (uv[:, 1] - self.cy) / self.fy], axis=1)
        with np.errstate(all="ignore"):
            x = self.undistort(xd)
            ok = np.all(np.isfinite(x), axis=1) & (np.linalg.norm(self.distort(x) - xd, axis=1) < 1e-9 + 1e-9 *
                                                    np.linalg.norm(xd, axis=1))
            t = np.linspace(0.0, 1.0, samples)[:, None, None]
            path = self.distort((t * x[None]).reshape(-1, 2)).reshape(samples, -1, 2)
            outward = np.einsum("snk,nk->sn", np.diff(path, axis=0), x)  # along the ray's direction
            ok &= np.all(outward > 0, axis=0) | (np.linalg.norm(x, axis=1) == 0)
        return ok

    def homography(self) -> np.ndarray:
        """3x3 homography from the ground plane (X, Y, 1) in metres to pixels, without lens
        distortion (:meth:`image_to_pitch` undoes the lens too). Its inverse maps pixels to the
        pitch.

        >>> cam = Camera.from_look_at((0, 50, -20), (0, 0, 0), hfov_deg=40, width=960, height=540)
        >>> p = cam.homography() @ [0.0, 0.0, 1.0]  # the centre spot
        >>> (p[:2] / p[2]).round(6).tolist()
        [480.0, 270.0]
        """
        return self.ground_homography()

    def in_image(self, uv: ArrayLike) -> np.ndarray:
        """(N,) whether each pixel of ``uv`` (N, 2) is inside the image: 0 <= x < width and
        0 <= y < height (NaN is outside). Other shapes refused (ArgumentError naming ``uv``).

        >>> cam = Camera.from_look_at((0, 50, -20), (0, 0, 0), hfov_deg=40, width=960, height=540)
        >>> cam.in_image([[10, 10], [960, 0]]).tolist()
        [True, False]
        """
        uv = np.asarray(uv, float)
        if uv.ndim != 2 or uv.shape[1] != 2:
            raise ArgumentError(f"uv: expected pixels (N, 2), got an array of shape {uv.shape}")
        return (uv[:, 0] >= 0) & (uv[:, 0] < self.width) & (uv[:, 1] >= 0) & (uv[:, 1] < self.height)
