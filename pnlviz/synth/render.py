"""Broadcast-like rendering of a synthetic frame by per-pixel ray casting (vectorised numpy).

Every pixel centre (integer coordinates, the convention of :meth:`Camera.project`) gets a world
ray, lens distortion removed. Rays are scaled so that their camera-frame z component is 1: the
ray parameter ``t`` of a hit is then its depth along the optical axis, and ``t / fx`` is the
size of a pixel there (the footprint used for anti-aliasing).

Layers, back to front:

1. background, the nearest of: the ground plane z = 0 (grass with mowing stripes, lighting,
   a world-space noise texture and the painted markings), the advertising boards (vertical
   planes a few metres outside the touchlines and goal lines), the stands (sloped planes beyond
   the boards, a crowd texture), or the sky;
2. "sprites" drawn in depth order, farthest first, each tested against the depth of boards and
   stands: goal nets (faint meshes on the faces of a 2 m deep box), posts and crossbars (white
   12 cm cylinders, coverage from the distance between each pixel ray and the bar axis) and
   players (upright billboards facing the camera with a body made of capsules);
3. camera effects: optical blur, optional motion blur, vignetting, colour gain, sensor noise.
   JPEG compression happens when the frame is written.

Markings are 12 cm wide, centred on the pitch model's lines and arcs (the penalty arcs only
where the model's arc angles put them, outside the big boxes), plus the three spots. Their
coverage is the exact box filter of the paint strip over the pixel's footprint measured along
the strip's normal (from the Jacobian of the pixel -> ground map), so thin far lines fade
instead of aliasing. The work per marking is limited to windows around its projection.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np

from pnlviz.field.model import load_field_model
from pnlviz.geometry.camera import Camera

from .scene import HALF_LENGTH, HALF_WIDTH, Scene, sample_scene

SKY, GROUND, BOARD, STAND = 0, 1, 2, 3
F32 = np.float32
SPOT_RADIUS = 0.11
POST_RADIUS = 0.06
GOAL_HALF_WIDTH = load_field_model().dimensions["goal_width"] / 2
GOAL_HEIGHT = load_field_model().dimensions["goal_height"]
#: Ground hits are clamped to this camera depth (metres) so that rays at the horizon stay finite.
FAR = 1.0e6


@dataclass
class RenderResult:
    image: np.ndarray  # (H, W, 3) uint8, BGR
    surface: np.ndarray  # (H, W) uint8: SKY, GROUND, BOARD or STAND (what the background shows)
    occluder: np.ndarray  # (H, W) float32: opacity of the goals and players drawn over it
    scene: Scene


# ----------------------------------------------------------------------------- rays
def _radial_ratio_table(camera: Camera, r_max: float, n: int = 4096) -> tuple[np.ndarray, np.ndarray]:
    """Undistorted / distorted normalised radius as a function of the distorted radius, from the
    camera's own (iterative) undistortion on a fine radial grid. Exact for radial-only lenses."""
    rd = np.linspace(0.0, r_max, n)
    ru = camera.undistort(np.stack([rd, np.zeros(n)], axis=1))[:, 0]
    ratio = np.ones(n)
    ratio[1:] = ru[1:] / rd[1:]
    return rd, ratio


def ray_grid(camera: Camera) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World directions (dx, dy, dz), each (H, W) float32, of the rays through every pixel centre,
    distortion removed, scaled to a camera-frame z of 1.

    Equivalent to ``camera.pixel_rays`` on the pixel grid (rescaled), computed faster: the
    normalised coordinates are separable without distortion; a radial-only lens is undone with
    a radial lookup table built from ``camera.undistort``; any other lens uses ``pixel_rays``.
    """
    W, H = int(round(camera.width)), int(round(camera.height))
    R = camera.R
    xd = (np.arange(W) - camera.cx) / camera.fx
    yd = (np.arange(H) - camera.cy) / camera.fy
    if not camera.has_distortion:
        xn = xd.astype(F32)[None, :]
        yn = yd.astype(F32)[:, None]
    elif not (np.any(camera.tangential) or np.any(camera.thin_prism)):
        r = np.sqrt(xd[None, :] ** 2 + yd[:, None] ** 2)
        table_r, table_ratio = _radial_ratio_table(camera, float(r.max()) * 1.001 + 1e-9)
        ratio = np.interp(r, table_r, table_ratio)
        xn = (xd[None, :] * ratio).astype(F32)
        yn = (yd[:, None] * ratio).astype(F32)
    else:
        uu, vv = np.meshgrid(np.arange(W, dtype=float), np.arange(H, dtype=float))
        d = camera.pixel_rays(np.stack([uu.ravel(), vv.ravel()], axis=1))
        d = d / (d @ R[2])[:, None]  # camera-frame z = 1
        return tuple(d[:, k].reshape(H, W).astype(F32) for k in range(3))
    R32 = R.astype(F32)
    return tuple(np.broadcast_to(R32[0, k] * xn + R32[1, k] * yn + R32[2, k], (H, W)).astype(F32)
                 for k in range(3))


# ----------------------------------------------------------------------------- helpers
def _box(d: np.ndarray, half: float, p: np.ndarray) -> np.ndarray:
    """Share of a pixel of footprint ``p`` centred at distance ``d`` from the middle of a strip
    of half width ``half`` that the strip covers (box filter)."""
    return np.clip(np.minimum(d + 0.5 * p, half) - np.maximum(d - 0.5 * p, -half), 0.0, None) / p


def _interval(x: np.ndarray, lo: float, hi: float, p: np.ndarray) -> np.ndarray:
    """Share of a pixel of footprint ``p`` centred at ``x`` that lies in [lo, hi]."""
    return np.clip(np.minimum(x + 0.5 * p, hi) - np.maximum(x - 0.5 * p, lo), 0.0, None) / p


_LAST_FRUSTUM = threading.local()  # per thread: (camera, bounds) of the last call


def _frustum_bounds(camera: Camera) -> tuple[float, float]:
    """Half extents (a, b) of the image in undistorted normalised coordinates, with a margin."""
    last = getattr(_LAST_FRUSTUM, "value", None)
    if last is not None and last[0] is camera:
        return last[1]
    W, H = camera.width, camera.height
    s = np.linspace(0.0, 1.0, 33)
    border = np.concatenate([np.stack([s * W, np.zeros_like(s)], 1), np.stack([s * W, np.full_like(s, H)], 1),
                             np.stack([np.zeros_like(s), s * H], 1), np.stack([np.full_like(s, W), s * H], 1)])
    xd = np.stack([(border[:, 0] - camera.cx) / camera.fx, (border[:, 1] - camera.cy) / camera.fy], axis=1)
    xn = camera.undistort(xd)
    bounds = (float(np.abs(xn[:, 0]).max()) * 1.1 + 0.01, float(np.abs(xn[:, 1]).max()) * 1.1 + 0.01)
    _LAST_FRUSTUM.value = (camera, bounds)
    return bounds


def _windows(camera: Camera, points: np.ndarray, margin_m: float, extra_px: float = 3.0, *,
             closed: bool = False, near: float = 0.2):
    """Pixel windows around the polylines through groups of world points (G, K, 3) (closed
    polygons with ``closed``): a list of (slice_v, slice_u), or None where nothing of a group is
    in view. Each chord is clipped to the (slightly enlarged) view frustum in camera space first,
    so parts behind or far beside the camera do not blow the window up."""
    W, H = int(round(camera.width)), int(round(camera.height))
    G, K, _ = points.shape
    Pc = camera.to_camera(points.reshape(-1, 3)).reshape(G, K, 3)
    if closed:
        Pc = np.concatenate([Pc, Pc[:, :1]], axis=1)
    P0, P1 = Pc[:, :-1], Pc[:, 1:]
    a, b = _frustum_bounds(camera)

    def planes(P):  # >= 0 inside: near, right, left, bottom, top
        x, y, z = P[..., 0], P[..., 1], P[..., 2]
        return np.stack([z - near, a * z - x, a * z + x, b * z - y, b * z + y], axis=-1)

    f0, f1 = planes(P0), planes(P1)
    with np.errstate(divide="ignore", invalid="ignore"):
        cross = f0 / (f0 - f1)
    lo = np.where((f0 < 0) & (f1 >= 0), cross, 0.0).max(axis=-1)
    hi = np.where((f0 >= 0) & (f1 < 0), cross, 1.0).min(axis=-1)
    ok = (lo <= hi) & ~np.any((f0 < 0) & (f1 < 0), axis=-1)
    ends = np.stack([P0 + lo[..., None] * (P1 - P0), P0 + hi[..., None] * (P1 - P0)], axis=2)  # (G, K-1, 2, 3)
    Xw = ends.reshape(-1, 3) @ camera.R + camera.C  # back to world for Camera.project
    uv, depth = camera.project(Xw)
    uv = uv.reshape(G, -1, 2, 2)
    depth = depth.reshape(G, -1, 2)
    f = max(camera.fx, camera.fy)
    out = []
    for g in range(G):
        sel = ok[g]
        if not sel.any():
            out.append(None)
            continue
        pu, dg = uv[g][sel].reshape(-1, 2), depth[g][sel].ravel()
        m = margin_m * f / max(float(dg.min()), near) + extra_px
        u0 = max(0, int(math.floor(pu[:, 0].min() - m)))
        u1 = min(W, int(math.ceil(pu[:, 0].max() + m)) + 1)
        v0 = max(0, int(math.floor(pu[:, 1].min() - m)))
        v1 = min(H, int(math.ceil(pu[:, 1].max() + m)) + 1)
        out.append((slice(v0, v1), slice(u0, u1)) if u0 < u1 and v0 < v1 else None)
    return out


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
@dataclass(frozen=True)
class _Piece:
    kind: str  # "seg", "arc" or "spot"
    params: tuple
    points: np.ndarray  # (K, 3) samples whose projection bounds the piece


PIECE_POINTS = 6


@lru_cache(maxsize=1)
def _marking_pieces() -> tuple[list[_Piece], np.ndarray]:
    """The ground markings cut into short pieces (window culling), with their sample points."""
    model = load_field_model()
    pieces: list[_Piece] = []
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
            pieces.append(_Piece("seg", (A, e, n, L), pts))
    for arc in model.circles.values():
        a0, a1 = math.radians(arc.start_deg), math.radians(arc.end_deg)
        k = max(1, int(math.ceil(arc.radius * (a1 - a0) / 4.0)))
        full = arc.end_deg - arc.start_deg >= 360.0 - 1e-9
        for i in range(k):
            ang = np.linspace(a0 + (a1 - a0) * i / k, a0 + (a1 - a0) * (i + 1) / k, PIECE_POINTS)
            pieces.append(_Piece("arc", (arc, full), arc.point_at(ang)))
    spots = [np.zeros(2), model.circles["Circle left"].center[:2], model.circles["Circle right"].center[:2]]
    for c in spots:
        pts = np.zeros((PIECE_POINTS, 3))
        ang = np.linspace(0, 2 * math.pi, PIECE_POINTS)
        pts[:, 0] = c[0] + 0.2 * np.cos(ang)
        pts[:, 1] = c[1] + 0.2 * np.sin(ang)
        pieces.append(_Piece("spot", (np.asarray(c, float),), pts))
    return pieces, np.stack([p.points for p in pieces])


def _paint_coverage(camera: Camera, X: np.ndarray, Y: np.ndarray, half_width: float) -> np.ndarray:
    """(H, W) float32 share of each pixel covered by paint (ground markings only)."""
    H, W = X.shape
    cov = np.zeros((H, W), F32)
    pieces, points = _marking_pieces()
    for piece, win in zip(pieces, _windows(camera, points, half_width + 0.03, 2.5)):
        if win is None:
            continue
        x, y = X[win], Y[win]
        if x.shape[0] < 2 or x.shape[1] < 2:
            continue
        # Jacobian of the pixel -> ground map inside the window (metres per pixel).
        xv, xu = np.gradient(x)
        yv, yu = np.gradient(y)
        if piece.kind == "seg":
            A, e, n, L = piece.params
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
            c = _box(across, half_width, pn + F32(1e-6))
            c *= _interval(along, -half_width, L + half_width, pa + F32(1e-6))
        elif piece.kind == "arc":
            arc, full = piece.params
            rx, ry = x - F32(arc.center[0]), y - F32(arc.center[1])
            rho = np.hypot(rx, ry) + F32(1e-6)
            cx, cy = rx / rho, ry / rho
            pn = np.hypot(xu * cx + yu * cy, xv * cx + yv * cy) + F32(1e-6)
            c = _box(np.abs(rho - F32(arc.radius)), half_width, pn)
            if not full:
                c = c * arc.contains_angle(np.arctan2(ry, rx))
        else:
            (centre,) = piece.params
            rho = np.hypot(x - F32(centre[0]), y - F32(centre[1]))
            p = np.sqrt(np.hypot(xu, xv) * np.hypot(yu, yv)) + F32(1e-6)
            c = _interval(rho, -SPOT_RADIUS, SPOT_RADIUS, p)
        np.maximum(cov[win], c.astype(F32), out=cov[win])
    return cov


# ----------------------------------------------------------------------------- background
def _stripes(x: np.ndarray, width: float, phase: float, p: np.ndarray) -> np.ndarray:
    """Square wave (+1 / -1 bands of ``width`` along x) box-filtered over the footprint ``p``:
    difference of its (triangular, periodic) integral."""
    period = 2.0 * width

    def integral(v):
        m = np.mod(v - F32(phase), F32(period))
        return np.where(m < width, m, F32(period) - m)

    p = np.maximum(p, F32(1e-4))
    return (integral(x + 0.5 * p) - integral(x - 0.5 * p)) / p


def _surfaces(camera: Camera, scene: Scene, d: tuple) -> tuple:
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


def _upsample(field: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Resize a field computed on a coarse pixel grid back to ``shape`` (smooth fields only)."""
    return cv2.resize(field.astype(F32), (shape[1], shape[0]), interpolation=cv2.INTER_LINEAR)


def _ground_colour(camera: Camera, scene: Scene, d: tuple, t_ground: np.ndarray) -> tuple:
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


def _hash(i: np.ndarray, j: np.ndarray, salt: int) -> np.ndarray:
    h = (i.astype(np.int64).astype(np.uint32) * np.uint32(73856093)) ^ (j.astype(np.int64).astype(np.uint32) * np.uint32(19349663))
    h ^= np.uint32(salt & 0xFFFFFFFF)
    h ^= h >> np.uint32(15)
    h *= np.uint32(2246822519)
    h ^= h >> np.uint32(13)
    h *= np.uint32(3266489917)
    h ^= h >> np.uint32(16)
    return h


def _board_colour(scene: Scene, P: np.ndarray, info: np.ndarray) -> np.ndarray:
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


def _stand_colour(scene: Scene, P: np.ndarray, info: np.ndarray, starts: list[float]) -> np.ndarray:
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


def _sky_colour(scene: Scene, d: np.ndarray) -> np.ndarray:
    elev = np.clip(-d[:, 2] / np.linalg.norm(d, axis=1), 0, 1) ** 0.6
    look = scene.look
    return (look.sky_horizon[None, :] * (1 - elev[:, None]) + look.sky_top[None, :] * elev[:, None]).astype(F32)


# ----------------------------------------------------------------------------- sprites
class _Canvas:
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


def _draw_bar(cv: _Canvas, P0: np.ndarray, P1: np.ndarray, radius: float, colour: np.ndarray, light: float) -> None:
    """A cylinder of ``radius`` around the segment P0-P1, with perspective thickness."""
    pts = P0[None, :] + np.linspace(0, 1, 8)[:, None] * (P1 - P0)[None, :]
    (win,) = _windows(cv.camera, pts[None], radius, 2.0)
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
    alpha = _box(dist, radius, fp) * ((t > 0) & (t < cv.t_bg[win]))
    if not alpha.any():
        return
    shade = (F32(1.0) - F32(0.35) * np.clip(dist / F32(radius), 0, 1) ** 2) * F32(light)
    cv.blend(win, alpha.astype(F32), colour[None, None, :] * shade[:, :, None])


def _covers_a_corner(cv: "_Canvas", axis: int, value: float, ka: int, ra: tuple, kb: int, rb: tuple) -> bool:
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


def _draw_net(cv: _Canvas, axis: int, value: float, ranges: dict, colour: np.ndarray, opacity: float,
              light: float, spacing: float = 0.14, thread: float = 0.025) -> None:
    """A faint square mesh on the rectangle ``{axis: value} x ranges`` (axis-aligned plane)."""
    (ka, (lo_a, hi_a)), (kb, (lo_b, hi_b)) = sorted(ranges.items())
    corners = np.zeros((4, 3))
    corners[:, axis] = value
    corners[:, ka] = [lo_a, hi_a, lo_a, hi_a]
    corners[:, kb] = [lo_b, lo_b, hi_b, hi_b]
    corners = corners[[0, 1, 3, 2]]
    (win,) = _windows(cv.camera, corners[None], 0.0, 2.0, closed=True)
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
        exact = _box(dist, 0.5 * thread, fp)
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


def _draw_player(cv: _Canvas, player, shade: float, light_side: float) -> None:
    F = np.array([player.foot[0], player.foot[1], 0.0])
    to_cam = cv.camera.C[:2] - F[:2]
    dist = float(np.linalg.norm(to_cam))
    if dist < 1.0:
        return
    n = to_cam / dist
    ea = np.array([-n[1], n[0], 0.0])
    hgt = player.height
    corners = np.array([F + ea * s - np.array([0, 0, b]) for s, b in ((-0.6, 0.0), (0.6, 0.0), (0.6, hgt + 0.05), (-0.6, hgt + 0.05))])
    (win,) = _windows(cv.camera, corners[None], 0.0, 2.0, closed=True)
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


def _goal_sprites(scene: Scene, camera: Camera) -> list:
    """Goal parts as (distance, draw-callable-args) for depth sorting."""
    out = []
    net, op = scene.net_colour, scene.net_opacity
    white = np.array([0.97, 0.97, 0.97], F32)
    grey = np.array([0.7, 0.7, 0.72], F32)
    r = POST_RADIUS
    for sign in (-1.0, 1.0):
        gx = sign * HALF_LENGTH
        bx = gx + sign * 2.0
        gw, gh = GOAL_HALF_WIDTH, GOAL_HEIGHT
        xs = (min(gx, bx), max(gx, bx))
        items = [
            ((bx, 0.0, -gh / 2), ("net", 0, bx, {1: (-gw, gw), 2: (-gh, 0.0)}, net, op)),
            ((gx + sign, 0.0, -gh), ("net", 2, -gh, {0: xs, 1: (-gw, gw)}, net, op)),
            ((gx + sign, -gw, -gh / 2), ("net", 1, -gw, {0: xs, 2: (-gh, 0.0)}, net, op)),
            ((gx + sign, gw, -gh / 2), ("net", 1, gw, {0: xs, 2: (-gh, 0.0)}, net, op)),
            ((bx, -gw, -gh / 2), ("bar", np.array([bx, -gw, 0.0]), np.array([bx, -gw, -gh]), 0.035, grey)),
            ((bx, gw, -gh / 2), ("bar", np.array([bx, gw, 0.0]), np.array([bx, gw, -gh]), 0.035, grey)),
            ((gx + sign, -gw, -gh), ("bar", np.array([gx, -gw, -gh]), np.array([bx, -gw, -gh]), 0.03, grey)),
            ((gx + sign, gw, -gh), ("bar", np.array([gx, gw, -gh]), np.array([bx, gw, -gh]), 0.03, grey)),
            ((gx, -gw, -gh / 2), ("bar", np.array([gx, -gw, 0.0]), np.array([gx, -gw, -gh - r]), r, white)),
            ((gx, gw, -gh / 2), ("bar", np.array([gx, gw, 0.0]), np.array([gx, gw, -gh - r]), r, white)),
            ((gx, 0.0, -gh), ("bar", np.array([gx, -gw - r, -gh]), np.array([gx, gw + r, -gh]), r, white)),
        ]
        out.extend(items)
    return [(float(np.linalg.norm(np.asarray(c) - camera.C)), item) for c, item in out]


def _player_shadows(camera: Camera, scene: Scene, X, Y, colour: np.ndarray) -> None:
    """Soft ground shadows under (and cast away from) each player, in place on ``colour``."""
    if not scene.players:
        return
    sd = scene.sun_dir
    squares = []
    for p in scene.players:
        c = p.foot + 0.5 * sd
        squares.append([[c[0] + ox, c[1] + oy, 0.0] for ox, oy in ((-1.3, -1.3), (1.3, -1.3), (1.3, 1.3), (-1.3, 1.3))])
    wins = _windows(camera, np.array(squares), 0.0, 2.0, closed=True)
    for p, win in zip(scene.players, wins):
        if win is None:
            continue
        rx = X[win] - F32(p.foot[0] + 0.45 * sd[0])
        ry = Y[win] - F32(p.foot[1] + 0.45 * sd[1])
        along = rx * F32(sd[0]) + ry * F32(sd[1])
        across = -rx * F32(sd[1]) + ry * F32(sd[0])
        blob = np.exp(-(along / F32(0.65)) ** 2 - (across / F32(0.28)) ** 2)
        colour[win] *= (F32(1.0) - F32(scene.player_shadow) * blob)[:, :, None]


# ----------------------------------------------------------------------------- camera effects
def _camera_effects(image: np.ndarray, scene: Scene, rng: np.random.Generator) -> np.ndarray:
    look = scene.look
    H, W = image.shape[:2]
    img = cv2.GaussianBlur(image, (0, 0), look.blur_sigma)
    if look.motion_blur is not None:
        # A line kernel of odd size, point-symmetric about its centre pixel: blurs without
        # shifting the image (the markings stay centred on the ground truth).
        length, angle = look.motion_blur
        size = length | 1
        c = size // 2
        k = np.zeros((size, size), F32)
        for s in np.linspace(-c, c, 4 * size):
            k[c + int(math.floor(s * math.sin(angle) + 0.5)), c + int(math.floor(s * math.cos(angle) + 0.5))] = 1.0
        k += k[::-1, ::-1]
        img = cv2.filter2D(img, -1, k / k.sum(), borderType=cv2.BORDER_REFLECT)
    if look.vignette > 0:
        u = (np.arange(W, dtype=F32) - W / 2) / F32(W / 2)
        v = (np.arange(H, dtype=F32) - H / 2) / F32(W / 2)
        vig = F32(1.0) - F32(look.vignette) * (u[None, :] ** 2 + v[:, None] ** 2) / F32(1.3)
        img *= vig[:, :, None]
    img *= look.gain[None, None, :] * F32(255.0)
    noise = rng.standard_normal((H, W), dtype=F32) * F32(look.noise_sigma)
    img += noise[:, :, None]
    return np.clip(img + F32(0.5), 0, 255).astype(np.uint8)


# ----------------------------------------------------------------------------- entry points
def render(camera: Camera, rng: np.random.Generator, scene: Scene | None = None) -> RenderResult:
    """Render a broadcast-like frame of ``camera.width`` x ``camera.height`` seen by ``camera``.

    The random stadium and look are drawn from ``rng`` (or given as ``scene``); the result keeps
    the per-pixel surface ids and the opacity of occluders (players and goals) for tests.
    """
    if scene is None:
        scene = sample_scene(camera, rng)
    d = ray_grid(camera)
    H, W = d[0].shape
    surf, t_bg, t_ground, info, starts = _surfaces(camera, scene, d)
    image, X, Y, _ = _ground_colour(camera, scene, d, t_ground)
    _player_shadows(camera, scene, X, Y, image)

    flat = image.reshape(-1, 3)
    s = surf.ravel()
    for sid in (BOARD, STAND):
        idx = np.flatnonzero(s == sid)
        if len(idx):
            t = t_bg.ravel()[idx]
            P = np.stack([camera.C[k] + t * d[k].ravel()[idx] for k in range(3)], axis=1)
            if sid == BOARD:
                flat[idx] = _board_colour(scene, P, info.ravel()[idx])
            else:
                flat[idx] = _stand_colour(scene, P, info.ravel()[idx], starts)
    idx = np.flatnonzero(s == SKY)
    if len(idx):
        flat[idx] = _sky_colour(scene, np.stack([d[k].ravel()[idx] for k in range(3)], axis=1))

    # Sprites, farthest first.
    canvas = _Canvas(camera, d, image, t_bg)
    light_side = float(scene.sun_dir[0])
    sprites = _goal_sprites(scene, camera)
    sprites += [(float(np.linalg.norm(np.array([p.foot[0], p.foot[1], -0.9]) - camera.C)), ("player", p))
                for p in scene.players]
    sprites.sort(key=lambda item: -item[0])
    for _, item in sprites:
        if item[0] == "bar":
            _draw_bar(canvas, item[1], item[2], item[3], item[4], light=1.0)
        elif item[0] == "net":
            _draw_net(canvas, item[1], item[2], item[3], item[4], item[5], light=0.95)
        else:
            p = item[1]
            _draw_player(canvas, p, shade=_shade_at(scene, p.foot), light_side=light_side)
    out = _camera_effects(image, scene, rng)
    return RenderResult(image=out, surface=surf, occluder=canvas.occ, scene=scene)


def _shade_at(scene: Scene, xy: np.ndarray) -> float:
    g = scene.grass
    shade = 1.0
    if g.shadow is not None:
        nx, ny, off, strength = g.shadow
        s = min(max((xy[0] * nx + xy[1] * ny - off) / 1.5 + 0.5, 0.0), 1.0)
        shade *= 1.0 - strength * s
    return shade


def render_frame(camera: Camera, rng: np.random.Generator) -> np.ndarray:
    """BGR uint8 image (camera.height, camera.width, 3) of a random broadcast-like scene."""
    return render(camera, rng).image


__all__ = ["render", "render_frame", "RenderResult", "ray_grid", "SKY", "GROUND", "BOARD", "STAND"]
