"""The sprites of a synthetic frame, drawn over the background in depth order, farthest first,
each tested against the depth of boards and stands: goal nets (faint meshes on the faces of a
2 m deep box), posts and crossbars (white 12 cm cylinders, coverage from the distance between
each pixel ray and the bar axis) and players (upright billboards facing the camera with a body
made of capsules).
"""

from __future__ import annotations

from collections.abc import Callable
from functools import partial

import numpy as np

from pnlviz.field.model import load_field_model
from pnlviz.geometry.camera import Camera

from .ground import shade_at
from .raycast import F32, box_coverage, pixel_windows
from .scene import HALF_LENGTH, Scene

POST_RADIUS = 0.06
GOAL_HALF_WIDTH = load_field_model().dimensions["goal_width"] / 2
GOAL_HEIGHT = load_field_model().dimensions["goal_height"]


class Canvas:
    """The image being composed plus what sprites need per pixel."""

    def __init__(self, camera: Camera, d: tuple, image: np.ndarray, t_bg: np.ndarray):
        self.camera = camera
        self.d = d
        self.image = image
        self.t_bg = t_bg
        self.occ = np.zeros(t_bg.shape, F32)
        self.C = camera.C.astype(F32)
        self.f = F32(max(camera.fx, camera.fy))

    def blend(self, win, alpha: np.ndarray, colour: np.ndarray) -> None:
        a = alpha[:, :, None]
        img = self.image[win]
        img += (colour - img) * a
        np.maximum(self.occ[win], alpha, out=self.occ[win])


def draw_bar(cv: Canvas, P0: np.ndarray, P1: np.ndarray, radius: float, colour: np.ndarray, light: float) -> None:
    """A cylinder of ``radius`` around the segment P0-P1, with perspective thickness."""
    pts = P0[None, :] + np.linspace(0, 1, 8)[:, None] * (P1 - P0)[None, :]
    (win,) = pixel_windows(cv.camera, pts[None], radius, 2.0)
    if win is None:
        return
    dx, dy, dz = (a[win] for a in cv.d)
    L = float(np.linalg.norm(P1 - P0))
    u = ((P1 - P0) / L).astype(F32)
    w0 = (cv.C - P0.astype(F32))
    a = dx * dx + dy * dy + dz * dz
    b = dx * u[0] + dy * u[1] + dz * u[2]
    dd = dx * w0[0] + dy * w0[1] + dz * w0[2]
    e = F32(u @ w0)
    den = np.maximum(a - b * b, F32(1e-12))
    s = np.clip((a * e - b * dd) / den, 0, L)
    t = (s * b - dd) / a
    qx = cv.C[0] + t * dx - (P0[0] + s * u[0])
    qy = cv.C[1] + t * dy - (P0[1] + s * u[1])
    qz = cv.C[2] + t * dz - (P0[2] + s * u[2])
    dist = np.sqrt(qx * qx + qy * qy + qz * qz)
    fp = np.maximum(t, F32(1e-3)) / cv.f
    alpha = box_coverage(dist, radius, fp) * ((t > 0) & (t < cv.t_bg[win]))
    if not alpha.any():
        return
    shade = (F32(1.0) - F32(0.35) * np.clip(dist / F32(radius), 0, 1) ** 2) * F32(light)
    cv.blend(win, alpha.astype(F32), colour[None, None, :] * shade[:, :, None])


def _covers_a_corner(cv: "Canvas", axis: int, value: float, ka: int, ra: tuple, kb: int, rb: tuple) -> bool:
    """Whether the ray of an image corner meets the axis-aligned rectangle (then the rectangle
    may cover the whole view and its edges alone do not bound it)."""
    for v, u in ((0, 0), (0, -1), (-1, 0), (-1, -1)):
        d = [float(c[v, u]) for c in cv.d]
        if d[axis] == 0:
            continue
        t = (value - cv.camera.C[axis]) / d[axis]
        pa, pb = cv.camera.C[ka] + t * d[ka], cv.camera.C[kb] + t * d[kb]
        if t > 0 and ra[0] <= pa <= ra[1] and rb[0] <= pb <= rb[1]:
            return True
    return False


def draw_net(cv: Canvas, axis: int, value: float, ranges: dict, colour: np.ndarray, opacity: float,
              light: float, spacing: float = 0.14, thread: float = 0.025) -> None:
    """A faint square mesh on the rectangle ``{axis: value} x ranges`` (axis-aligned plane)."""
    (ka, (lo_a, hi_a)), (kb, (lo_b, hi_b)) = sorted(ranges.items())
    corners = np.zeros((4, 3))
    corners[:, axis] = value
    corners[:, ka] = [lo_a, hi_a, lo_a, hi_a]
    corners[:, kb] = [lo_b, lo_b, hi_b, hi_b]
    corners = corners[[0, 1, 3, 2]]
    (win,) = pixel_windows(cv.camera, corners[None], 0.0, 2.0, closed=True)
    if _covers_a_corner(cv, axis, value, ka, (lo_a, hi_a), kb, (lo_b, hi_b)):
        win = (slice(None), slice(None))
    if win is None:
        return
    d = [a[win] for a in cv.d]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (F32(value) - cv.C[axis]) / d[axis]
    pa = cv.C[ka] + t * d[ka]
    pb = cv.C[kb] + t * d[kb]
    inside = (t > 0) & (pa >= lo_a) & (pa <= hi_a) & (pb >= lo_b) & (pb <= hi_b) & (t < cv.t_bg[win])
    if not inside.any():
        return
    norm = np.sqrt(d[0] ** 2 + d[1] ** 2 + d[2] ** 2)
    cos = np.maximum(np.abs(d[axis]) / norm, F32(0.15))
    fp = np.maximum(t, F32(1e-3)) / cv.f / cos

    def mesh(q):
        dist = np.abs(np.mod(q, F32(spacing)) - F32(0.5 * spacing))
        dist = F32(0.5 * spacing) - dist  # distance to the nearest thread
        exact = box_coverage(dist, 0.5 * thread, fp)
        return np.where(fp < spacing, exact, F32(thread / spacing))

    ca, cb = mesh(pa), mesh(pb)
    alpha = (F32(opacity) * (ca + cb - ca * cb) * inside).astype(F32)
    cv.blend(win, alpha, colour[None, None, :] * F32(light))


def _body_parts(height: float, stride: float, swing: float):
    """Capsules (a0, b0, a1, b1, radius, part) in billboard metres; part 0 shirt, 1 shorts,
    2 socks, 3 skin, 4 hair, 5 shoes."""
    k = height / 1.8
    parts = [
        (-0.09 * k + stride, 0.05 * k, -0.09 * k, 0.82 * k, 0.07 * k, 2),  # legs (socks / skin by height)
        (0.09 * k - stride, 0.05 * k, 0.09 * k, 0.82 * k, 0.07 * k, 2),
        (-0.09 * k + stride - 0.05, 0.04 * k, -0.09 * k + stride + 0.08, 0.04 * k, 0.045 * k, 5),  # shoes
        (0.09 * k - stride - 0.05, 0.04 * k, 0.09 * k - stride + 0.08, 0.04 * k, 0.045 * k, 5),
        (0.0, 0.86 * k, 0.0, 0.92 * k, 0.17 * k, 1),  # shorts
        (0.0, 1.08 * k, 0.0, 1.34 * k, 0.185 * k, 0),  # torso
        (-0.22 * k, 1.38 * k, -0.27 * k - swing, 0.92 * k, 0.05 * k, 0),  # arms
        (0.22 * k, 1.38 * k, 0.27 * k + swing, 0.92 * k, 0.05 * k, 0),
        (0.0, 1.44 * k, 0.0, 1.52 * k, 0.05 * k, 3),  # neck
        (0.0, 1.64 * k, 0.0, 1.66 * k, 0.105 * k, 3),  # head
    ]
    return parts


def draw_player(cv: Canvas, player, shade: float, light_side: float) -> None:
    F = np.array([player.foot[0], player.foot[1], 0.0])
    to_cam = cv.camera.C[:2] - F[:2]
    dist = float(np.linalg.norm(to_cam))
    if dist < 1.0:
        return
    n = to_cam / dist
    ea = np.array([-n[1], n[0], 0.0])
    hgt = player.height
    corners = np.array([F + ea * s - np.array([0, 0, b]) for s, b in ((-0.6, 0.0), (0.6, 0.0), (0.6, hgt + 0.05), (-0.6, hgt + 0.05))])
    (win,) = pixel_windows(cv.camera, corners[None], 0.0, 2.0, closed=True)
    if win is None:
        return
    dx, dy, dz = (a[win] for a in cv.d)
    nx, ny = F32(n[0]), F32(n[1])
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((F32(F[0]) - cv.C[0]) * nx + (F32(F[1]) - cv.C[1]) * ny) / (dx * nx + dy * ny)
    px = cv.C[0] + t * dx - F32(F[0])
    py = cv.C[1] + t * dy - F32(F[1])
    a = px * F32(ea[0]) + py * F32(ea[1])
    b = -(cv.C[2] + t * dz)
    fp = np.maximum(t, F32(1e-3)) / cv.f
    best = np.full(a.shape, np.inf, F32)
    part = np.zeros(a.shape, np.int8)
    for a0, b0, a1, b1, r, kind in _body_parts(hgt, player.stride, player.arm_swing):
        va, vb = F32(a1 - a0), F32(b1 - b0)
        wa, wb = a - F32(a0), b - F32(b0)
        h = np.clip((wa * va + wb * vb) / F32(va * va + vb * vb + 1e-9), 0, 1)
        sd = np.hypot(wa - h * va, wb - h * vb) - F32(r)
        closer = sd < best
        best = np.where(closer, sd, best)
        part = np.where(closer, np.int8(kind), part)
    k = hgt / 1.8
    # Colours by part, refined by height: bare knees and thighs, sleeves, hair on top of the head.
    kit = player.kit
    lut = np.stack([kit.shirt, kit.shorts, kit.socks, player.skin, player.hair, np.full(3, 0.06, F32)]).astype(F32)
    part = np.where((part == 2) & (b > F32(0.5 * k)), np.int8(3), part)
    part = np.where((part == 0) & (b < F32(1.16 * k)) & (np.abs(a) > F32(0.2 * k)), np.int8(3), part)
    part = np.where((part == 3) & (b > F32(1.68 * k)), np.int8(4), part)
    colour = lut[part]
    side = np.clip(a / F32(0.25 * k), -1, 1) * F32(light_side)
    colour = colour * (F32(shade) * (F32(1.0) + F32(0.22) * side))[:, :, None]
    alpha = np.clip(F32(0.5) - best / fp, 0, 1) * ((t > 0) & (t < cv.t_bg[win]))
    if alpha.any():
        cv.blend(win, alpha.astype(F32), colour.astype(F32))


def goal_sprites(scene: Scene, camera: Camera) -> list[tuple[float, Callable[[Canvas], None]]]:
    """The parts of both goals (nets, posts, crossbars, the back frame) as (distance from the
    camera, draw(canvas)), for depth sorting."""
    out = []
    net, op = scene.net_colour, scene.net_opacity
    white = np.array([0.97, 0.97, 0.97], F32)
    grey = np.array([0.7, 0.7, 0.72], F32)
    r = POST_RADIUS

    def mesh(axis, value, ranges):
        return partial(draw_net, axis=axis, value=value, ranges=ranges, colour=net, opacity=op, light=0.95)

    def bar(a, b, radius, colour):
        return partial(draw_bar, P0=np.array(a), P1=np.array(b), radius=radius, colour=colour, light=1.0)

    for sign in (-1.0, 1.0):
        gx = sign * HALF_LENGTH
        bx = gx + sign * 2.0
        gw, gh = GOAL_HALF_WIDTH, GOAL_HEIGHT
        xs = (min(gx, bx), max(gx, bx))
        out += [
            ((bx, 0.0, -gh / 2), mesh(0, bx, {1: (-gw, gw), 2: (-gh, 0.0)})),
            ((gx + sign, 0.0, -gh), mesh(2, -gh, {0: xs, 1: (-gw, gw)})),
            ((gx + sign, -gw, -gh / 2), mesh(1, -gw, {0: xs, 2: (-gh, 0.0)})),
            ((gx + sign, gw, -gh / 2), mesh(1, gw, {0: xs, 2: (-gh, 0.0)})),
            ((bx, -gw, -gh / 2), bar([bx, -gw, 0.0], [bx, -gw, -gh], 0.035, grey)),
            ((bx, gw, -gh / 2), bar([bx, gw, 0.0], [bx, gw, -gh], 0.035, grey)),
            ((gx + sign, -gw, -gh), bar([gx, -gw, -gh], [bx, -gw, -gh], 0.03, grey)),
            ((gx + sign, gw, -gh), bar([gx, gw, -gh], [bx, gw, -gh], 0.03, grey)),
            ((gx, -gw, -gh / 2), bar([gx, -gw, 0.0], [gx, -gw, -gh - r], r, white)),
            ((gx, gw, -gh / 2), bar([gx, gw, 0.0], [gx, gw, -gh - r], r, white)),
            ((gx, 0.0, -gh), bar([gx, -gw - r, -gh], [gx, gw + r, -gh], r, white)),
        ]
    return [(float(np.linalg.norm(np.asarray(c) - camera.C)), draw) for c, draw in out]


def draw_sprites(canvas: Canvas, scene: Scene) -> None:
    """The goals and the players of ``scene`` onto ``canvas``, farthest first."""
    camera = canvas.camera
    light_side = float(scene.sun_dir[0])
    sprites = goal_sprites(scene, camera)
    sprites += [(float(np.linalg.norm(np.array([p.foot[0], p.foot[1], -0.9]) - camera.C)),
                 partial(draw_player, player=p, shade=shade_at(scene, p.foot), light_side=light_side))
                for p in scene.players]
    sprites.sort(key=lambda item: -item[0])
    for _, draw in sprites:
        draw(canvas)
