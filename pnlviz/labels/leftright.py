"""Left-right disambiguation of annotations (paper Sec. III-A, "Left-Right Disambiguation").

When the camera looks along the long axis of the pitch (behind a goal, or a high end camera),
nothing in the image says which half it is: annotators may call the near goal area "left" or
"right". The SoccerNet evaluator accepts both (it keeps the better of a frame and its mirror),
so for *training* targets PnLCalib remaps the annotation so that the goal area closest to the
camera is always the left one, and leaves the choice to after inference.

The paper decides from the angles of the field lines, with a threshold set from their
distribution and by visual inspection. We measure the one angle that matters directly: the
**azimuth of the viewing direction on the pitch** implied by the annotated lines, i.e. which way
"up the image" points on the ground, through the ground homography of the keypoints (see
:func:`viewing_azimuth_deg`; it only uses the local affine part of the homography, so zoomed,
nearly affine views are measured as well as wide ones).

* ``azimuth`` = angle between that direction and +x: 0 = looking towards +x, 180 = towards -x,
  90 = across the pitch, the main camera's usual view.
* The view is **longitudinal** when the azimuth is within :data:`LONGITUDINAL_MAX_DEG` = 35
  degrees of the long axis (either way). Threshold from the distributions: on the 381 SN22 test
  frames with a homography (main camera) the azimuth spans 46..140 degrees for 99 % of frames
  (min 21); cameras behind a goal aiming at the pitch are within ~35 degrees of the axis.
* A longitudinal view looking towards -x comes from behind (or above) the right goal: it is
  **mirrored** (the evaluator's central symmetry :data:`pnlviz.field.MIRROR`), after which the
  goal area nearest to the camera is the left one and the camera looks towards +x.

Without a homography (fewer than 4 well spread ground keypoints) the view is left as annotated.
Limit: a side camera panned to a very oblique view of a corner (within 35 degrees of the axis)
counts as longitudinal too.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pnlviz.field.names import FLIP_X, MIRROR, canonical_class_name

#: A view is longitudinal when its ground viewing direction is within this angle of the long axis.
LONGITUDINAL_MAX_DEG = 35.0


@dataclass(frozen=True)
class LRDecision:
    mirror: bool
    longitudinal: bool
    #: angle between the ground viewing direction and +x, degrees in [0, 180]; None without homography
    azimuth_deg: float | None
    reason: str


def mirror_annotation(annotation: dict) -> dict:
    """The annotation with every class renamed by the evaluator's mirror table (points kept)."""
    out = {}
    for name, pts in annotation.items():
        canon = canonical_class_name(name) or name
        out[MIRROR.get(canon, canon)] = pts
    return out


def flip_annotation(annotation: dict) -> dict:
    """The annotation of the horizontally flipped image: normalised x -> 1 - x (pixel x ->
    W - 1 - x, the evaluator's x * (W - 1) scaling) and every class renamed by
    :data:`pnlviz.field.FLIP_X` (the pitch reflected in its halfway line). Points are arrays
    (N, 2) or lists of ``{"x", "y"}`` dicts, as given."""
    out = {}
    for name, pts in annotation.items():
        canon = canonical_class_name(name) or name
        flipped: np.ndarray | list[dict]
        if isinstance(pts, np.ndarray):
            flipped = np.array(pts, dtype=float, copy=True)
            flipped[:, 0] = 1.0 - flipped[:, 0]
        else:
            flipped = [{**p, "x": 1.0 - float(p["x"])} for p in pts]
        out[FLIP_X.get(canon, canon)] = flipped
    return out


def viewing_azimuth_deg(homography: np.ndarray, at: np.ndarray, step: float = 10.0) -> float | None:
    """Angle (degrees, 0..180) between +x and the direction on the pitch that points "up the
    image" at pixel ``at``: the ground points of ``at`` and of ``at - (0, step)`` through
    ``homography^-1``. For an upright camera (no roll) and ``at`` on the image's centre column
    this is exactly the ground projection of the optical axis; elsewhere it is the direction from
    the camera's foot to the ground point seen at ``at``. Unlike the perspective row of ``H``,
    it only needs the local (affine) part of the homography, which even a zoomed, nearly affine
    view determines well."""
    Hinv = np.linalg.inv(np.asarray(homography, float))
    pts = np.array([[at[0], at[1], 1.0], [at[0], at[1] - step, 1.0]]) @ Hinv.T
    if np.any(pts[:, 2] * np.sign(pts[0, 2]) <= 0):
        return None
    g = pts[:, :2] / pts[:, 2:3]
    d = g[1] - g[0]
    if not np.all(np.isfinite(d)) or np.linalg.norm(d) < 1e-12:
        return None
    return math.degrees(math.atan2(abs(d[1]), d[0]))


def lr_decision(homography: np.ndarray | None, at: np.ndarray | None = None, *,
                max_deg: float = LONGITUDINAL_MAX_DEG) -> LRDecision:
    """Whether to mirror the annotation a homography was fitted to (see the module docstring);
    ``at``: a pixel on the visible ground (the centroid of the keypoints)."""
    if homography is None or at is None:
        return LRDecision(False, False, None, "no homography: kept as annotated")
    az = viewing_azimuth_deg(homography, at)
    if az is None:
        return LRDecision(False, False, None, "degenerate homography: kept as annotated")
    if az <= max_deg:
        return LRDecision(False, True, az, f"looks along the long axis towards +x (azimuth {az:.0f} deg)")
    if az >= 180.0 - max_deg:
        return LRDecision(True, True, az, f"looks along the long axis towards -x (azimuth {az:.0f} deg): mirrored")
    return LRDecision(False, False, az, f"looks across the pitch (azimuth {az:.0f} deg)")
