"""The ground of a synthetic frame: grass (mowing stripes, lighting, a world-space noise texture),
the painted markings and the players' shadows.

Markings are 12 cm wide, centred on the pitch model's lines and arcs (the penalty arcs only
where the model's arc angles put them, outside the big boxes), plus the three spots. Their
coverage is the exact box filter of the paint strip over the pixel's footprint measured along
the strip's normal (from the Jacobian of the pixel -> ground map), so thin far lines fade
instead of aliasing. The work per marking is limited to windows around its projection.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np

from pnlviz.field.model import Arc, load_field_model
from pnlviz.geometry.camera import Camera

from .raycast import F32, box_coverage, interval_coverage, pixel_windows
from .scene import HALF_LENGTH, HALF_WIDTH, Scene

SPOT_RADIUS = 0.11
#: Ground hits are clamped to this camera depth (metres) so that rays at the horizon stay finite.
FAR = 1.0e6


@lru_cache(maxsize=1)
def _grass_tile() -> np.ndarray:
    """A 512 x 512 periodic noise tile (zero mean, unit variance), the same in every process:
    white noise low-passed in the Fourier domain (a periodic blur), fine grain plus clumps."""
    rng = np.random.default_rng(20240611)
    spectrum = np.fft.rfft2(rng.standard_normal((512, 512)))
    fy = np.fft.fftfreq(512)[:, None]
    fx = np.fft.rfftfreq(512)[None, :]
    f2 = fx ** 2 + fy ** 2
    transfer = np.exp(-2 * (np.pi * 1.2) ** 2 * f2) + 1.5 * np.exp(-2 * (np.pi * 6.0) ** 2 * f2)
    tile = np.fft.irfft2(spectrum * transfer, s=(512, 512))
    tile = (tile - tile.mean()) / tile.std()
    return tile.astype(F32)


# ----------------------------------------------------------------------------- markings
PIECE_POINTS = 6


@dataclass(frozen=True)
class _Stripe:
    """A piece of a straight marking from ``A`` along ``e`` (unit) for ``L`` metres (``n``: its normal)."""

    A: np.ndarray
    e: np.ndarray
    n: np.ndarray
    L: float
    points: np.ndarray  # (K, 3) samples whose projection bounds the piece

    def coverage(self, x, y, xu, xv, yu, yv, half_width: float) -> np.ndarray:
        A, e, n, L = self.A, self.e, self.n, self.L
        if e[1] == 0 or e[0] == 0:  # axis-aligned: every line of the pitch
            horizontal = e[1] == 0
            along = (x - F32(A[0])) * F32(e[0]) if horizontal else (y - F32(A[1])) * F32(e[1])
            across = np.abs(y - F32(A[1])) if horizontal else np.abs(x - F32(A[0]))
            pa, pn = (np.hypot(xu, xv), np.hypot(yu, yv)) if horizontal else (np.hypot(yu, yv), np.hypot(xu, xv))
        else:
            rx, ry = x - F32(A[0]), y - F32(A[1])
            along = rx * F32(e[0]) + ry * F32(e[1])
            across = np.abs(rx * F32(n[0]) + ry * F32(n[1]))
            pn = np.hypot(xu * F32(n[0]) + yu * F32(n[1]), xv * F32(n[0]) + yv * F32(n[1]))
            pa = np.hypot(xu * F32(e[0]) + yu * F32(e[1]), xv * F32(e[0]) + yv * F32(e[1]))
        c = box_coverage(across, half_width, pn + F32(1e-6))
        c *= interval_coverage(along, -half_width, L + half_width, pa + F32(1e-6))
        return c


@dataclass(frozen=True)
class _ArcPiece:
    """A piece of a circle or arc marking (``full``: a whole circle, no angle test)."""

    arc: Arc
    full: bool
    points: np.ndarray

    def coverage(self, x, y, xu, xv, yu, yv, half_width: float) -> np.ndarray:
        arc = self.arc
        rx, ry = x - F32(arc.center[0]), y - F32(arc.center[1])
        rho = np.hypot(rx, ry) + F32(1e-6)
        cx, cy = rx / rho, ry / rho
        pn = np.hypot(xu * cx + yu * cy, xv * cx + yv * cy) + F32(1e-6)
        c = box_coverage(np.abs(rho - F32(arc.radius)), half_width, pn)
        return c if self.full else c * arc.contains_angle(np.arctan2(ry, rx))


@dataclass(frozen=True)
class _Spot:
    """A penalty or centre spot at ``centre`` (x, y)."""

    centre: np.ndarray
    points: np.ndarray

    def coverage(self, x, y, xu, xv, yu, yv, half_width: float) -> np.ndarray:
        rho = np.hypot(x - F32(self.centre[0]), y - F32(self.centre[1]))
        p = np.sqrt(np.hypot(xu, xv) * np.hypot(yu, yv)) + F32(1e-6)
        return interval_coverage(rho, -SPOT_RADIUS, SPOT_RADIUS, p)


@lru_cache(maxsize=1)
def _marking_pieces() -> tuple[list, np.ndarray]:
    """The ground markings cut into short pieces (window culling), with their sample points."""
    model = load_field_model()
    pieces: list = []
    for seg in model.lines.values():
        if seg.plane != "ground":
            continue
        A, B = seg.start[:2], seg.end[:2]
        L = float(np.linalg.norm(B - A))
        e = (B - A) / L
        n = np.array([-e[1], e[0]])
        k = max(1, int(math.ceil(L / 4.0)))
        for i in range(k):
            s = np.linspace(L * i / k, L * (i + 1) / k, PIECE_POINTS)
            pts = np.zeros((PIECE_POINTS, 3))
            pts[:, :2] = A + s[:, None] * e
            pieces.append(_Stripe(A, e, n, L, pts))
    for arc in model.circles.values():
        a0, a1 = math.radians(arc.start_deg), math.radians(arc.end_deg)
        k = max(1, int(math.ceil(arc.radius * (a1 - a0) / 4.0)))
        full = arc.end_deg - arc.start_deg >= 360.0 - 1e-9
        for i in range(k):
            ang = np.linspace(a0 + (a1 - a0) * i / k, a0 + (a1 - a0) * (i + 1) / k, PIECE_POINTS)
            pieces.append(_ArcPiece(arc, full, arc.point_at(ang)))
    spots = [np.zeros(2), model.circles["Circle left"].center[:2], model.circles["Circle right"].center[:2]]
    for c in spots:
        pts = np.zeros((PIECE_POINTS, 3))
        ang = np.linspace(0, 2 * math.pi, PIECE_POINTS)
        pts[:, 0] = c[0] + 0.2 * np.cos(ang)
        pts[:, 1] = c[1] + 0.2 * np.sin(ang)
        pieces.append(_Spot(np.asarray(c, float), pts))
    return pieces, np.stack([p.points for p in pieces])


def _paint_coverage(camera: Camera, X: np.ndarray, Y: np.ndarray, half_width: float) -> np.ndarray:
    """(H, W) float32 share of each pixel covered by paint (ground markings only)."""
    H, W = X.shape
    cov = np.zeros((H, W), F32)
    pieces, points = _marking_pieces()
    for piece, win in zip(pieces, pixel_windows(camera, points, half_width + 0.03, 2.5)):
        if win is None:
            continue
        x, y = X[win], Y[win]
        if x.shape[0] < 2 or x.shape[1] < 2:
            continue
        # Jacobian of the pixel -> ground map inside the window (metres per pixel).
        xv, xu = np.gradient(x)
        yv, yu = np.gradient(y)
        c = piece.coverage(x, y, xu, xv, yu, yv, half_width)
        np.maximum(cov[win], c.astype(F32), out=cov[win])
    return cov


# ----------------------------------------------------------------------------- grass
def _stripes(x: np.ndarray, width: float, phase: float, p: np.ndarray) -> np.ndarray:
    """Square wave (+1 / -1 bands of ``width`` along x) box-filtered over the footprint ``p``:
    difference of its (triangular, periodic) integral."""
    period = 2.0 * width

    def integral(v):
        m = np.mod(v - F32(phase), F32(period))
        return np.where(m < width, m, F32(period) - m)

    p = np.maximum(p, F32(1e-4))
    return (integral(x + 0.5 * p) - integral(x - 0.5 * p)) / p


def _upsample(field: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Resize a field computed on a coarse pixel grid back to ``shape`` (smooth fields only)."""
    return cv2.resize(field.astype(F32), (shape[1], shape[0]), interpolation=cv2.INTER_LINEAR)


def ground_colour(camera: Camera, scene: Scene, d: tuple, t_ground: np.ndarray) -> tuple:
    """Grass + markings + lighting for every pixel (meaningless where the ground is not seen).
    Returns (BGR (H, W, 3) float32, X, Y, paint coverage)."""
    dx, dy, dz = d
    C = camera.C
    g = scene.grass
    H, W = dx.shape
    t = np.minimum(t_ground, F32(FAR))
    X = (F32(C[0]) + t * dx).astype(F32)
    Y = (F32(C[1]) + t * dy).astype(F32)
    # Smooth fields on a coarse grid: pixel footprint on the ground and lighting.
    step = 4
    Xs, Ys = X[::step, ::step], Y[::step, ::step]
    gxv, gxu = np.gradient(Xs)
    gyv, gyu = np.gradient(Ys)
    pX = np.hypot(gxu, gxv) / step
    pY = np.hypot(gyu, gyv) / step
    (ax, fx, phx), (ay, fy, phy) = g.light_waves
    shade = 1.0 + ax * np.cos(Xs * fx + phx) + ay * np.cos(Ys * fy + phy)
    if g.shadow is not None:
        nx, ny, off, strength = g.shadow
        shade = shade * (1.0 - strength * np.clip((Xs * nx + Ys * ny - off) / 1.5 + 0.5, 0, 1))
    tex_amp = g.texture_strength / (1.0 + (np.maximum(pX, pY) / (4 * g.texture_scale)) ** 2)
    pX, shade, tex_amp = (_upsample(f, (H, W)) for f in (pX, shade, tex_amp))
    # Grass: stripes along x inside the mowed area, a world-space noise texture.
    stripe = _stripes(X, g.stripe_width, g.stripe_phase, pX)
    stripe *= F32(g.stripe_contrast)
    stripe[(np.abs(X) > HALF_LENGTH + 2.5) | (np.abs(Y) > HALF_WIDTH + 2.5)] = 0
    mx = np.mod(X * F32(1.0 / g.texture_scale) + F32(g.texture_offset[0]), F32(512.0))
    my = np.mod(Y * F32(1.0 / g.texture_scale) + F32(g.texture_offset[1]), F32(512.0))
    tex = cv2.remap(_grass_tile(), mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)
    factor = (F32(1.0) + stripe + tex * tex_amp) * shade
    colour = g.base[None, None, :] * factor[:, :, None]
    st = scene.stadium
    beyond = np.flatnonzero((np.abs(X) > st.board_end) | (np.abs(Y) > st.board_side))
    flat = colour.reshape(-1, 3)
    if len(beyond):
        flat[beyond] = st.track_colour[None, :] * shade.ravel()[beyond, None]
    # Paint, lit like the grass under it.
    half_width = 0.5 * float(load_field_model().dimensions.get("line_width", 0.12))
    cov = _paint_coverage(camera, X, Y, half_width)
    idx = np.flatnonzero(cov)
    if len(idx):
        a = (F32(g.line_opacity) * cov.ravel()[idx])[:, None]
        paint = g.line_colour[None, :] * shade.ravel()[idx, None]
        flat[idx] += (paint - flat[idx]) * a
    return colour, X, Y, cov


def player_shadows(camera: Camera, scene: Scene, X, Y, colour: np.ndarray) -> None:
    """Soft ground shadows under (and cast away from) each player, in place on ``colour``."""
    if not scene.players:
        return
    sd = scene.sun_dir
    squares = []
    for p in scene.players:
        c = p.foot + 0.5 * sd
        squares.append([[c[0] + ox, c[1] + oy, 0.0] for ox, oy in ((-1.3, -1.3), (1.3, -1.3), (1.3, 1.3), (-1.3, 1.3))])
    wins = pixel_windows(camera, np.array(squares), 0.0, 2.0, closed=True)
    for p, win in zip(scene.players, wins):
        if win is None:
            continue
        rx = X[win] - F32(p.foot[0] + 0.45 * sd[0])
        ry = Y[win] - F32(p.foot[1] + 0.45 * sd[1])
        along = rx * F32(sd[0]) + ry * F32(sd[1])
        across = -rx * F32(sd[1]) + ry * F32(sd[0])
        blob = np.exp(-(along / F32(0.65)) ** 2 - (across / F32(0.28)) ** 2)
        colour[win] *= (F32(1.0) - F32(scene.player_shadow) * blob)[:, :, None]



def shade_at(scene: Scene, xy: np.ndarray) -> float:
    g = scene.grass
    shade = 1.0
    if g.shadow is not None:
        nx, ny, off, strength = g.shadow
        s = min(max((xy[0] * nx + xy[1] * ny - off) / 1.5 + 0.5, 0.0), 1.0)
        shade *= 1.0 - strength * s
    return shade
