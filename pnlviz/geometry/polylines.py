"""Project sampled pitch polylines into an image and clip them at the image border, with the same
rules as the SoccerNet evaluator (``get_polylines``), so that anything built on it (synthetic
annotations, metrics, overlays) agrees with the official scores.

The evaluator's rules, restated:

* points at depth <= 1e-3 m are skipped: they neither start nor end a visible run and are not
  remembered as the previous point;
* a point is inside when ``0 <= u < W`` and ``0 <= v < H`` (W, H given, not the camera's);
* when the polyline enters the image after its first point, the crossing of the segment (as an
  infinite line through the previous and current projected points) with the image border lines
  ``u = 0``, ``u = W - 1``, ``v = 0``, ``v = H - 1`` that lies inside and is closest to the current
  point is inserted before it; the same when it leaves, after the last inside point;
* all visible runs of a class are concatenated into one list.

``evaluator_precision=True`` reproduces the evaluator's float32 pixel arithmetic bit for bit.
"""

from __future__ import annotations

import math

import numpy as np

from pnlviz.errors import ArgumentError
from pnlviz.geometry.camera import MIN_DEPTH, Camera
from pnlviz.geometry.lens import imaged_in_camera
from pnlviz.geometry.shapes import as_array, as_points


def _project_like_evaluator(camera: Camera, X: np.ndarray, evaluator_precision: bool,
                            skip_folded: bool = False) -> tuple[np.ndarray, np.ndarray]:
    Xc = camera.to_camera(X)
    z = Xc[:, 2]
    ok = imaged_in_camera(camera, Xc) if skip_folded else z > MIN_DEPTH
    xn = np.zeros((len(X), 2))
    xn[ok] = Xc[ok, :2] / z[ok, None]
    xn[ok] = camera.distort(xn[ok])
    if evaluator_precision:
        # The evaluator's distort() returns float32, and the pixel maths then stays in float32.
        x32 = xn.astype(np.float32)
        uv = np.empty_like(x32)
        uv[:, 0] = x32[:, 0] * np.float32(camera.fx) + np.float32(camera.cx)
        uv[:, 1] = x32[:, 1] * np.float32(camera.fy) + np.float32(camera.cy)
        uv = uv.astype(np.float64)
    else:
        uv = np.empty_like(xn)
        uv[:, 0] = xn[:, 0] * camera.fx + camera.cx
        uv[:, 1] = xn[:, 1] * camera.fy + camera.cy
    return uv, ok


def segment_in_image(p: np.ndarray, q: np.ndarray, width: float, height: float) -> tuple[float, float] | None:
    """The part of segment p-q inside [0, W-1] x [0, H-1] as parameters (s0, s1) of p + s (q - p),
    0 <= s0 <= s1 <= 1 (Liang-Barsky); None when none of it is. Unlike :func:`clip_polyline` (which
    follows the evaluator), a segment crossing the image between two outside ends is clipped too.
    ``p``, ``q``: (2,) each; another shape: ArgumentError."""
    p, q = as_array(p, (2,), "p"), as_array(q, (2,), "q")
    d = q - p
    s0, s1 = 0.0, 1.0
    # p + s d inside the image, as inequalities P s <= Q
    for P, Q in ((-d[0], p[0]), (d[0], width - 1 - p[0]), (-d[1], p[1]), (d[1], height - 1 - p[1])):
        if abs(P) < 1e-12:
            if Q < 0:
                return None
        elif P < 0:
            s0 = max(s0, Q / P)
        else:
            s1 = min(s1, Q / P)
    return (s0, s1) if s0 <= s1 else None


def _inside(uv: np.ndarray, width: float, height: float) -> np.ndarray:
    """(N,) whether each pixel of ``uv`` (N, 2) is inside a ``width`` x ``height`` image, by the
    evaluator's rule (``0 <= u < W`` and ``0 <= v < H``; NaN is outside)."""
    return (uv[:, 0] >= 0) & (uv[:, 0] < width) & (uv[:, 1] >= 0) & (uv[:, 1] < height)


def _cross(a: tuple[float, float, float], b: tuple[float, float, float]) -> tuple[float, float, float]:
    """``np.cross`` of two 3-vectors in Python floats: the same products in the same order, so the
    same bits, without numpy's overhead on three numbers (the crossing below took most of an
    overlay's time)."""
    return a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]


def _border_crossing(cur, prev, width: float, height: float) -> np.ndarray | None:
    """Crossing of the line through two homogeneous points (3 numbers each) with the border lines,
    as the evaluator computes it (the candidate inside the image closest to ``cur``), or None."""
    cx, cy, cw = (float(v) for v in cur)
    line = _cross((cx, cy, cw), (float(prev[0]), float(prev[1]), float(prev[2])))
    best, best_d = None, math.inf
    right, bottom = float(-width + 1), float(-height + 1)  # as numpy turns the sides into float64
    for side in ((1.0, 0.0, 0.0), (1.0, 0.0, right), (0.0, 1.0, 0.0), (0.0, 1.0, bottom)):
        x, y, w = _cross(line, side)
        if w == 0:  # a point at infinity: numpy's division gives inf or NaN, never inside
            continue
        x, y, one = x / w, y / w, w / w
        if 0 <= x < width and 0 <= y < height:
            d = math.sqrt((x - cx) * (x - cx) + (y - cy) * (y - cy) + (one - cw) * (one - cw))
            if d < best_d:  # the first of equal distances, as np.argmin
                best, best_d = (x, y, one), d
    return None if best is None else np.array(best)


def clip_polyline(uv: np.ndarray, valid: np.ndarray, width: float, height: float) -> np.ndarray:
    """Visible part of one projected polyline ``uv`` (N, 2), as (M, 2) (possibly M = 0). ``valid``
    (N,) marks points in front of the camera. Other shapes: ArgumentError."""
    uv = as_points(uv, 2, "uv", "pixels")
    if np.shape(valid) != (len(uv),):
        raise ArgumentError(f"valid: expected one flag per point ({len(uv)},), got shape {np.shape(valid)}")
    idx = np.flatnonzero(valid)  # the evaluator skips the others entirely
    pts = uv[idx]
    inside = _inside(pts, width, height)
    if not inside.any():
        # A polyline can cross the image between two outside samples; the evaluator ignores that
        # case (it only looks for crossings next to an inside sample), and so do we.
        return np.zeros((0, 2))
    flags = np.concatenate([[False], inside, [False]]).astype(np.int8)
    starts = np.flatnonzero(np.diff(flags) == 1)  # first inside of each run
    ends = np.flatnonzero(np.diff(flags) == -1) - 1  # last inside of each run
    hom = np.hstack([pts, np.ones((len(pts), 1))])
    out: list[np.ndarray] = []
    for a, b in zip(starts, ends):
        if idx[a] > 0:  # entering: crossing between the previous remembered point and this one
            prev = hom[a - 1] if a > 0 else np.zeros(3)
            crossing = _border_crossing(hom[a], prev, width, height)
            if crossing is not None:
                out.append(crossing[None, :2])
        out.append(pts[a:b + 1])
        if b + 1 < len(pts):  # leaving: crossing between the last inside point and the next one
            crossing = _border_crossing(hom[b + 1], hom[b], width, height)
            if crossing is not None:
                out.append(crossing[None, :2])
    return np.vstack(out)


def project_polylines(camera: Camera, polylines: dict[str, np.ndarray], width: float | None = None,
                      height: float | None = None, *, evaluator_precision: bool = False,
                      skip_folded: bool = False) -> dict[str, np.ndarray]:
    """``{class: (N, 3) world points}`` -> ``{class: (M, 2) pixels}`` of the classes that are
    visible, clipped at the border of a ``width`` x ``height`` image (default: the camera's).
    ``skip_folded``: skip the points beyond the lens model's fold as well as those behind the camera
    (:func:`pnlviz.geometry.lens.imaged`): the model draws them inside the image where nothing of
    them is seen. For pictures; the evaluator keeps them, so metrics leave it False."""
    width = camera.width if width is None else width
    height = camera.height if height is None else height
    names = list(polylines)
    counts = [len(polylines[n]) for n in names]
    uv_all, ok_all = _project_like_evaluator(camera, np.vstack([polylines[n] for n in names]), evaluator_precision,
                                             skip_folded)
    seen = ok_all & _inside(uv_all, width, height)
    out: dict[str, np.ndarray] = {}
    start = 0
    for name, n in zip(names, counts):
        if seen[start:start + n].any():  # else nothing of it is drawn (clip_polyline would say so)
            clipped = clip_polyline(uv_all[start:start + n], ok_all[start:start + n], width, height)
            if len(clipped):
                out[name] = clipped
        start += n
    return out


def visible_pitch(camera: Camera, width: float = 960, height: float = 540, *, spacing: float = 0.9,
                  evaluator_precision: bool = False, model=None) -> dict[str, np.ndarray]:
    """The pitch model as the official evaluator sees it through ``camera`` at ``width`` x
    ``height`` (its ``get_polylines(camera, 960, 540, sampling_factor=0.9)``): the camera is used
    as given, not rescaled, exactly like the evaluator."""
    from pnlviz.field.model import load_field_model

    model = model or load_field_model()
    return project_polylines(camera, model.sample_polylines(spacing), width, height,
                             evaluator_precision=evaluator_precision)
