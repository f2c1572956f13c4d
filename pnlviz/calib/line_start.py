"""A first camera from a frame's straight ground lines, where its keypoints are too few.

A ground homography needs four point correspondences, but a line is as good as a point: the
image of a pitch line ``L`` (homogeneous, in ground coordinates) under the homography ``H`` is
the image line ``l`` with ``H^T l ~ L``, two linear equations in ``H`` as a point's ``x ~ H X``
gives two. A frame showing the goal line, two lines of the penalty box and a side line has no
four painted intersections in view (its keypoints are the two or three corners in the image) yet
its four lines fix the plane. :func:`line_homography` solves both kinds of equation together
(direct linear transform, each side normalised); :func:`line_sets` says which sets of lines and
ground keypoints to solve it from: all of them, and each with one left out (a wrong class in a
detection costs one start, not all). :func:`pnlviz.calib.calibrate.line_candidates` turns them
into cameras for the frame pipeline's vote.

The image lines are straight fits to the observed points (the lens bends them a little; the
refinement that follows has k1); only the start comes from here. The lines and points must fix
the plane (:func:`determined`): two lines in each of two directions do, three parallel lines and
one across do not (parallel lines meet at one point, at infinity, and a third adds one equation).
Four lines fix a homography exactly, a wrong one among them too: a camera started here must hold
more classes than fix it, or a measured keypoint, to pass the verdict
(:func:`pnlviz.calib.pipeline._verdict`).
"""

from __future__ import annotations

import numpy as np

from pnlviz.field.model import FieldModel

from .observations import Observations

__all__ = ["CHECKED_CLASSES", "LINE_SUBSET", "MIN_SPAN_PX", "determined", "ground_lines", "line_homography", "line_sets"]

#: an image line is fitted only to points spanning at least this far (px at 960 px width)
MIN_SPAN_PX = 20.0
#: the ``subset`` of a candidate (and of the result it wins) started from the lines
LINE_SUBSET = "lines"
#: four lines fix a homography exactly (eight equations), a wrong one among them as well: a camera
#: started from the lines is trusted when it fits this many classes, or a measured keypoint
CHECKED_CLASSES = 5


def _fit_image_line(points: np.ndarray) -> np.ndarray:
    """Homogeneous image line (unit normal) through ``points`` (M, 2): total least squares."""
    mean = points.mean(axis=0)
    _, _, vt = np.linalg.svd(points - mean)
    n = vt[-1]
    return np.array([n[0], n[1], -n @ mean])


def ground_lines(obs: Observations, model: FieldModel, min_span: float) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """The frame's straight ground classes measured well enough for a line: name -> (image line,
    pitch line), both homogeneous, the image line fitted to points spanning ``min_span`` px."""
    out = {}
    for name, pts in obs.lines.items():
        seg = model.lines.get(name)
        pts = np.asarray(pts, float).reshape(-1, 2)
        pts = pts[np.all(np.isfinite(pts), axis=1)]  # a point no one can place says nothing of the line
        if seg is None or seg.plane != "ground" or len(pts) < 2:
            continue
        if np.linalg.norm(pts.max(axis=0) - pts.min(axis=0)) < min_span:
            continue
        world = np.cross([seg.start[0], seg.start[1], 1.0], [seg.end[0], seg.end[1], 1.0])
        out[name] = (_fit_image_line(pts), world)
    return out


def _rows(image_lines: np.ndarray, pitch_lines: np.ndarray, image_points: np.ndarray,
          pitch_points: np.ndarray) -> np.ndarray:
    """The linear equations in ``H`` (row-major, 9 unknowns) of homogeneous line pairs (K, 3) and
    point pairs (P, 3): ``L x (H^T l) = 0`` and ``x x (H X) = 0``, three rows each (rank two)."""
    rows = [np.zeros((0, 9))]
    for l, L in zip(image_lines, pitch_lines):  # (H^T l)_i = sum_j l_j H[j, i]
        A = np.zeros((3, 9))
        for i in range(3):
            A[i, [i, 3 + i, 6 + i]] = l / np.linalg.norm(l)
        rows.append(_cross_matrix(L / np.linalg.norm(L)) @ A)
    for x, X in zip(image_points, pitch_points):  # (H X)_j = sum_k H[j, k] X_k
        B = np.zeros((3, 9))
        for j in range(3):
            B[j, 3 * j:3 * j + 3] = X / np.linalg.norm(X)
        rows.append(_cross_matrix(x / np.linalg.norm(x)) @ B)
    return np.vstack(rows)


#: a generic plane-to-plane map: the rank of the equations under it is the rank for any camera in
#: general position, so it tells a configuration that cannot fix the plane (three parallel lines
#: and one across, two points on a line...) from one that can, whatever the noise
_GENERIC = np.array([[1.1, 0.2, 0.3], [-0.1, 0.9, -0.2], [0.05, 0.03, 1.0]])


def determined(pitch_lines: np.ndarray, pitch_points: np.ndarray) -> bool:
    """Whether these pitch lines (K, 3, homogeneous) and points (P, 2) fix a homography."""
    Tw = np.diag([1.0 / 50.0, 1.0 / 50.0, 1.0])
    L = (np.linalg.inv(Tw).T @ np.asarray(pitch_lines, float).reshape(-1, 3).T).T
    X = (Tw @ np.column_stack([np.asarray(pitch_points, float).reshape(-1, 2), np.ones(len(pitch_points))]).T).T
    rows = _rows((np.linalg.inv(_GENERIC).T @ L.T).T, L, (_GENERIC @ X.T).T, X)
    if len(rows) < 8:
        return False
    s = np.linalg.svd(rows, compute_uv=False)
    return bool(s[7] > 1e-9 * s[0])


def line_homography(image_lines: np.ndarray, pitch_lines: np.ndarray, image_points: np.ndarray,
                    pitch_points: np.ndarray, width: int) -> np.ndarray:
    """The homography ``H`` (3x3, pitch metres (x, y, 1) -> pixels) that maps each pitch line
    (K, 3) onto its image line (K, 3) and each pitch point (P, 2) onto its image point (P, 2), in
    the least-squares sense of the linear equations, both sides normalised; the caller checks
    that they fix it (:func:`determined`)."""
    Ti = np.array([[2.0 / width, 0.0, -1.0], [0.0, 2.0 / width, 0.0], [0.0, 0.0, 1.0]])
    Tw = np.diag([1.0 / 50.0, 1.0 / 50.0, 1.0])

    def points(p: np.ndarray, T: np.ndarray) -> np.ndarray:
        p = np.asarray(p, float).reshape(-1, 2)
        return (T @ np.column_stack([p, np.ones(len(p))]).T).T

    rows = _rows((np.linalg.inv(Ti).T @ np.asarray(image_lines, float).reshape(-1, 3).T).T,
                 (np.linalg.inv(Tw).T @ np.asarray(pitch_lines, float).reshape(-1, 3).T).T,
                 points(image_points, Ti), points(pitch_points, Tw))
    Hn = np.linalg.svd(rows)[2][-1].reshape(3, 3)
    return np.linalg.inv(Ti) @ Hn @ Tw


def _cross_matrix(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def line_sets(obs: Observations, model: FieldModel, min_span: float) -> list[tuple[np.ndarray, list[str], np.ndarray]]:
    """The homographies to start from (pitch metres -> pixels), each with the line classes and
    the keypoints (indices) it was solved from: every ground line and ground keypoint that is not
    derived from the lines (``Observations.derived``: it repeats them), then each such set with
    one of them left out, each when it can fix the plane. ``min_span``: px a line's points must
    span (:data:`MIN_SPAN_PX` at 960 px width, scaled with the frame)."""
    lines = ground_lines(obs, model, min_span)
    if not lines:
        return []
    on_ground = np.flatnonzero((np.abs(obs.kp_xyz[:, 2]) < 1e-9) & ~obs.derived) if obs.n_keypoints else np.zeros(0, int)
    names = list(lines)
    items = [("line", n) for n in names] + [("point", int(k)) for k in on_ground]
    out = []
    for drop in [None] + (items if len(items) >= 5 else []):
        keep = [n for n in names if drop != ("line", n)]
        pts = [k for k in on_ground if drop != ("point", int(k))]
        if len(keep) + len(pts) < 4 or not determined(np.array([lines[n][1] for n in keep]), obs.kp_xyz[pts, :2]):
            continue
        H = line_homography(np.array([lines[n][0] for n in keep]), np.array([lines[n][1] for n in keep]),
                            obs.kp_xy[pts], obs.kp_xyz[pts, :2], obs.width)
        out.append((H, keep, np.asarray(pts, int)))
    return out
