"""SoccerNet line annotations of a synthetic camera, clicked the way human annotators do.

The annotation is a test oracle (DESIGN.md, "Synthetic frames are test oracles"):

* it holds exactly the classes the official evaluator's ``get_polylines(cam, 960, 540,
  sampling_factor=0.9)`` sees through the ground-truth camera: no class is ever dropped, even
  when a player hides it in the rendered image, and none is added;
* every point lies on that evaluator polyline (its vertices, or interpolated along its genuine
  segments), so the ground-truth camera scores accuracy 1.0 at any threshold >= 0.5 px.

The camera used is the one written to disk, read back: ``Camera.from_soccernet`` of
``camera.scaled(960, 540).to_soccernet()``, projected with the evaluator's float32 pixel
arithmetic, so that border decisions are the evaluator's own.

Points per class, like an annotator's clicks: for a straight class, both ends of each visible
run plus 0-2 points in between; for a circle, 6-20 points spread along the visible run(s), in
polyline order, run ends included. The evaluator joins the runs of a class into one polyline;
runs are told apart again by where consecutive points jump along the pitch model (more than the
model sampling step between them), found by back-projecting them onto the class' plane.
Coordinates are normalised at the evaluation scale: ``x / (960 - 1)``, ``y / (540 - 1)``.
"""

from __future__ import annotations

import math

import numpy as np

from pnlviz.conventions import EVAL_SIZE
from pnlviz.field.model import load_field_model
from pnlviz.field.names import CIRCLE_CLASSES
from pnlviz.geometry.camera import Camera
from pnlviz.geometry.polylines import visible_pitch

EVAL_W, EVAL_H = EVAL_SIZE
#: Model sampling of the evaluator: straight classes every 0.9 m, circles every 0.2 m.
LINE_SPACING, CIRCLE_SPACING = 0.9, 0.2
#: When a class' visible polyline degenerates to one point, the second click is this far away
#: (pixels, along the projected line): well inside the evaluator's 0.5 px tolerance.
SECOND_CLICK_PX = 0.2


def evaluation_camera(camera: Camera) -> Camera:
    """The ground-truth camera at 960 x 540 exactly as stored in the camera JSON and read back."""
    return Camera.from_soccernet(camera.scaled(EVAL_W, EVAL_H).to_soccernet())


def _model_param(cam: Camera, name: str, uv: np.ndarray) -> np.ndarray:
    """Position (metres along the model curve) of pixels ``uv`` lying on class ``name``."""
    model = load_field_model()
    d = cam.pixel_rays(uv)
    if name in CIRCLE_CLASSES:
        arc = model.circles[name]
        with np.errstate(divide="ignore", invalid="ignore"):
            s = -cam.C[2] / d[:, 2]
        P = cam.C + s[:, None] * d
        ang = np.arctan2(P[:, 1] - arc.center[1], P[:, 0] - arc.center[0])
        rel = np.mod(ang - math.radians(arc.start_deg), 2 * np.pi)
        return rel * arc.radius
    seg = model.lines[name]
    direction = (seg.end - seg.start) / seg.length
    if seg.plane == "ground":
        axis, value = 2, 0.0
    else:  # goal posts and crossbars lie in the goal-line plane x = +-52.5
        axis, value = 0, float(seg.start[0])
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (value - cam.C[axis]) / d[:, axis]
    P = cam.C + s[:, None] * d
    return (P - seg.start) @ direction


def split_runs(cam: Camera, name: str, poly: np.ndarray) -> list[np.ndarray]:
    """The visible runs of the evaluator polyline ``poly`` (M, 2) of class ``name``."""
    if len(poly) < 2:
        return [poly]
    param = _model_param(cam, name, poly)
    step = np.abs(np.diff(param))
    if name == "Circle central":  # the angle wraps where the evaluator's sampling starts
        step = np.minimum(step, 2 * np.pi * load_field_model().circles[name].radius - step)
    jumps = np.flatnonzero(np.isfinite(step) & (step > _max_sample_gap(name) * 1.02 + 1e-3))
    return np.split(poly, jumps + 1)


def _max_sample_gap(name: str) -> float:
    """Largest distance along the model between consecutive evaluator samples of ``name`` (the
    appended end point of a straight class can be up to two sampling steps away)."""
    X = load_field_model().sample_polylines(LINE_SPACING, CIRCLE_SPACING)[name]
    return float(np.linalg.norm(np.diff(X, axis=0), axis=1).max())


def _arc_points(run: np.ndarray, positions: np.ndarray) -> np.ndarray:
    """Points at arc-length ``positions`` along the polyline ``run`` (exactly on its segments)."""
    seg = np.hypot(*np.diff(run, axis=0).T)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    out = []
    for p in positions:
        if p <= 0:
            out.append(run[0])
            continue
        if p >= cum[-1]:
            out.append(run[-1])
            continue
        j = int(np.searchsorted(cum, p, side="right") - 1)
        j = min(j, len(seg) - 1)
        frac = (p - cum[j]) / seg[j] if seg[j] > 0 else 0.0
        out.append(run[j] + frac * (run[j + 1] - run[j]))
    return np.array(out).reshape(-1, 2)


def _length(run: np.ndarray) -> float:
    return float(np.hypot(*np.diff(run, axis=0).T).sum()) if len(run) > 1 else 0.0


def _clicks_on_run(run: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` >= 2 clicks spread along ``run``, its two ends included (fewer if it has no length)."""
    L = _length(run)
    if L == 0.0:
        return run[:1]
    if n <= 2:
        return _arc_points(run, np.array([0.0, L]))
    inner = np.linspace(0.0, L, n)[1:-1]
    jitter = rng.uniform(-0.3, 0.3, len(inner)) * (L / (n - 1))
    inner = np.sort(np.clip(inner + jitter, 0.02 * L, 0.98 * L))
    return _arc_points(run, np.concatenate([[0.0], inner, [L]]))


def _allocate(total: int, share: np.ndarray) -> list[int]:
    """Split ``total`` clicks over runs by ``share``: at least 2 per run, at most ``total`` (20)
    overall unless there are that many runs."""
    counts = np.maximum(2, np.floor(total * share).astype(int))
    while counts.sum() > max(total, 2 * len(counts)):
        counts[np.argmax(counts)] -= 1
    while counts.sum() < total:
        counts[np.argmax(share * total - counts)] += 1
    return [int(c) for c in counts]


def _second_click(cam: Camera, name: str, p: np.ndarray) -> np.ndarray:
    """A point ``SECOND_CLICK_PX`` from ``p`` along the projected model curve of ``name``."""
    samples = load_field_model().sample_polylines(LINE_SPACING, CIRCLE_SPACING)[name]
    uv, depth = cam.project_with_depth(samples)
    ok = np.flatnonzero(depth > 1e-3)
    direction = np.array([1.0, 0.0])
    if len(ok) >= 2:
        k = ok[np.argmin(np.hypot(*(uv[ok] - p).T))]
        pos = int(np.searchsorted(ok, k))
        nb = ok[pos + 1] if pos + 1 < len(ok) else ok[pos - 1]
        v = uv[nb] - uv[k]
        if np.all(np.isfinite(v)) and np.hypot(*v) > 0:
            direction = v / np.hypot(*v)
    # Step towards the image centre side so the click stays in the frame when possible.
    centre = np.array([(EVAL_W - 1) / 2, (EVAL_H - 1) / 2])
    if np.dot(centre - p, direction) < 0:
        direction = -direction
    return p + SECOND_CLICK_PX * direction


def clicks_for_class(cam: Camera, name: str, poly: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Annotation points (pixels at 960 x 540) of class ``name`` given its evaluator polyline."""
    runs = [r for r in split_runs(cam, name, poly) if len(r)]
    if name in CIRCLE_CLASSES:
        total = int(rng.integers(6, 21))
        lengths = np.array([_length(r) for r in runs])
        long_runs = lengths > 0
        counts = np.ones(len(runs), int)  # a run without length is one click
        if long_runs.any():
            share = lengths[long_runs] / lengths[long_runs].sum()
            counts[long_runs] = _allocate(max(total - int((~long_runs).sum()), 2), share)
        pts = [_clicks_on_run(r, int(c), rng) for r, c in zip(runs, counts)]
    else:
        pts = []
        for r in runs:
            n_inner = int(rng.integers(0, 3)) if _length(r) > 0 else 0
            pts.append(_clicks_on_run(r, 2 + n_inner, rng))
    points = np.vstack(pts)
    # No two consecutive identical clicks.
    keep = np.concatenate([[True], np.any(np.diff(points, axis=0) != 0, axis=1)])
    points = points[keep]
    if len(points) < 2:
        points = np.vstack([points[:1], _second_click(cam, name, points[0])[None]])
    return points


def annotate(camera: Camera, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """``{class: (N, 2) normalised points}`` for every class the evaluator sees through ``camera``
    (any image size: the evaluation scale 960 x 540 is used), keys sorted."""
    cam = evaluation_camera(camera)
    visible = visible_pitch(cam, EVAL_W, EVAL_H, spacing=LINE_SPACING, evaluator_precision=True)
    scale = np.array([EVAL_W - 1, EVAL_H - 1], dtype=float)
    out = {}
    for name in sorted(visible):
        out[name] = clicks_for_class(cam, name, visible[name], rng) / scale
    return out


def annotation_to_json(annotation: dict[str, np.ndarray]) -> dict[str, list[dict[str, float]]]:
    """SoccerNet JSON structure ``{class: [{"x": .., "y": ..}, ...]}``."""
    return {name: [{"x": float(x) + 0.0, "y": float(y) + 0.0} for x, y in pts] for name, pts in annotation.items()}


__all__ = ["annotate", "annotation_to_json", "evaluation_camera", "split_runs", "clicks_for_class",
           "EVAL_W", "EVAL_H"]
