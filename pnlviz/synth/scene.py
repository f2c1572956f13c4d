"""The random stadium around a synthetic frame: grass, lighting, boards, stands, sky and players.

Everything here is drawn from the frame's random generator in a fixed order, so a frame is
reproducible from ``(seed, index)``. Colours are BGR floats in [0, 1] (OpenCV's channel order).
"""

from __future__ import annotations

import colorsys
import math
from dataclasses import dataclass

import cv2
import numpy as np

from pnlviz.field.model import load_field_model
from pnlviz.geometry.camera import Camera

_DIMENSIONS = load_field_model().dimensions
HALF_LENGTH, HALF_WIDTH = _DIMENSIONS["pitch_length"] / 2, _DIMENSIONS["pitch_width"] / 2


def hsv_to_bgr(h: float, s: float, v: float) -> np.ndarray:
    """HSV (hue in degrees, s and v in [0, 1]) -> BGR float32 in [0, 1]."""
    r, g, b = colorsys.hsv_to_rgb((h % 360.0) / 360.0, min(max(s, 0.0), 1.0), min(max(v, 0.0), 1.0))
    return np.array([b, g, r], dtype=np.float32)


def _kit_colour(rng: np.random.Generator) -> np.ndarray:
    """A football-kit colour: saturated hues, white, black or navy."""
    pick = rng.random()
    if pick < 0.15:
        return hsv_to_bgr(0, 0, rng.uniform(0.85, 0.97))  # white
    if pick < 0.25:
        return hsv_to_bgr(0, 0, rng.uniform(0.08, 0.18))  # black
    if pick < 0.32:
        return hsv_to_bgr(rng.uniform(215, 235), rng.uniform(0.6, 0.9), rng.uniform(0.2, 0.35))  # navy
    hue = rng.choice([0, 8, 30, 50, 200, 215, 270, 340, 120, 180]) + rng.normal(0, 6)
    return hsv_to_bgr(hue, rng.uniform(0.65, 0.95), rng.uniform(0.55, 0.9))


def _distinct_kit(rng: np.random.Generator, others: list[np.ndarray]) -> np.ndarray:
    best, best_d = None, -1.0
    for _ in range(8):
        c = _kit_colour(rng)
        d = min((float(np.abs(c - o).sum()) for o in others), default=9.0)
        if d > best_d:
            best, best_d = c, d
    assert best is not None  # the first draw beats -1
    return best


@dataclass(frozen=True)
class Kit:
    shirt: np.ndarray
    shorts: np.ndarray
    socks: np.ndarray


@dataclass(frozen=True)
class Player:
    """An upright figure standing at ``foot`` (x, y) on the ground."""

    foot: np.ndarray  # (2,)
    height: float  # metres
    kit: Kit
    skin: np.ndarray
    hair: np.ndarray
    stride: float  # signed half distance between the feet, metres (running pose)
    arm_swing: float  # signed, metres


@dataclass(frozen=True)
class Stadium:
    board_side: float  # y of the side boards (|y|)
    board_end: float  # x of the end boards (|x|)
    board_height: float
    board_block: float  # length of one advert block, metres
    board_styles: np.ndarray  # (S, 2, 3): background and lettering colours
    stand_side: float  # |y| where the side stands start rising
    stand_end: float  # |x| where the end stands start rising
    stand_slope: float  # radians
    stand_top: float  # height of the stand tops, metres
    row_depth: float  # metres along the slope per row
    seat_width: float
    aisle_every: float
    occupancy: float
    seat_colour: np.ndarray
    crowd_palette: np.ndarray  # (1024, 3)
    stand_light: float
    track_colour: np.ndarray
    hash_salt: int


@dataclass(frozen=True)
class Grass:
    base: np.ndarray  # (3,)
    stripe_width: float  # metres
    stripe_phase: float
    stripe_contrast: float  # relative brightness difference of the two stripe kinds
    texture_strength: float
    texture_scale: float  # metres per texel of the world-space noise tile
    texture_offset: np.ndarray  # (2,) texels
    light_waves: tuple[tuple[float, float, float], ...]  # (amplitude, metres^-1, phase) along x, then y
    shadow: tuple[float, float, float, float] | None  # (nx, ny, offset, strength) of a stand shadow
    line_colour: np.ndarray
    line_opacity: float


@dataclass(frozen=True)
class Look:
    """Camera-side effects."""

    sky_top: np.ndarray
    sky_horizon: np.ndarray
    blur_sigma: float
    motion_blur: tuple[int, float] | None  # (length px, angle rad)
    noise_sigma: float  # grey levels
    vignette: float
    gain: np.ndarray  # (3,) colour balance


@dataclass(frozen=True)
class Scene:
    grass: Grass
    stadium: Stadium
    players: list[Player]
    look: Look
    sun_dir: np.ndarray  # (2,) horizontal direction shadows fall towards
    player_shadow: float  # strength of the players' ground shadows
    net_colour: np.ndarray
    net_opacity: float


def _sample_grass(rng: np.random.Generator) -> Grass:
    base = hsv_to_bgr(rng.uniform(85, 112), rng.uniform(0.42, 0.68), rng.uniform(0.38, 0.62))
    waves = tuple((rng.uniform(0.03, 0.1), rng.uniform(0.03, 0.08), rng.uniform(0, 2 * math.pi)) for _ in range(2))
    shadow = None
    if rng.random() < 0.35:
        angle = rng.uniform(0, 2 * math.pi)
        shadow = (math.cos(angle), math.sin(angle), rng.uniform(-30, 30), rng.uniform(0.25, 0.45))
    return Grass(
        base=base,
        stripe_width=rng.uniform(5.0, 5.5),
        stripe_phase=rng.choice([0.0, rng.uniform(0, 5.25)]),
        stripe_contrast=rng.uniform(0.05, 0.16),
        texture_strength=rng.uniform(0.05, 0.12),
        texture_scale=rng.uniform(0.03, 0.06),
        texture_offset=rng.uniform(0, 512, size=2),
        light_waves=waves,
        shadow=shadow,
        line_colour=hsv_to_bgr(rng.uniform(40, 80), rng.uniform(0.0, 0.08), rng.uniform(0.88, 1.0)),
        line_opacity=rng.uniform(0.7, 0.95),
    )


def _hsv_array(h: np.ndarray, s: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Vectorised :func:`hsv_to_bgr`: (N,) arrays -> (N, 3) BGR float32."""
    hsv = np.stack([np.mod(h, 360.0), np.clip(s, 0, 1), np.clip(v, 0, 1)], axis=-1).astype(np.float32)
    return cv2.cvtColor(hsv[:, None, :], cv2.COLOR_HSV2BGR)[:, 0, :]


def _crowd_palette(rng: np.random.Generator, team_a: np.ndarray, team_b: np.ndarray, n: int = 1024) -> np.ndarray:
    """Colours of spectators: supporters of both teams, skin, dark and other clothes."""
    kind = rng.random(n)
    scale = rng.uniform(0.45, 0.9, n)[:, None].astype(np.float32)
    skin = _hsv_array(rng.uniform(15, 35, n), rng.uniform(0.25, 0.55, n), rng.uniform(0.3, 0.7, n))
    dark = _hsv_array(rng.uniform(0, 360, n), rng.uniform(0.0, 0.3, n), rng.uniform(0.05, 0.3, n))
    other = _hsv_array(rng.uniform(0, 360, n), rng.uniform(0.0, 0.5, n), rng.uniform(0.2, 0.8, n))
    palette = np.where((kind < 0.25)[:, None], team_a[None, :] * scale,
                       np.where((kind < 0.33)[:, None], team_b[None, :] * scale,
                                np.where((kind < 0.48)[:, None], skin, np.where((kind < 0.8)[:, None], dark, other))))
    return np.clip(palette, 0, 1).astype(np.float32)


def _sample_stadium(rng: np.random.Generator, grass_base: np.ndarray) -> Stadium:
    board_side = HALF_WIDTH + rng.uniform(3.0, 6.0)
    board_end = HALF_LENGTH + rng.uniform(3.0, 6.0)
    styles = []
    for _ in range(int(rng.integers(3, 7))):
        bg = hsv_to_bgr(rng.uniform(0, 360), rng.uniform(0.5, 1.0), rng.uniform(0.45, 1.0))
        if rng.random() < 0.2:
            bg = hsv_to_bgr(0, 0, rng.uniform(0.9, 1.0))
        fg = hsv_to_bgr(0, 0, 1.0) if rng.random() < 0.5 else hsv_to_bgr(rng.uniform(0, 360), rng.uniform(0.3, 1), rng.uniform(0.1, 1))
        if np.abs(fg - bg).sum() < 0.6:
            fg = 1.0 - bg
        styles.append(np.stack([bg, fg]))
    team_a, team_b = _kit_colour(rng), _kit_colour(rng)
    palette = _crowd_palette(rng, team_a, team_b)
    seat = hsv_to_bgr(rng.choice([0, 210, 225, 120, 45, 0]), rng.uniform(0.0, 0.8), rng.uniform(0.25, 0.6))
    return Stadium(
        board_side=board_side,
        board_end=board_end,
        board_height=rng.uniform(0.8, 1.0),
        board_block=rng.uniform(6.0, 11.0),
        board_styles=np.stack(styles).astype(np.float32),
        stand_side=board_side + rng.uniform(1.5, 5.0),
        stand_end=board_end + rng.uniform(1.5, 5.0),
        stand_slope=math.radians(rng.uniform(26, 36)),
        stand_top=rng.uniform(14, 32),
        row_depth=rng.uniform(0.75, 0.9),
        seat_width=rng.uniform(0.5, 0.6),
        aisle_every=rng.uniform(10, 20),
        occupancy=rng.uniform(0.6, 0.97),
        seat_colour=seat,
        crowd_palette=palette,
        stand_light=rng.uniform(0.5, 0.85),
        track_colour=grass_base * np.float32(rng.uniform(0.7, 0.9)),
        hash_salt=int(rng.integers(0, 2**31 - 1)),
    )


def _sample_look(rng: np.random.Generator) -> Look:
    overcast = rng.random() < 0.4
    if overcast:
        top = hsv_to_bgr(rng.uniform(200, 220), rng.uniform(0.0, 0.15), rng.uniform(0.6, 0.85))
        horizon = hsv_to_bgr(rng.uniform(200, 220), rng.uniform(0.0, 0.08), rng.uniform(0.75, 0.95))
    else:
        top = hsv_to_bgr(rng.uniform(205, 222), rng.uniform(0.45, 0.7), rng.uniform(0.55, 0.85))
        horizon = hsv_to_bgr(rng.uniform(195, 215), rng.uniform(0.12, 0.3), rng.uniform(0.8, 0.97))
    if rng.random() < 0.15:  # night match: dark sky
        top = hsv_to_bgr(230, 0.5, rng.uniform(0.03, 0.1))
        horizon = hsv_to_bgr(230, 0.4, rng.uniform(0.08, 0.18))
    motion = (int(rng.integers(3, 9)), rng.uniform(0, math.pi)) if rng.random() < 0.3 else None
    return Look(sky_top=top, sky_horizon=horizon, blur_sigma=rng.uniform(0.45, 0.85), motion_blur=motion,
                noise_sigma=rng.uniform(1.0, 4.0), vignette=rng.uniform(0.0, 0.18),
                gain=np.clip(1.0 + rng.normal(0, 0.03, 3), 0.9, 1.1).astype(np.float32))


def _visible_ground_points(camera: Camera, rng: np.random.Generator, n: int) -> np.ndarray:
    """Up to ``n`` random pitch points seen by ``camera`` (x, y), drawn from random pixels."""
    uv = np.stack([rng.uniform(0.03, 0.97, 4 * n) * camera.width,
                   rng.uniform(0.15, 1.0, 4 * n) * camera.height], axis=1)
    X = camera.back_project_to_ground(uv)
    ok = np.isfinite(X[:, 0]) & (np.abs(X[:, 0]) < HALF_LENGTH + 1.5) & (np.abs(X[:, 1]) < HALF_WIDTH + 1.5)
    return X[ok, :2][:n]


def _sample_players(camera: Camera, rng: np.random.Generator) -> list[Player]:
    n = int(rng.integers(5, 21))
    kits: list[Kit] = []
    for _ in range(5):  # two teams, two goalkeepers, referee
        shirt = _distinct_kit(rng, [k.shirt for k in kits])
        shorts = shirt if rng.random() < 0.4 else _kit_colour(rng)
        socks = shirt if rng.random() < 0.5 else shorts
        kits.append(Kit(shirt, shorts, socks))
    kits[4] = Kit(hsv_to_bgr(0, 0, 0.1), hsv_to_bgr(0, 0, 0.1), hsv_to_bgr(0, 0, 0.1)) if rng.random() < 0.6 else kits[4]
    seen = _visible_ground_points(camera, rng, n)
    # Players gather: most near the view, a few anywhere on the pitch.
    spots = [seen[i] for i in range(len(seen))]
    while len(spots) < n:
        spots.append(np.array([rng.uniform(-HALF_LENGTH, HALF_LENGTH), rng.uniform(-HALF_WIDTH, HALF_WIDTH)]))
    players = []
    for i, foot in enumerate(spots):
        team = int(rng.choice(5, p=[0.44, 0.44, 0.04, 0.04, 0.04]))
        skin = hsv_to_bgr(rng.uniform(18, 32), rng.uniform(0.3, 0.65), rng.uniform(0.25, 0.85))
        hair = hsv_to_bgr(rng.uniform(20, 40), rng.uniform(0.3, 0.7), rng.uniform(0.05, 0.45))
        players.append(Player(foot=np.asarray(foot, float), height=float(rng.uniform(1.7, 1.95)), kit=kits[team],
                              skin=skin, hair=hair, stride=float(rng.uniform(-0.3, 0.3)),
                              arm_swing=float(rng.uniform(-0.15, 0.15))))
    return players


def sample_scene(camera: Camera, rng: np.random.Generator) -> Scene:
    """A random stadium, lighting, look and players for a frame seen by ``camera``."""
    grass = _sample_grass(rng)
    stadium = _sample_stadium(rng, grass.base)
    look = _sample_look(rng)
    angle = rng.uniform(0, 2 * math.pi)
    players = _sample_players(camera, rng)
    return Scene(grass=grass, stadium=stadium, players=players, look=look,
                 sun_dir=np.array([math.cos(angle), math.sin(angle)]),
                 player_shadow=rng.uniform(0.25, 0.5),
                 net_colour=hsv_to_bgr(0, 0, rng.uniform(0.85, 1.0)), net_opacity=rng.uniform(0.5, 0.8))


__all__ = ["Scene", "Stadium", "Grass", "Look", "Player", "Kit", "sample_scene", "hsv_to_bgr"]
