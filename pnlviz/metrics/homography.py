"""Homography metrics of WorldCup 2014 / TS-WorldCup: IoU part, IoU whole, projection error (m)
and reprojection error.

Homographies map WC14 template points (yards; 115 x 74; origin at the far-left corner, x along
the length, y towards the main camera) to image pixels at 1280 x 720. There is no installable
reference implementation, so every choice is written down here:

* **Sign.** A homography is known up to scale, including its sign. For a real camera,
  ``H ~ K [r1 r2 t] T`` (T the template -> field map, a positive scale plus a shift) has
  ``det ∝ -C_z > 0`` for a camera above the pitch (z points down), and then the third
  homogeneous coordinate of ``H X`` is the depth of X. Every homography is first scaled to a
  positive determinant; template points whose depth is ``<= 0`` are behind the camera.
* **IoU part.** An all-ones 1280 x 720 image is warped into a 115 x 74 canvas (1 px per yard;
  canvas pixel ``(i, j)`` samples template point ``(i, j)``) with ``cv2.warpPerspective`` (bilinear,
  constant zero border) by the inverse of the homography (passed as H itself with
  ``WARP_INVERSE_MAP``, which is the same map without inverting twice); template pixels behind the
  camera are cleared (OpenCV would paint their mirror image). IoU of the non-zero pixels of the
  ground-truth and predicted masks; failure when both are empty.
* **IoU whole.** The template rectangle ``[0, 115] x [0, 74]`` is mapped by ``H_pred`` and then
  back by ``inv(H_gt)``, i.e. through ``M = inv(H_gt) H_pred``. When the homogeneous coordinate of
  M has the same strict sign at the four corners the image is a bounded convex quadrilateral,
  clipped against the rectangle (Sutherland-Hodgman, float64) for the polygon IoU. Otherwise
  the mapped template is unbounded (it crosses the horizon): failure.
* **Projection error.** Pixels are sampled with a fixed seed (``numpy.random.default_rng(seed)``,
  integer pixel coordinates, with replacement, by rejection) among the pixels whose ground-truth
  back-projection lands in front of the camera inside the template rectangle (the visible field
  area), 2,500 of them. Each is back-projected by both homographies; the mean distance on the
  template, converted from yards to metres (1 m = 1.09361 yd), is the error. Failure when no
  pixel of the frame shows the field, or when a sampled pixel lies above the predicted horizon
  (its predicted back-projection would be behind the predicted camera).
* **Reprojection error.** The 13 x 7 grid of template points ``linspace(0, 115, 13) x
  linspace(0, 74, 7)`` that project in front of the camera into the frame (``0 <= u < 1280``,
  ``0 <= v < 720``) under ``H_gt``; mean image distance between their ground-truth and predicted
  projections, divided by the image height (720). Failure when no grid point is in the frame or
  when one of them is behind the predicted camera.
* **Aggregation.** Mean and median over the frames where a metric is defined; failures (NaN) and
  frames without a prediction are counted separately, never averaged in.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import cv2
import numpy as np

from pnlviz.geometry.camera import Camera

__all__ = [
    "IMAGE_SIZE", "TEMPLATE_SIZE", "YARDS_PER_METRE", "homography_from_camera", "iou_part", "iou_whole",
    "projection_error", "reprojection_error", "HomographyFrameResult", "HomographySummary",
    "evaluate_homography", "evaluate_homographies", "METRICS",
]

IMAGE_SIZE: tuple[int, int] = (1280, 720)
TEMPLATE_SIZE: tuple[float, float] = (115.0, 74.0)
YARDS_PER_METRE = 1.09361
#: per-frame metric names, in table order
METRICS: tuple[str, ...] = ("iou_part", "iou_whole", "proj_error_m", "reproj_error")


def _positive(H: np.ndarray) -> np.ndarray | None:
    """``H`` scaled to unit Frobenius norm and a positive determinant; None if singular or not
    finite."""
    H = np.asarray(H, dtype=np.float64)
    if H.shape != (3, 3) or not np.all(np.isfinite(H)):
        return None
    norm = np.linalg.norm(H)
    if not norm > 0:
        return None
    H = H / norm
    d = np.linalg.det(H)
    if not abs(d) > 1e-12:
        return None
    return H if d > 0 else -H


def _apply(H: np.ndarray, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points (N, 2) through H -> (dehomogenised (N, 2), homogeneous w (N,))."""
    h = pts @ H[:, :2].T + H[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        return h[:, :2] / h[:, 2:], h[:, 2]


def homography_from_camera(camera: Camera | Mapping, model=None, image_size: tuple[int, int] = IMAGE_SIZE,
                           source_size: tuple[float, float] | None = None) -> np.ndarray:
    """Template (yards) -> image homography of a camera at ``image_size`` (default 1280 x 720).

    The camera (or SoccerNet camera dict) is taken at its own image size (twice its principal
    point, or ``source_size`` when given), rescaled to ``image_size``, and its ground homography
    (field metres -> pixels, lens distortion ignored) is composed with the template -> field
    map. The result has a positive determinant for a camera above the pitch.
    """
    from pnlviz.field.model import load_field_model

    model = model or load_field_model()
    cam = camera if isinstance(camera, Camera) else Camera.from_soccernet(camera)
    if source_size is not None:
        cam = replace(cam, width=float(source_size[0]), height=float(source_size[1]))
    cam = cam.scaled(*image_size)
    return cam.ground_homography() @ model.template_to_field_matrix


# ----------------------------------------------------------------------------------- IoU part
def _template_mask(H: np.ndarray, image_size: tuple[int, int], template_size: tuple[float, float]) -> np.ndarray:
    w, h = image_size
    tw, th = int(round(template_size[0])), int(round(template_size[1]))
    ones = np.ones((h, w), dtype=np.float32)
    warped = cv2.warpPerspective(ones, H, (tw, th), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                                 borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    ys, xs = np.mgrid[0:th, 0:tw]
    depth = H[2, 0] * xs + H[2, 1] * ys + H[2, 2]
    return (warped > 0) & (depth > 0)


def iou_part(H_gt: np.ndarray, H_pred: np.ndarray, image_size: tuple[int, int] = IMAGE_SIZE,
             template_size: tuple[float, float] = TEMPLATE_SIZE) -> float:
    """IoU of the template areas seen by the two homographies (1 px per yard); NaN on failure."""
    Hg, Hp = _positive(H_gt), _positive(H_pred)
    if Hg is None or Hp is None:
        return float("nan")
    a, b = _template_mask(Hg, image_size, template_size), _template_mask(Hp, image_size, template_size)
    union = np.count_nonzero(a | b)
    return np.count_nonzero(a & b) / union if union else float("nan")


# ---------------------------------------------------------------------------------- IoU whole
def _area(poly: np.ndarray) -> float:
    """Signed shoelace area (positive counter-clockwise in a y-up frame)."""
    if len(poly) < 3:
        return 0.0
    x, y = poly[:, 0], poly[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def clip_polygon_to_box(poly: np.ndarray, x0: float, y0: float, x1: float, y1: float) -> np.ndarray:
    """Sutherland-Hodgman clipping of a polygon (any orientation; convex or not) by the box
    ``[x0, x1] x [y0, y1]``. The result has the right area even where a non-convex polygon
    leaves degenerate edges along the box."""
    out = np.asarray(poly, dtype=np.float64).reshape(-1, 2)
    # each box side as (axis, bound, keep_greater)
    for axis, bound, keep_greater in ((0, x0, True), (0, x1, False), (1, y0, True), (1, y1, False)):
        if len(out) == 0:
            break
        nxt = np.roll(out, -1, axis=0)
        s_in = out[:, axis] >= bound if keep_greater else out[:, axis] <= bound
        e_in = np.roll(s_in, -1)
        pts = []
        for s, e, si, ei in zip(out, nxt, s_in, e_in):
            if si:
                pts.append(s)
            if si != ei:  # the edge crosses the side
                t = (bound - s[axis]) / (e[axis] - s[axis])
                p = s + t * (e - s)
                p[axis] = bound
                pts.append(p)
        out = np.array(pts).reshape(-1, 2)
    return out


def iou_whole(H_gt: np.ndarray, H_pred: np.ndarray, template_size: tuple[float, float] = TEMPLATE_SIZE) -> float:
    """Polygon IoU of the template rectangle with its image under ``inv(H_gt) H_pred``; NaN when
    that image is unbounded (see the module docstring) or a homography is singular."""
    Hg, Hp = _positive(H_gt), _positive(H_pred)
    if Hg is None or Hp is None:
        return float("nan")
    L, W = template_size
    corners = np.array([[0.0, 0.0], [L, 0.0], [L, W], [0.0, W]])
    M = np.linalg.solve(Hg, Hp)
    quad, w = _apply(M, corners)
    scale = np.abs(M[2]).sum() * max(L, W)
    if not (np.all(w > 1e-12 * scale) or np.all(w < -1e-12 * scale)) or not np.all(np.isfinite(quad)):
        return float("nan")
    if _area(quad) < 0:
        quad = quad[::-1]
    area_quad, area_rect = _area(quad), L * W
    inter = abs(_area(clip_polygon_to_box(quad, 0.0, 0.0, L, W)))
    union = area_rect + area_quad - inter
    return inter / union if union > 0 else float("nan")


# --------------------------------------------------------------------------- projection error
def visible_field_pixels(H_gt: np.ndarray, n: int = 2500, seed: int = 0, image_size: tuple[int, int] = IMAGE_SIZE,
                         template_size: tuple[float, float] = TEMPLATE_SIZE, max_draws: int = 1 << 20) -> np.ndarray:
    """``n`` integer pixels (with replacement, fixed seed) whose ground-truth back-projection is
    in front of the camera inside the template; fewer (maybe none) if the field covers less than
    ~``n / max_draws`` of the frame."""
    Hg = _positive(H_gt)
    if Hg is None:
        return np.zeros((0, 2))
    Hinv = np.linalg.inv(Hg)  # positive determinant too: in front <=> w > 0
    rng = np.random.default_rng(seed)
    w, h = image_size
    found: list[np.ndarray] = []
    count = draws = 0
    while count < n and draws < max_draws:
        batch = max(4096, 2 * (n - count))
        uv = np.stack([rng.integers(0, w, batch), rng.integers(0, h, batch)], axis=1).astype(np.float64)
        draws += batch
        xy, depth = _apply(Hinv, uv)
        keep = (depth > 0) & (xy[:, 0] >= 0) & (xy[:, 0] <= template_size[0]) & (xy[:, 1] >= 0) & (xy[:, 1] <= template_size[1])
        found.append(uv[keep])
        count += int(keep.sum())
    return np.vstack(found)[:n] if found else np.zeros((0, 2))


def projection_error(H_gt: np.ndarray, H_pred: np.ndarray, n: int = 2500, seed: int = 0,
                     image_size: tuple[int, int] = IMAGE_SIZE, template_size: tuple[float, float] = TEMPLATE_SIZE,
                     yards_per_metre: float = YARDS_PER_METRE) -> float:
    """Mean distance (metres) on the field between the ground-truth and predicted
    back-projections of ``n`` visible pixels; NaN on failure (see the module docstring)."""
    Hg, Hp = _positive(H_gt), _positive(H_pred)
    if Hg is None or Hp is None:
        return float("nan")
    uv = visible_field_pixels(Hg, n, seed, image_size, template_size)
    if len(uv) == 0:
        return float("nan")
    xy_gt, _ = _apply(np.linalg.inv(Hg), uv)
    xy_pred, depth = _apply(np.linalg.inv(Hp), uv)
    if not np.all(depth > 0):
        return float("nan")
    d = np.hypot(*(xy_pred - xy_gt).T)
    return float(np.mean(d)) / yards_per_metre


# ------------------------------------------------------------------------- reprojection error
def template_grid(template_size: tuple[float, float] = TEMPLATE_SIZE, shape: tuple[int, int] = (13, 7)) -> np.ndarray:
    """The ``nx x ny`` grid of template points spanning the rectangle, (nx * ny, 2)."""
    xs = np.linspace(0.0, template_size[0], shape[0])
    ys = np.linspace(0.0, template_size[1], shape[1])
    return np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)


def reprojection_error(H_gt: np.ndarray, H_pred: np.ndarray, image_size: tuple[int, int] = IMAGE_SIZE,
                       template_size: tuple[float, float] = TEMPLATE_SIZE, grid: tuple[int, int] = (13, 7)) -> float:
    """Mean image distance between the ground-truth and predicted projections of the template
    grid points visible under ``H_gt``, divided by the image height; NaN on failure."""
    Hg, Hp = _positive(H_gt), _positive(H_pred)
    if Hg is None or Hp is None:
        return float("nan")
    pts = template_grid(template_size, grid)
    uv_gt, depth = _apply(Hg, pts)
    w, h = image_size
    keep = (depth > 0) & (uv_gt[:, 0] >= 0) & (uv_gt[:, 0] < w) & (uv_gt[:, 1] >= 0) & (uv_gt[:, 1] < h)
    if not keep.any():
        return float("nan")
    uv_pred, depth_pred = _apply(Hp, pts[keep])
    if not np.all(depth_pred > 0):
        return float("nan")
    return float(np.mean(np.hypot(*(uv_pred - uv_gt[keep]).T))) / h


# --------------------------------------------------------------------------------- frames, sets
@dataclass(frozen=True)
class HomographyFrameResult:
    """The four metrics of one frame (NaN = failure); ``missing`` when there is no prediction."""

    stem: str | None
    missing: bool
    iou_part: float = math.nan
    iou_whole: float = math.nan
    proj_error_m: float = math.nan
    reproj_error: float = math.nan

    def value(self, metric: str) -> float:
        return getattr(self, metric)


def evaluate_homography(H_gt: np.ndarray, H_pred: np.ndarray | None, stem: str | None = None, *,
                        image_size: tuple[int, int] = IMAGE_SIZE, template_size: tuple[float, float] = TEMPLATE_SIZE,
                        n_pixels: int = 2500, seed: int = 0) -> HomographyFrameResult:
    """All four metrics of one frame (``H_pred`` None = no prediction)."""
    if H_pred is None:
        return HomographyFrameResult(stem, True)
    return HomographyFrameResult(
        stem, False,
        iou_part(H_gt, H_pred, image_size, template_size),
        iou_whole(H_gt, H_pred, template_size),
        projection_error(H_gt, H_pred, n_pixels, seed, image_size, template_size),
        reprojection_error(H_gt, H_pred, image_size, template_size),
    )


@dataclass
class HomographySummary:
    frames: list[HomographyFrameResult]
    skipped: list[str] = field(default_factory=list)

    @property
    def n_frames(self) -> int:
        return len(self.frames)

    @property
    def n_missing(self) -> int:
        return sum(f.missing for f in self.frames)

    def values(self, metric: str) -> np.ndarray:
        """Finite values of ``metric`` over the frames with a prediction."""
        v = np.array([f.value(metric) for f in self.frames if not f.missing], dtype=np.float64)
        return v[np.isfinite(v)]

    def n_failed(self, metric: str) -> int:
        return self.n_frames - self.n_missing - len(self.values(metric))

    def mean(self, metric: str) -> float:
        v = self.values(metric)
        return float(np.mean(v)) if len(v) else float("nan")

    def median(self, metric: str) -> float:
        v = self.values(metric)
        return float(np.median(v)) if len(v) else float("nan")

    def as_dict(self) -> dict[str, Any]:
        return {"frames": self.n_frames, "missing": self.n_missing,
                **{m: {"mean": self.mean(m), "median": self.median(m), "failed": self.n_failed(m)} for m in METRICS}}

    def table(self) -> str:
        labels = {"iou_part": "IoU part", "iou_whole": "IoU whole", "proj_error_m": "proj. error (m)",
                  "reproj_error": "reproj. error (/H)"}
        lines = [f"frames {self.n_frames}, without prediction {self.n_missing}",
                 f"{'metric':<20}{'mean':>10}{'median':>10}{'failed':>8}"]
        for m in METRICS:
            lines.append(f"{labels[m]:<20}{self.mean(m):10.4f}{self.median(m):10.4f}{self.n_failed(m):8d}")
        return "\n".join(lines)


def evaluate_homographies(gt: Mapping[str, np.ndarray], pred: Mapping[str, np.ndarray | None],
                          progress: bool = False, stems: Iterable[str] | None = None, **kwargs) -> HomographySummary:
    """Score every ground-truth frame (or ``stems``) against ``pred`` (missing = no prediction)."""
    from tqdm import tqdm

    stems = list(gt if stems is None else stems)
    frames = [evaluate_homography(gt[s], pred.get(s), s, **kwargs)
              for s in tqdm(stems, desc="homography metrics", unit="frame", disable=not progress or None)]
    return HomographySummary(frames)
