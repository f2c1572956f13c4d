"""What the background of a synthetic frame shows beyond the pitch: the advertising boards
(vertical planes a few metres outside the touchlines and goal lines), the stands (sloped planes
beyond the boards, a crowd texture) and the sky; and which of them, or the ground, each pixel
ray meets first.
"""

from __future__ import annotations

import math

import numpy as np

from pnlviz.geometry.camera import Camera

from .raycast import F32
from .scene import Scene

#: what a pixel's background is (:func:`surfaces`)
SKY, GROUND, BOARD, STAND = 0, 1, 2, 3


def surfaces(camera: Camera, scene: Scene, d: tuple) -> tuple:
    """Nearest background hit per pixel: surface id (H, W), depth of boards/stands (inf
    elsewhere), ground depth (inf above the horizon), which board/stand was hit (board index,
    +4 for a board's back), and where each of the four stands starts rising (metres)."""
    dx, dy, dz = d
    C = camera.C.astype(F32)
    st = scene.stadium
    H, W = dx.shape
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        t_ground = np.where(dz > 1e-6, -C[2] / dz, F32(np.inf)).astype(F32)
        t_bg = np.full((H, W), np.inf, F32)
        surf = np.full((H, W), SKY, np.uint8)
        info = np.zeros((H, W), np.uint8)  # which board/stand (0..3) and front/back bit
        # Boards: four vertical planes of height board_height.
        hb = F32(st.board_height)
        for k, (axis, value) in enumerate(((1, st.board_side), (1, -st.board_side), (0, st.board_end), (0, -st.board_end))):
            da = d[axis]
            t = (F32(value) - C[axis]) / da
            other = 1 - axis
            span = st.board_end if axis == 1 else st.board_side
            o = C[other] + t * d[other]
            z = C[2] + t * dz
            hit = (t > 0) & (np.abs(o) <= span) & (z >= -hb) & (z <= 0) & (t < t_bg)
            t_bg = np.where(hit, t, t_bg)
            surf[hit] = BOARD
            front = abs(camera.C[axis]) < abs(value)
            info[hit] = k | (0 if front else 4)
        # Stands: sloped planes z = -(q - start) tan(slope), q the outward coordinate. A camera
        # inside its own stand hangs on a gantry 2 m above a shallower lower tier (and, if even a
        # 15 degree slope is too steep, the tier starts farther out).
        starts = []
        for k, (axis, sign, start) in enumerate(((1, 1, st.stand_side), (1, -1, st.stand_side),
                                                 (0, 1, st.stand_end), (0, -1, st.stand_end))):
            q_cam, height = sign * camera.C[axis], -camera.C[2]
            tan = math.tan(st.stand_slope)
            if height - 2.0 < (q_cam - start) * tan:
                tan = max((height - 2.0) / (q_cam - start), math.tan(math.radians(15)))
                start = max(start, q_cam - (height - 2.0) / tan)
            starts.append(start)
            f_cam = F32(camera.C[2] + (q_cam - start) * tan)
            if f_cam >= 0:  # camera below 2 m: no stand on this side
                continue
            den = dz + F32(sign * tan) * d[axis]
            t = -f_cam / den
            z = C[2] + t * dz
            hit = (den > 0) & (t > 0) & (z >= -F32(st.stand_top)) & (t < t_bg)
            t_bg = np.where(hit, t, t_bg)
            surf[hit] = STAND
            info[hit] = k
        ground = t_ground < t_bg
        surf[ground] = GROUND
        t_bg[ground] = np.inf
    return surf, t_bg, t_ground, info, starts


def _hash(i: np.ndarray, j: np.ndarray, salt: int) -> np.ndarray:
    h = (i.astype(np.int64).astype(np.uint32) * np.uint32(73856093)) ^ (j.astype(np.int64).astype(np.uint32) * np.uint32(19349663))
    h ^= np.uint32(salt & 0xFFFFFFFF)
    h ^= h >> np.uint32(15)
    h *= np.uint32(2246822519)
    h ^= h >> np.uint32(13)
    h *= np.uint32(3266489917)
    h ^= h >> np.uint32(16)
    return h


def board_colour(scene: Scene, P: np.ndarray, info: np.ndarray) -> np.ndarray:
    """Advert boards at hit points P (N, 3), ``info`` = board index | 4 for the back side."""
    st = scene.stadium
    along = np.where((info & 3) < 2, P[:, 0], P[:, 1]) + np.where((info & 3) % 2 == 0, 0.0, 500.0)
    h = -P[:, 2] / st.board_height  # 0 at the bottom, 1 at the top
    block = np.floor(along / st.board_block)
    local = along / st.board_block - block
    style = _hash(block, (info & 3).astype(np.int64), st.hash_salt) % np.uint32(len(st.board_styles))
    bg = st.board_styles[style, 0]
    fg = st.board_styles[style, 1]
    # Lettering: a row of block glyphs in the middle of each advert.
    cell = 0.42 / st.board_block
    li = np.floor(local / cell)
    lf = local / cell - li
    glyph = _hash(li, block, st.hash_salt + 7) & np.uint32(3)
    in_text = (local > 0.12) & (local < 0.88) & (h > 0.25) & (h < 0.75)
    body = (lf > 0.12) & (lf < 0.82)
    hole = np.where(glyph == 0, (lf > 0.35) & (lf < 0.6) & (h > 0.4) & (h < 0.6),
                    np.where(glyph == 1, (h > 0.45) & (h < 0.55), np.where(glyph == 2, (lf > 0.4) & (lf < 0.55), False)))
    letter = in_text & body & ~hole
    col = np.where(letter[:, None], fg, bg)
    col = np.where(((h < 0.06) | (h > 0.94))[:, None], F32(0.08), col)
    back = (info & 4) > 0
    col[back] = F32(0.18)
    return col.astype(F32)


def stand_colour(scene: Scene, P: np.ndarray, info: np.ndarray, starts: list[float]) -> np.ndarray:
    """Crowd on the stands at hit points P (N, 3); ``info`` = stand index (0..3) whose slope
    starts at ``starts[info]``."""
    st = scene.stadium
    side = (info & 3).astype(np.int64)
    along = np.where(side < 2, P[:, 0], P[:, 1])
    outward = np.where(side < 2, np.abs(P[:, 1]), np.abs(P[:, 0])) - np.asarray(starts)[side]
    height = -P[:, 2]
    slope_pos = np.hypot(np.maximum(outward, 0), height)  # metres along the slope
    row = np.floor(slope_pos / st.row_depth)
    fv = slope_pos / st.row_depth - row
    seat_u = along / st.seat_width + 0.5 * (row % 2)
    seat = np.floor(seat_u)
    fu = seat_u - seat
    h = _hash(seat + 10000 * side, row, st.hash_salt)
    occupied = (h & np.uint32(1023)).astype(F32) < st.occupancy * 1024
    person = st.crowd_palette[(h >> np.uint32(10)) & np.uint32(1023)]
    # A spectator seen from the front and above: shoulders/torso ellipse and a round head; the
    # seat and the step of the row behind show around them.
    du = fu - 0.5 + ((h >> np.uint32(24)).astype(F32) / 255 - 0.5) * 0.16  # not all sit centred
    body = occupied & ((du / 0.36) ** 2 + ((fv - 0.42) / 0.34) ** 2 < 1)
    head = occupied & ((du / 0.15) ** 2 + ((fv - 0.8) / 0.13) ** 2 < 1)
    heads = np.array([[0.32, 0.45, 0.62], [0.2, 0.3, 0.45], [0.1, 0.14, 0.2], [0.06, 0.06, 0.07]], F32)
    seat = st.seat_colour[None, :] * (F32(0.55) + F32(0.45) * np.clip(fv / 0.6, 0, 1))[:, None]
    col = np.where(body[:, None], person, seat)
    col = np.where(head[:, None], heads[(h >> np.uint32(20)) & np.uint32(3)], col)
    col = np.where((fv <= 0.1)[:, None], F32(0.3), col)  # concrete step
    aisle = np.abs(np.mod(along, st.aisle_every) - 0.5 * st.aisle_every) < 0.6
    col = np.where(aisle[:, None], F32(0.42), col)
    front_wall = slope_pos < 1.3
    col = np.where(front_wall[:, None], st.seat_colour * F32(0.45) + F32(0.08), col)
    top = height > st.stand_top - 1.5
    col = np.where(top[:, None], F32(0.07), col)
    shade = st.stand_light * (1.0 - 0.35 * np.clip(height / max(st.stand_top, 1.0), 0, 1))
    return (col * shade[:, None]).astype(F32)


def sky_colour(scene: Scene, d: np.ndarray) -> np.ndarray:
    elev = np.clip(-d[:, 2] / np.linalg.norm(d, axis=1), 0, 1) ** 0.6
    look = scene.look
    return (look.sky_horizon[None, :] * (1 - elev[:, None]) + look.sky_top[None, :] * elev[:, None]).astype(F32)


def paint_background(image: np.ndarray, camera: Camera, scene: Scene, d: tuple, surf: np.ndarray, t_bg: np.ndarray,
                     info: np.ndarray, starts: list[float]) -> None:
    """Colour the pixels whose background is a board, a stand or the sky, in place on ``image``
    (the ground is coloured already); ``surf``, ``t_bg``, ``info``, ``starts`` from :func:`surfaces`."""
    flat = image.reshape(-1, 3)
    s = surf.ravel()
    for sid in (BOARD, STAND):
        idx = np.flatnonzero(s == sid)
        if len(idx):
            t = t_bg.ravel()[idx]
            P = np.stack([camera.C[k] + t * d[k].ravel()[idx] for k in range(3)], axis=1)
            if sid == BOARD:
                flat[idx] = board_colour(scene, P, info.ravel()[idx])
            else:
                flat[idx] = stand_colour(scene, P, info.ravel()[idx], starts)
    idx = np.flatnonzero(s == SKY)
    if len(idx):
        flat[idx] = sky_colour(scene, np.stack([d[k].ravel()[idx] for k in range(3)], axis=1))
