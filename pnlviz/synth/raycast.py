"""Rays through the pixels of a camera, and the pixel windows that world polylines cover: the
geometry every layer of the renderer (:mod:`pnlviz.synth.render`) shares.

Every pixel centre (integer coordinates, the convention of :meth:`Camera.project`) gets a world
ray, lens distortion removed. Rays are scaled so that their camera-frame z component is 1: the
ray parameter ``t`` of a hit is then its depth along the optical axis, and ``t / fx`` is the
size of a pixel there (the footprint used for anti-aliasing, by the box filters below).
"""

from __future__ import annotations

import math
import threading

import numpy as np

from pnlviz.geometry.camera import Camera

F32 = np.float32


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
        x, y, z = (d[:, k].reshape(H, W).astype(F32) for k in range(3))
        return x, y, z
    R32 = R.astype(F32)
    x, y, z = (np.broadcast_to(R32[0, k] * xn + R32[1, k] * yn + R32[2, k], (H, W)).astype(F32) for k in range(3))
    return x, y, z


# ----------------------------------------------------------------------------- coverage and windows
def box_coverage(d: np.ndarray, half: float, p: np.ndarray) -> np.ndarray:
    """Share of a pixel of footprint ``p`` centred at distance ``d`` from the middle of a strip
    of half width ``half`` that the strip covers (box filter)."""
    return np.clip(np.minimum(d + 0.5 * p, half) - np.maximum(d - 0.5 * p, -half), 0.0, None) / p


def interval_coverage(x: np.ndarray, lo: float, hi: float, p: np.ndarray) -> np.ndarray:
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


def pixel_windows(camera: Camera, points: np.ndarray, margin_m: float, extra_px: float = 3.0, *,
             closed: bool = False, near: float = 0.2) -> list[tuple[slice, slice] | None]:
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
    uv, depth = camera.project_with_depth(Xw)
    uv = uv.reshape(G, -1, 2, 2)
    depth = depth.reshape(G, -1, 2)
    f = max(camera.fx, camera.fy)
    out: list[tuple[slice, slice] | None] = []
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
