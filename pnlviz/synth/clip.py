"""Synthetic broadcast clips: pan-tilt-zoom shots with the exact camera of every frame.

A clip is a few shots separated by cuts. In a shot the camera stands still (one centre and one
lens, k1) and follows play: its aim point moves over the pitch with a smoothly varying velocity
(a smooth random walk: its acceleration drifts, up to about 10 m/s at 25 frames/s), it zooms in and out (log field of
view, another damped walk, 12-45 degrees) and keeps a small roll. The players run: each has a
velocity that turns slowly. The stadium and its look stay the same over the clip; a cut moves to
another main-camera position (the other side of the half-way line, higher or lower).

Frame ``t`` of clip ``seed`` depends only on ``(seed, t)`` through the clip's plan (drawn once from
``seed``) and its own noise stream, so any frame can be rendered alone (and in parallel).
Stems are ``clip<seed>-IMG_<t+1:04d>``: :func:`pnlviz.data.layout.clip_key` reads them back.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from pnlviz.conventions import EVAL_SIZE
from pnlviz.geometry.camera import Camera

from .cameras import HALF_LENGTH, HALF_WIDTH, K1_SIGMA, _main_position, camera_problem
from .scene import Scene, sample_scene

__all__ = ["ClipPlan", "Motion", "clip_frame", "clip_stem", "plan_clip"]


@dataclass
class ClipPlan:
    """The whole clip, drawn once: per frame the camera (at ``size``) and its shot; the scene."""

    seed: int
    size: tuple[int, int]
    cameras: list[Camera]
    shot_of: list[int]
    scene: Scene
    #: per frame, the players' feet (P, 2)
    feet: np.ndarray


def clip_stem(seed: int, t: int) -> str:
    return f"clip{seed}-IMG_{t + 1:04d}"


def _shot_lengths(rng: np.random.Generator, frames: int, cuts: int) -> list[int]:
    if cuts <= 0 or frames < 2 * (cuts + 1):
        return [frames]
    cut_at = np.sort(rng.choice(np.arange(10, frames - 10), size=cuts, replace=False)) if frames > 30 else \
        np.linspace(0, frames, cuts + 2)[1:-1].astype(int)
    bounds = [0, *[int(c) for c in cut_at], frames]
    return [b - a for a, b in zip(bounds[:-1], bounds[1:]) if b > a]


def _damped_walk(rng: np.random.Generator, n: int, step: float, damping: float = 0.97) -> np.ndarray:
    """A smooth 1-D path, as an operator's hand moves a camera head: the acceleration is itself a
    damped walk (a_t = 0.9 a_{t-1} + N(0, step / 10)), the velocity follows it with ``damping``
    (v_t = damping v_{t-1} + a_t), the position sums the velocity. ``step`` sets the typical speed
    change per frame."""
    a = np.zeros(n)
    v = np.zeros(n)
    for t in range(1, n):
        a[t] = 0.9 * a[t - 1] + rng.normal(0, step / 10)
        v[t] = damping * v[t - 1] + a[t]
    return np.cumsum(v)


@dataclass(frozen=True)
class Motion:
    """How a shot's camera moves: ``pan`` scales how fast its aim point wanders (1: a camera
    following play, 3: fast pans, 0.3: a slow, steady view), ``zoom`` how fast it zooms."""

    pan: float = 1.0
    zoom: float = 1.0


def _shot_cameras(rng: np.random.Generator, n: int, size: tuple[int, int], side: float,
                  motion: Motion = Motion()) -> list[Camera]:
    W, H = size
    for _ in range(200):
        C = _main_position(rng)
        C[1] = side * abs(C[1])
        k1 = float(rng.normal(0.0, K1_SIGMA))
        start = np.array([rng.uniform(-35, 35), rng.uniform(-20, 20)])
        path = start + np.column_stack([_damped_walk(rng, n, 0.05 * motion.pan),
                                        _damped_walk(rng, n, 0.03 * motion.pan)])
        path[:, 0] = np.clip(path[:, 0], -HALF_LENGTH + 5, HALF_LENGTH - 5)
        path[:, 1] = np.clip(path[:, 1], -HALF_WIDTH + 3, HALF_WIDTH - 3)
        log_fov = math.log(rng.uniform(18, 35)) + _damped_walk(rng, n, 0.003 * motion.zoom)
        hfov = np.clip(np.exp(log_fov), 12.0, 45.0)
        roll = rng.normal(0, 0.4) + _damped_walk(rng, n, 0.0005)
        cams = [Camera.from_look_at(C, np.array([path[t, 0], path[t, 1], 0.0]), hfov_deg=float(hfov[t]), width=W,
                                    height=H, roll_deg=float(roll[t]), k1=k1) for t in range(n)]
        if all(camera_problem(c) is None for c in cams[:: max(1, n // 12)] + [cams[-1]]):
            return cams
    raise RuntimeError("no usable shot in 200 draws")


def plan_clip(seed: int, frames: int, size: tuple[int, int] = EVAL_SIZE, cuts: int | None = None,
              motions: Sequence[Motion] | None = None) -> ClipPlan:
    """Draw clip ``seed``: ``frames`` frames in ``cuts`` + 1 shots (default: one cut per 60
    frames, at least one for clips of 40 frames or more); ``motions``: how each shot's camera
    moves (default: :class:`Motion` ()), the last one for the shots beyond the list."""
    rng = np.random.default_rng([int(seed), 1_000_003])
    if cuts is None:
        cuts = max(1 if frames >= 40 else 0, frames // 60)
    cameras: list[Camera] = []
    shot_of: list[int] = []
    side = 1.0
    for k, n in enumerate(_shot_lengths(rng, frames, cuts)):
        motion = (motions[min(k, len(motions) - 1)] if motions else Motion())
        cameras += _shot_cameras(rng, n, size, side if rng.random() < 0.8 else -side, motion)
        shot_of += [k] * n
    scene = sample_scene(cameras[0], rng)
    P = len(scene.players)
    feet = np.empty((frames, P, 2))
    pos = np.array([p.foot for p in scene.players], float)
    heading = rng.uniform(0, 2 * math.pi, P)
    speed = rng.uniform(0.05, 0.28, P)  # metres per frame (1-7 m/s at 25 frames/s)
    for t in range(frames):
        feet[t] = pos
        heading += rng.normal(0, 0.08, P)
        pos = pos + speed[:, None] * np.column_stack([np.cos(heading), np.sin(heading)])
        pos[:, 0] = np.clip(pos[:, 0], -HALF_LENGTH - 2, HALF_LENGTH + 2)
        pos[:, 1] = np.clip(pos[:, 1], -HALF_WIDTH - 2, HALF_WIDTH + 2)
    return ClipPlan(int(seed), (size[0], size[1]), cameras, shot_of, scene, feet)


def clip_frame(plan: ClipPlan, t: int) -> dict:
    """Frame ``t`` of ``plan``: ``{"stem", "image", "annotation", "camera", "shot", "jpeg_quality"}``
    like :func:`pnlviz.synth.writer.make_frame` (camera JSON at 960x540, with the shot)."""
    from .annotate import annotate, annotation_to_json
    from .render import render

    rng = np.random.default_rng([plan.seed, int(t), 7])
    cam = plan.cameras[t]
    players = [replace(p, foot=plan.feet[t, i], stride=float(0.3 * math.sin(0.5 * t + i)),
                       arm_swing=float(0.15 * math.sin(0.5 * t + i + 1.0))) for i, p in enumerate(plan.scene.players)]
    scene = replace(plan.scene, players=players)
    image = render(cam, rng, scene).image
    annotation = annotate(cam, rng)
    cam_json = cam.scaled(*EVAL_SIZE).to_soccernet()
    cam_json["synth"] = {"kind": "main", "clip": plan.seed, "shot": plan.shot_of[t],
                         "image_size": [int(plan.size[0]), int(plan.size[1])]}
    return {"stem": clip_stem(plan.seed, t), "image": image, "annotation": annotation_to_json(annotation),
            "camera": cam_json, "shot": plan.shot_of[t], "jpeg_quality": int(rng.integers(70, 96))}
