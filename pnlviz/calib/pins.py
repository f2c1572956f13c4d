"""Pinned keypoints: the ones a hand placed or moved. The annotator is in charge, so a frame's
calibration treats them apart (see :mod:`pnlviz.calib.pipeline` and :mod:`pnlviz.calib.calibrate`):
they are in every hypothesis set, count as inliers of the vote up to a generous radius, weigh
more than the others in every refinement (with a bounded loss) and are never gated out. Where
the camera cannot agree with one, it is *flagged* with its residual, not dropped.

This module holds what is particular to them: the camera of four (or more) hand-placed ground
points alone (:func:`pin_camera`: a homography, its closed-form focal length, else a search over
the field of view with a planar pose at each, the principal point at the image centre), and the
named condition that fails when they cannot give one (:class:`PinCondition`). Pure.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum
from itertools import combinations

import cv2
import numpy as np

from pnlviz.calib.observations import Observations
from pnlviz.geometry.camera import Camera
from pnlviz.geometry.homography import camera_from_ground_homography

#: the hand-placed ground points a camera needs
MIN_PINS = 4
#: three points are collinear when their triangle's area is below this fraction of its longest side squared
COLLINEAR = 0.01
#: fields of view (degrees) tried when the homography's own focal length is out of range
SEARCH_STEPS = 48


class PinCondition(str, Enum):
    """Why hand-placed points cannot calibrate a frame by themselves (a stable code each)."""

    FEWER_THAN_FOUR = "fewer_than_four"  #: fewer than four hand-placed points on the ground plane
    COLLINEAR_ON_PITCH = "collinear_on_pitch"  #: three of the chosen ids lie on one pitch line
    COLLINEAR_IN_IMAGE = "collinear_in_image"  #: three of the points were placed on one image line
    HORIZON = "across_horizon"  #: the points are on both sides of the horizon their homography puts
    MIRRORED = "mirrored"  #: their order in the image is the pitch's mirror image (ids swapped left/right?)
    FOCAL_OUT_OF_RANGE = "focal_out_of_range"  #: no field of view in range fits them


@dataclass(frozen=True)
class PinFailure:
    """A named condition that fails, and the sentence that says so."""

    condition: PinCondition
    message: str


def _ids(ids) -> str:
    return ", ".join(str(int(i)) for i in ids)


def _collinear(pts: np.ndarray) -> tuple[int, int, int] | None:
    """The first three points (indices) of ``pts`` (N, 2) on one line, or None."""
    for a, b, c in combinations(range(len(pts)), 3):
        u, v = pts[b] - pts[a], pts[c] - pts[a]
        side = max(np.hypot(*u), np.hypot(*v), np.hypot(*(pts[c] - pts[b])))
        if side == 0 or abs(u[0] * v[1] - u[1] * v[0]) / 2 < COLLINEAR * side * side:
            return a, b, c
    return None


def ground_pins(obs: Observations) -> tuple[np.ndarray, np.ndarray]:
    """Masks (N,): the pinned keypoints on the ground plane, and those off it."""
    pins = obs.pins
    return pins & obs.ground, pins & ~obs.ground


def check_pins(obs: Observations) -> tuple[PinFailure | None, np.ndarray | None]:
    """The first named condition the frame's hand-placed ground points fail before any camera
    is tried, or their field-to-image homography (None, H; H with the points in front: third
    coordinate positive)."""
    ground, off = ground_pins(obs)
    ids = obs.kp_ids
    if ground.sum() < MIN_PINS:
        extra = f"; {_ids(ids[off])} not on the ground plane" if off.any() else ""
        return PinFailure(PinCondition.FEWER_THAN_FOUR,
                          f"fewer than {MIN_PINS} hand-placed ground points ({int(ground.sum())}"
                          f"{': ' + _ids(ids[ground]) if ground.any() else ''}{extra})"), None
    world, xy = obs.kp_xyz[ground, :2], obs.kp_xy[ground]
    line = _collinear(world)
    if line is not None:
        return PinFailure(PinCondition.COLLINEAR_ON_PITCH,
                          f"hand-placed points {_ids(ids[ground][list(line)])} lie on one line of the pitch"), None
    line = _collinear(xy)
    if line is not None:
        return PinFailure(PinCondition.COLLINEAR_IN_IMAGE,
                          f"hand-placed points {_ids(ids[ground][list(line)])} lie on one line in the image"), None
    H, _ = cv2.findHomography(world, xy, 0)
    if H is None or not np.all(np.isfinite(H)):
        return PinFailure(PinCondition.COLLINEAR_IN_IMAGE, "the hand-placed points give no homography"), None
    w = (np.c_[world, np.ones(len(world))] @ H.T)[:, 2]
    if not (np.all(w > 0) or np.all(w < 0)):
        return PinFailure(PinCondition.HORIZON,
                          "the hand-placed points lie on both sides of the horizon they imply"), None
    H = H * np.sign(w[0])
    if np.linalg.det(H) < 0:
        return PinFailure(PinCondition.MIRRORED, f"hand-placed points {_ids(ids[ground])} are in the mirror order of "
                          "the pitch (no camera above it sees them so: left and right swapped?)"), None
    return None, H


def _planar_pose(world: np.ndarray, xy: np.ndarray, f: float, width: int, height: int) -> Camera | None:
    """The pose (planar PnP, IPPE) of a camera with focal ``f`` and the principal point at the
    centre that sees the ground points ``world`` (N, 2) at ``xy``; None when it is under the pitch."""
    K = np.array([[f, 0, width / 2], [0, f, height / 2], [0, 0, 1]])
    obj = np.c_[world, np.zeros(len(world))].astype(np.float64)
    ok, rvec, tvec = cv2.solvePnP(obj, xy.astype(np.float64), K, None, flags=cv2.SOLVEPNP_IPPE)
    if not ok:
        return None
    R = cv2.Rodrigues(rvec)[0]
    C = -R.T @ tvec.ravel()
    if not C[2] < 0:
        return None
    return Camera(f, f, width / 2, height / 2, R, C, float(width), float(height))


def pin_camera(obs: Observations, min_hfov: float, max_hfov: float, fit_px: float) -> Camera | PinFailure:
    """The camera of the frame's hand-placed ground points alone (four or more), or the named
    condition that fails. The homography's closed-form focal length when it is in
    ``[min_hfov, max_hfov]`` (degrees), else the field of view in that range whose planar pose
    fits the points best; a camera that puts them farther than ``fit_px`` (RMS) fails as
    ``FOCAL_OUT_OF_RANGE``. Not refined: the pipeline refines it with everything else."""
    failure, H = check_pins(obs)
    if failure is not None:
        return failure
    assert H is not None  # check_pins gives a homography whenever no condition fails
    ground, _ = ground_pins(obs)
    world, xy = obs.kp_xyz[ground, :2], obs.kp_xy[ground]
    W, Hh = obs.width, obs.height

    def rms(cam: Camera) -> float:
        uv, z = cam.project_with_depth(obs.kp_xyz[ground])
        return float(np.sqrt(np.mean(np.sum((uv - xy) ** 2, axis=1)))) if np.all(z > 0) else np.inf

    cam = camera_from_ground_homography(H, W, Hh)
    tried = []
    if cam is not None and min_hfov <= cam.hfov_deg <= max_hfov:
        tried.append((rms(cam), cam))
    for hfov in np.geomspace(max(min_hfov, 1e-3), max_hfov, SEARCH_STEPS):
        c = _planar_pose(world, xy, (W / 2) / np.tan(np.radians(hfov) / 2), W, Hh)
        if c is not None:
            tried.append((rms(c), c))
    best_rms, best_cam = min(tried, key=lambda t: t[0], default=(np.inf, None))
    if best_cam is None or not best_rms <= fit_px:
        found = best_cam is not None and np.isfinite(best_rms)
        got = f" (best {best_rms:.0f} px at {best_cam.hfov_deg:.0f} deg)" if best_cam is not None and found else ""
        return PinFailure(PinCondition.FOCAL_OUT_OF_RANGE,
                          f"focal length out of range: no field of view of {min_hfov:g}-{max_hfov:g} deg puts "
                          f"hand-placed points {_ids(obs.kp_ids[ground])} within {fit_px:.0f} px{got}")
    return best_cam


def flagged_pins(obs: Observations, residuals: dict[int, float], limit_px: float) -> dict[int, float]:
    """The pinned keypoints farther than ``limit_px`` from the camera: id -> residual (px)."""
    return {int(i): float(residuals.get(int(i), np.inf)) for i in obs.kp_ids[obs.pins]
            if not residuals.get(int(i), np.inf) <= limit_px}


def slips(obs: Observations, fit, limit_px: float, kids=None) -> dict[int, float]:
    """The hand-placed keypoints (``kids``: these only; default all the pinned ones) farther than
    ``limit_px`` from the camera the *other* observations give: id -> that distance (px). A slip of
    the hand pulls a camera fitted with it towards itself (a pin weighs more than a detection),
    so its residual under that camera hides it; without it, the rest of the frame says where the
    point belongs. ``fit(observations) -> Camera | None``: the frame's calibration. A point whose
    frame gives no camera without it is not judged."""
    out: dict[int, float] = {}
    wanted = None if kids is None else {int(k) for k in kids}
    for i in np.flatnonzero(obs.pins):
        kid = int(obs.kp_ids[i])
        if wanted is not None and kid not in wanted:
            continue
        keep = np.ones(obs.n_keypoints, bool)
        keep[i] = False
        cam = fit(obs.subset(keep))
        if cam is None:
            continue
        uv = cam.project(obs.kp_xyz[i])
        d = float(np.hypot(*(uv - obs.kp_xy[i])))
        if not d <= limit_px:  # NaN (behind the camera) is a slip too
            out[kid] = round(d, 2) if np.isfinite(d) else float("inf")
    return out
