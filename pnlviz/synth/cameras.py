"""Broadcast-like random cameras for synthetic frames.

:func:`sample_camera` draws a camera kind first (70 % ``main``, 10 % each ``closeup``,
``behind_goal`` and ``reverse``) and whether the lens gets a small radial distortion (30 %), then
draws poses for that kind until one is usable (:func:`camera_problem` returns None). Rejection
keeps the kind, so the kind mix stays the nominal one whatever the rejection rate of each kind.

A camera is usable when, at the 960 x 540 evaluation scale:

* the official evaluator's ``get_polylines`` sees at least :data:`MIN_CLASSES` pitch classes;
* the view is not mostly sky: at least half of a coarse grid of pixel rays meets the ground
  within :data:`GROUND_REACH` metres of the camera;
* the lens distortion is invertible over everything that shapes the visible polylines. With
  ``k1 < 0`` the radial model ``r (1 + k1 r^2)`` folds back beyond ``r_m = 1 / sqrt(-3 k1)``;
  the evaluator would then draw far off-axis pitch points inside the frame, where no renderer
  (and no real lens) puts them, so such cameras are rejected.
"""

from __future__ import annotations

import numpy as np

from pnlviz.conventions import EVAL_SIZE
from pnlviz.field.model import load_field_model
from pnlviz.geometry.camera import MIN_DEPTH, Camera
from pnlviz.geometry.lens import fold_radius
from pnlviz.geometry.polylines import visible_pitch

KINDS: tuple[str, ...] = ("main", "closeup", "behind_goal", "reverse")
KIND_PROBABILITIES: tuple[float, ...] = (0.7, 0.1, 0.1, 0.1)
#: Share of frames whose lens gets a radial distortion k1 ~ N(0, K1_SIGMA).
DISTORTED_SHARE = 0.3
K1_SIGMA = 0.03
#: The SoccerNet evaluation scale; validity is judged there.
MIN_CLASSES = 4
#: A ray "sees the ground" when it meets z = 0 closer than this (metres).
GROUND_REACH = 200.0
MIN_GROUND_SHARE = 0.5

HALF_LENGTH, HALF_WIDTH = 52.5, 34.0


class CameraSamplingError(RuntimeError):
    """No usable camera was found within the allowed number of draws."""


def _main_position(rng: np.random.Generator) -> np.ndarray:
    return np.array([rng.uniform(-20, 20), rng.uniform(40, 70), -rng.uniform(8, 25)])


def _pitch_point(rng: np.random.Generator) -> np.ndarray:
    return np.array([rng.uniform(-HALF_LENGTH, HALF_LENGTH), rng.uniform(-HALF_WIDTH, HALF_WIDTH), 0.0])


def _propose(rng: np.random.Generator, kind: str, width: float, height: float, distorted: bool) -> Camera:
    """One draw of a camera of ``kind`` (not yet checked)."""
    roll = rng.normal(0.0, 0.5)
    if kind == "main":
        position, target = _main_position(rng), _pitch_point(rng)
        hfov = rng.uniform(10, 60)
    elif kind == "closeup":
        position = _main_position(rng)
        side = rng.choice((-1.0, 1.0))
        if rng.random() < 0.5:  # the goal mouth
            target = np.array([side * rng.uniform(47, 53), rng.uniform(-6, 6), -rng.uniform(0, 2)])
        else:  # somewhere on the penalty box
            target = np.array([side * rng.uniform(34, 52.5), rng.uniform(-21, 21), 0.0])
        hfov = rng.uniform(5, 12)
    elif kind == "behind_goal":
        side = rng.choice((-1.0, 1.0))
        position = np.array([side * rng.uniform(55, 70), rng.uniform(-15, 15), -rng.uniform(3, 15)])
        target = np.array([side * rng.uniform(-5, 45), rng.uniform(-25, 25), 0.0])
        hfov = rng.uniform(20, 60)
    elif kind == "reverse":
        position = np.array([rng.uniform(-20, 20), -rng.uniform(40, 70), -rng.uniform(8, 25)])
        target = _pitch_point(rng)
        hfov = rng.uniform(10, 60)
    else:
        raise ValueError(f"unknown camera kind {kind!r}; expected one of {KINDS}")
    k1 = rng.normal(0.0, K1_SIGMA) if distorted else 0.0
    return Camera.from_look_at(position, target, hfov_deg=hfov, width=width, height=height,
                               roll_deg=roll, k1=k1)


def _ray_grid(camera: Camera, nx: int = 32, ny: int = 18) -> np.ndarray:
    u = (np.arange(nx) + 0.5) * camera.width / nx
    v = (np.arange(ny) + 0.5) * camera.height / ny
    uu, vv = np.meshgrid(u, v)
    return camera.pixel_rays(np.stack([uu.ravel(), vv.ravel()], axis=1))


def ground_share(camera: Camera) -> float:
    """Share of a coarse grid of pixel rays that meet the ground within :data:`GROUND_REACH` m."""
    d = _ray_grid(camera)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = -camera.C[2] / d[:, 2]
    return float(np.mean((d[:, 2] > 0) & (s < GROUND_REACH)))


def distortion_folds(camera: Camera, width: float, height: float) -> bool:
    """True when a folded-back part of the radial model (k1 < 0) shapes what the evaluator sees:
    a pitch sample beyond the fold radius is inside the frame, or next to an inside sample."""
    k1 = float(camera.radial[0])
    if k1 >= 0 or np.any(camera.radial[1:]):
        return False
    r_fold = fold_radius(camera)
    for X in load_field_model().sample_polylines(0.9).values():
        Xc = camera.to_camera(X)
        front = Xc[:, 2] > MIN_DEPTH
        if not front.any():
            continue
        xn = Xc[front, :2] / Xc[front, 2:3]
        r = np.hypot(xn[:, 0], xn[:, 1])
        uv = camera.project(X[front])
        inside = (uv[:, 0] >= 0) & (uv[:, 0] < width) & (uv[:, 1] >= 0) & (uv[:, 1] < height)
        near = inside.copy()
        near[1:] |= inside[:-1]
        near[:-1] |= inside[1:]
        if np.any(near & (r >= 0.98 * r_fold)):
            return True
    return False


def camera_problem(camera: Camera) -> str | None:
    """Why ``camera`` is not a usable synthetic camera, or None when it is."""
    w, h = EVAL_SIZE
    cam = camera.scaled(w, h)
    if distortion_folds(cam, w, h):
        return "lens distortion folds back inside the view"
    n = len(visible_pitch(cam, w, h))
    if n < MIN_CLASSES:
        return f"sees {n} pitch classes (< {MIN_CLASSES})"
    share = ground_share(cam)
    if share < MIN_GROUND_SHARE:
        return f"mostly sky: only {share:.0%} of the view is ground"
    return None


def sample_camera(rng: np.random.Generator, width: float = 960, height: float = 540, *,
                  kind: str | None = None, max_draws: int = 2000) -> tuple[Camera, str]:
    """A random broadcast-like camera for a ``width`` x ``height`` image and its kind.

    ``kind`` forces one of :data:`KINDS` (default: drawn with :data:`KIND_PROBABILITIES`).
    Deterministic for the state of ``rng``.
    """
    if kind is None:
        kind = KINDS[int(rng.choice(len(KINDS), p=KIND_PROBABILITIES))]
    elif kind not in KINDS:
        raise ValueError(f"unknown camera kind {kind!r}; expected one of {KINDS}")
    distorted = bool(rng.random() < DISTORTED_SHARE)
    for _ in range(max_draws):
        camera = _propose(rng, kind, width, height, distorted)
        if camera_problem(camera) is None:
            return camera, kind
    raise CameraSamplingError(f"no usable {kind!r} camera in {max_draws} draws")


__all__ = ["KINDS", "KIND_PROBABILITIES", "EVAL_SIZE", "MIN_CLASSES", "CameraSamplingError",
           "sample_camera", "camera_problem", "ground_share", "distortion_folds"]
