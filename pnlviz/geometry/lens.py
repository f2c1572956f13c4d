"""Where a camera's lens model stops being a lens: its fold radius, and which world points it images.

SoccerNet's radial model moves a normalised point at radius ``r`` to ``r f(r^2)``. A real lens
moves points outwards the farther they are from the axis; the polynomial does so only up to the
radius where ``r f(r^2)`` stops growing (for ``k1 < 0`` alone: ``1 / sqrt(-3 k1)``). Beyond it the
model folds back, and a point far outside the view (beside the camera, or under it) is drawn
inside the image, as if it were seen: a pitch line through the stands, a keypoint where there is
none. A calibrated ``k1`` of -0.005 folds at a normalised radius of 8 (83 degrees off the axis),
which the touchline under a broadcast camera reaches.

:func:`imaged` says which world points the lens images where the model puts them; the drawing
code skips the others. The SoccerNet evaluator keeps them (it draws the fold too), so metric code
does not use this. The pixel side of the same question is :meth:`Camera.lens_inverts`.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from pnlviz.geometry.camera import MIN_DEPTH, Camera
from pnlviz.geometry.shapes import as_points

#: the radii scanned for a fold when the lens has more than ``k1`` (normalised, log-spaced: 0.4 %
#: apart, up to 89.99 degrees off the axis)
_SCAN = np.geomspace(1e-3, 1e4, 4001)


def fold_radius(camera: Camera) -> float:
    """The normalised (undistorted) radius where the radial model ``r f(r^2)`` stops growing;
    ``inf`` when it grows everywhere (no distortion, ``k1 >= 0`` alone, ...). With ``k1`` alone
    exactly ``1 / sqrt(-3 k1)``; otherwise the first scanned radius where it stops growing (to
    0.4 %). The tangential and thin-prism terms are left out: on a broadcast lens they move a point
    by a fraction of a pixel, where the radial terms move it by tens.

    >>> cam = Camera.from_look_at((0, 50, -20), (0, 0, 0), hfov_deg=40, width=960, height=540, k1=-0.0052)
    >>> round(fold_radius(cam), 3)
    8.006
    """
    k = camera.radial
    if not k.any():
        return math.inf
    if not k[1:].any():
        return 1.0 / math.sqrt(-3.0 * k[0]) if k[0] < 0 else math.inf
    s = _SCAN * _SCAN
    with np.errstate(all="ignore"):
        g = _SCAN * (1 + s * (k[0] + s * (k[1] + s * k[2]))) / (1 + s * (k[3] + s * (k[4] + s * k[5])))
    stops = np.flatnonzero(~(np.diff(g) > 0))  # NaN (a pole) stops it too
    return float(_SCAN[stops[0]]) if len(stops) else math.inf


def imaged(camera: Camera, world: ArrayLike) -> np.ndarray:
    """(N,) whether ``camera`` images each world point (N, 3) where its model puts it: in front
    of it (depth > :data:`MIN_DEPTH`) and inside the lens's :func:`fold_radius`. Another shape:
    ArgumentError.

    >>> cam = Camera.from_look_at((0, 50, -20), (0, 0, 0), hfov_deg=40, width=960, height=540, k1=-0.0052)
    >>> imaged(cam, [[0, 0, 0], [0, 100, 0], [60, 52, 0]]).tolist()  # ahead, behind, beside it
    [True, False, False]
    """
    return imaged_in_camera(camera, camera.to_camera(as_points(world, 3, "world")))


def imaged_in_camera(camera: Camera, Xc: np.ndarray) -> np.ndarray:
    """:func:`imaged` of points already in ``camera``'s frame (N, 3), for callers that have them."""
    z = Xc[:, 2]
    front = z > MIN_DEPTH
    limit = fold_radius(camera)
    if math.isinf(limit):
        return front
    with np.errstate(all="ignore"):
        r = np.hypot(Xc[:, 0], Xc[:, 1]) / z
    return front & (r < limit)


def folds_into_view(camera: Camera, points: ArrayLike) -> bool:
    """Whether ``camera``'s lens model puts any of the world ``points`` (N, 3) that it does not
    image (:func:`imaged`: beyond its fold, in front of it) inside its own image: a lens that draws
    the pitch where it is not. False at once when the lens cannot fold (:func:`fold_radius` inf)."""
    if math.isinf(fold_radius(camera)):
        return False
    X = as_points(points, 3, "points")
    Xc = camera.to_camera(X)
    folded = (Xc[:, 2] > MIN_DEPTH) & ~imaged_in_camera(camera, Xc)
    if not folded.any():
        return False
    return bool(np.any(camera.in_image(camera.project(X[folded]))))  # only those beyond the fold projected
