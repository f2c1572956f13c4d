"""Small numerical helpers for label generation: total-least-squares lines, ground homographies
(fit, projection, degeneracy and orientation checks) and the cross-product orientation test.

Orientation convention (paper Sec. III-A, "Keypoint Disambiguation", last step). The SoccerNet
world frame is right-handed with z pointing *down*, and every broadcast camera sits above the
ground (C_z < 0). For the ground homography ``H = K [r1 r2 t]`` (world (X, Y, 1) -> image) of such
a camera, ``det [r1 r2 t] = r3 . t = -C_z > 0``, and the depth ``w`` of every point in front of the
camera is positive, so the image triangle of three ground points has the orientation
``sign(det H) * sign(det[X1 X2 X3]) / (w1 w2 w3)`` = the orientation of the world triangle in
(X, Y). In words: with image axes u right / v down and world axes X / Y, a camera above the
ground *keeps* the sign of every cross product, whichever side of the pitch it stands on (from
the main side, +X is image right and +Y image down; from the opposite side both flip, a 180 degree
rotation, orientation kept). A labelling whose homography flips the sign is the mirror image of a
real view, i.e. the "bottom view" the paper rejects. ``tests/test_labels.py`` checks this with
synthetic cameras on both sides.
"""

from __future__ import annotations

import itertools

import cv2
import numpy as np


# ----------------------------------------------------------------------------------- lines
def fit_line(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Total least squares line through 2D points (N >= 2): ``(line, centroid, direction)`` with
    the homogeneous line ``(a, b, c)`` normalised so that ``a^2 + b^2 = 1`` (then ``l . (u, v, 1)``
    is the signed distance in pixels), or None when the points do not define a line."""
    pts = np.asarray(points, float).reshape(-1, 2)
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    if len(pts) < 2:
        return None
    c = pts.mean(axis=0)
    centred = pts - c
    _, s, vt = np.linalg.svd(centred, full_matrices=False)
    if s[0] < 1e-9:
        return None
    d = vt[0]
    n = np.array([-d[1], d[0]])
    return np.array([n[0], n[1], -n @ c]), c, d


def intersect(l1: np.ndarray, l2: np.ndarray, min_sin: float = 1e-6) -> np.ndarray | None:
    """Intersection of two normalised homogeneous lines, None when (nearly) parallel."""
    x = np.cross(l1, l2)
    if abs(x[2]) < min_sin:  # |x[2]| = |sin(angle)| for normalised lines
        return None
    return x[:2] / x[2]


# ----------------------------------------------------------------------------- homographies
def project_h(H: np.ndarray, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Map world (X, Y) points (N, 2) through ``H``: image points (N, 2) and their ``w`` (N,)."""
    xy = np.asarray(xy, float).reshape(-1, 2)
    X = np.hstack([xy, np.ones((len(xy), 1))]) @ np.asarray(H, float).T
    with np.errstate(divide="ignore", invalid="ignore"):
        return X[:, :2] / X[:, 2:3], X[:, 2]


def _normalizer(pts: np.ndarray) -> np.ndarray:
    c = pts.mean(axis=0)
    s = np.sqrt(np.mean(np.sum((pts - c) ** 2, axis=1)))
    s = np.sqrt(2) / s if s > 0 else 1.0
    return np.array([[s, 0, -s * c[0]], [0, s, -s * c[1]], [0, 0, 1.0]])


def homography_condition(world_xy: np.ndarray, img: np.ndarray) -> float:
    """How well the correspondences determine a homography: ``s8 / s1`` of the Hartley-normalised
    DLT matrix (second-smallest over largest singular value). ~0 when the points are degenerate
    (fewer than 4, or all on one line); > 1e-3 for a well spread set."""
    world_xy = np.asarray(world_xy, float).reshape(-1, 2)
    img = np.asarray(img, float).reshape(-1, 2)
    n = len(world_xy)
    if n < 4:
        return 0.0
    Tw, Ti = _normalizer(world_xy), _normalizer(img)
    a = np.hstack([world_xy, np.ones((n, 1))]) @ Tw.T
    b = np.hstack([img, np.ones((n, 1))]) @ Ti.T
    A = np.zeros((2 * n, 9))
    A[0::2, 3:6] = -a
    A[0::2, 6:9] = b[:, 1:2] * a
    A[1::2, 0:3] = a
    A[1::2, 6:9] = -b[:, 0:1] * a
    s = np.linalg.svd(A, compute_uv=False)
    if len(s) < 9:  # 4 points: 8 rows, 8 singular values; the null space is the 9th
        s = np.concatenate([s, np.zeros(9 - len(s))])
    return float(s[7] / s[0]) if s[0] > 0 else 0.0


def max_collinear(world_xy: np.ndarray, tol: float = 0.05) -> int:
    """Size of the largest subset of the points lying on one line (within ``tol``)."""
    P = np.asarray(world_xy, float).reshape(-1, 2)
    n = len(P)
    if n <= 2:
        return n
    i, j = np.triu_indices(n, 1)
    d = P[j] - P[i]
    norm = np.linalg.norm(d, axis=1)
    ok = norm > tol
    if not ok.any():
        return n
    i, d, norm = i[ok], d[ok], norm[ok]
    rel = P[None, :, :] - P[i][:, None, :]  # (pairs, n, 2)
    dist = np.abs(d[:, None, 0] * rel[:, :, 1] - d[:, None, 1] * rel[:, :, 0]) / norm[:, None]
    return int((dist <= tol).sum(axis=1).max())


def fit_homography(world_xy: np.ndarray, img: np.ndarray, *, min_condition: float = 1e-4) -> np.ndarray | None:
    """Least-squares ground homography world (X, Y) -> image (``cv2.findHomography``, method 0:
    DLT then Levenberg-Marquardt on the reprojection error), normalised so that ``w > 0`` for the
    majority of the given points and the Frobenius norm is 1.

    None when the points cannot determine it: fewer than 4, fewer than 2 points off the world
    line holding most of them (exact catalogue coordinates make this test exact: 4 points on a
    side line plus one elsewhere fit any noise), a near-singular DLT, or an OpenCV failure."""
    world_xy = np.asarray(world_xy, float).reshape(-1, 2)
    img = np.asarray(img, float).reshape(-1, 2)
    n = len(world_xy)
    if n < 4 or n - max_collinear(world_xy) < 2 or homography_condition(world_xy, img) < min_condition:
        return None
    H, _ = cv2.findHomography(world_xy.astype(np.float64), img.astype(np.float64), 0)
    if H is None or not np.all(np.isfinite(H)):
        return None
    H = H / np.linalg.norm(H)
    _, w = project_h(H, world_xy)
    if np.sum(w > 0) < np.sum(w < 0):
        H = -H
    return H


def reprojection_errors(H: np.ndarray, world_xy: np.ndarray, img: np.ndarray) -> np.ndarray:
    """Pixel distance between ``H(world)`` and ``img`` per point (inf behind the camera)."""
    proj, w = project_h(H, world_xy)
    err = np.linalg.norm(proj - np.asarray(img, float).reshape(-1, 2), axis=1)
    return np.where(w > 0, err, np.inf)


def orientation_ok(H: np.ndarray, world_xy: np.ndarray) -> bool:
    """True when ``H`` is the homography of a camera above the ground for these points: every
    point in front (``w > 0`` after :func:`fit_homography`'s normalisation) and ``det H > 0``
    (orientation kept, see the module docstring)."""
    _, w = project_h(H, world_xy)
    return bool(np.all(w > 0) and np.linalg.det(H) > 0)


def orientation_outliers(world_xy: np.ndarray, img: np.ndarray, *, min_sin: float = 0.05,
                         min_world_side: float = 1.0) -> list[int]:
    """The paper's cross-product check: over every triple of ground points whose world and image
    triangles are both well shaped (each corner angle's sine >= ``min_sin`` and the world sides
    >= ``min_world_side`` metres), the sign of ``(b - a) x (c - a)`` must be the same in the world
    and in the image. Returns the indices to drop, greedily (the point in the most disagreeing
    triples first) until every triple agrees."""
    W = np.asarray(world_xy, float).reshape(-1, 2)
    P = np.asarray(img, float).reshape(-1, 2)
    n = len(W)
    if n < 3:
        return []
    tri = np.array(list(itertools.combinations(range(n), 3)), dtype=int).reshape(-1, 3)

    def signed(pts, require_side):
        a, b, c = pts[tri[:, 0]], pts[tri[:, 1]], pts[tri[:, 2]]
        ab, ac, bc = b - a, c - a, c - b
        cross = ab[:, 0] * ac[:, 1] - ab[:, 1] * ac[:, 0]
        la, lb, lc = (np.linalg.norm(v, axis=1) for v in (ab, ac, bc))
        with np.errstate(divide="ignore", invalid="ignore"):
            # the smallest corner sine of the triangle = |cross| / (product of its two longest sides)
            longest2 = np.sort(np.stack([la, lb, lc], axis=1), axis=1)[:, 1:].prod(axis=1)
            good = np.abs(cross) / longest2 >= min_sin
        if require_side:
            good &= np.minimum(np.minimum(la, lb), lc) >= min_world_side
        return np.sign(cross), good

    sw, gw = signed(W, True)
    si, gi = signed(P, False)
    use = gw & gi
    bad = use & (sw != si)
    dropped: list[int] = []
    alive = np.ones(n, bool)
    while True:
        active = bad & alive[tri].all(axis=1)
        if not active.any():
            return dropped
        counts = np.bincount(tri[active].ravel(), minlength=n)
        totals = np.bincount(tri[use & alive[tri].all(axis=1)].ravel(), minlength=n)
        with np.errstate(divide="ignore", invalid="ignore"):
            share = np.where(totals > 0, counts / np.maximum(totals, 1), 0.0)
        worst = int(np.lexsort((-counts, -share))[0])  # highest share, then most bad triples
        dropped.append(worst)
        alive[worst] = False


def _dlt_batch(world_xy: np.ndarray, img: np.ndarray) -> np.ndarray:
    """Hartley-normalised linear DLT for a batch of image point sets (B, N, 2) sharing the world
    points (N, 2). Returns (B, 3, 3) homographies (unnormalised scale)."""
    n = len(world_xy)
    Tw = _normalizer(world_xy)
    a = np.hstack([world_xy, np.ones((n, 1))]) @ Tw.T  # (N, 3)
    B = img.shape[0]
    Ti = np.stack([_normalizer(im) for im in img])  # (B, 3, 3)
    b = np.einsum("bij,bnj->bni", Ti, np.concatenate([img, np.ones((B, n, 1))], axis=2))
    A = np.zeros((B, 2 * n, 9))
    A[:, 0::2, 3:6] = -a * b[:, :, 2:3]
    A[:, 0::2, 6:9] = b[:, :, 1:2] * a
    A[:, 1::2, 0:3] = a * b[:, :, 2:3]
    A[:, 1::2, 6:9] = -b[:, :, 0:1] * a
    _, _, vt = np.linalg.svd(A, full_matrices=False) if 2 * n >= 9 else np.linalg.svd(A)
    h = vt[:, -1, :].reshape(B, 3, 3)
    return np.linalg.inv(Ti) @ h @ Tw


def homography_noise_gain(world_xy: np.ndarray, img: np.ndarray, targets_xy: np.ndarray) -> np.ndarray:
    """How much 1 px of independent noise on each image point moves the homography projection of
    each target world point: ``sqrt(sum_j |d proj / d img_j|^2)`` over the 2N image coordinates,
    by finite differences on the linear DLT (one batched SVD). (K,) pixels per pixel; large where
    the homography extrapolates far from its points or they are badly spread."""
    world_xy = np.asarray(world_xy, float).reshape(-1, 2)
    img = np.asarray(img, float).reshape(-1, 2)
    targets_xy = np.asarray(targets_xy, float).reshape(-1, 2)
    n = len(world_xy)
    if n < 4 or len(targets_xy) == 0:
        return np.full(len(targets_xy), np.inf)
    step = 0.5
    batch = np.repeat(img[None], 2 * n + 1, axis=0)
    j = np.arange(2 * n)
    batch[1 + j, j // 2, j % 2] += step
    Hs = _dlt_batch(world_xy, batch)
    X = np.hstack([targets_xy, np.ones((len(targets_xy), 1))])
    P = np.einsum("bij,kj->bki", Hs, X)
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = P[:, :, :2] / P[:, :, 2:3]
    d = (uv[1:] - uv[0][None]) / step  # (2N, K, 2)
    gain = np.sqrt(np.sum(d ** 2, axis=(0, 2)))
    return np.where(np.isfinite(gain), gain, np.inf)


# ------------------------------------------------------------------------- conic sensitivity
def fit_ellipse_batch(points: np.ndarray) -> np.ndarray:
    """Halir-Flusser direct ellipse fit of a batch of point sets (B, N, 2) -> conic matrices
    (B, 3, 3) (NaN where no ellipse fits). The same algorithm as
    :func:`pnlviz.geometry.conics.fit_ellipse`, vectorised over the batch: used to estimate how
    sensitive ellipse-derived keypoints are to annotation noise (finite differences)."""
    pts = np.asarray(points, float)
    B, n, _ = pts.shape
    mean = pts.mean(axis=1, keepdims=True)
    scale = np.sqrt(np.mean(np.sum((pts - mean) ** 2, axis=2), axis=1))[:, None, None]
    q = (pts - mean) / scale
    x, y = q[..., 0], q[..., 1]
    D1 = np.stack([x * x, x * y, y * y], axis=2)
    D2 = np.stack([x, y, np.ones_like(x)], axis=2)
    S1 = np.einsum("bni,bnj->bij", D1, D1)
    S2 = np.einsum("bni,bnj->bij", D1, D2)
    S3 = np.einsum("bni,bnj->bij", D2, D2)
    out = np.full((B, 3, 3), np.nan)
    try:
        T = -np.linalg.solve(S3, np.swapaxes(S2, 1, 2))
    except np.linalg.LinAlgError:
        return out
    M = S1 + S2 @ T
    M = np.stack([M[:, 2] / 2, -M[:, 1], M[:, 0] / 2], axis=1)
    _, V = np.linalg.eig(M)
    V = np.real(V)
    cond = 4 * V[:, 0, :] * V[:, 2, :] - V[:, 1, :] ** 2  # (B, 3)
    has = (cond > 0).any(axis=1)
    pick = np.argmax(cond > 0, axis=1)
    a1 = V[np.arange(B), :, pick]  # (B, 3)
    a = np.concatenate([a1, np.einsum("bij,bj->bi", T, a1)], axis=1)
    A, Bc, C, D, E, F = a.T
    Qn = np.stack([np.stack([A, Bc / 2, D / 2], -1), np.stack([Bc / 2, C, E / 2], -1),
                   np.stack([D / 2, E / 2, F], -1)], axis=1)
    s, m = scale[:, 0, 0], mean[:, 0, :]
    N = np.zeros((B, 3, 3))
    N[:, 0, 0] = N[:, 1, 1] = 1 / s
    N[:, 0, 2] = -m[:, 0] / s
    N[:, 1, 2] = -m[:, 1] / s
    N[:, 2, 2] = 1
    Q = np.swapaxes(N, 1, 2) @ Qn @ N
    Q /= np.linalg.norm(Q, axis=(1, 2), keepdims=True)
    out[has] = Q[has]
    return out


def conic_line_points(Q: np.ndarray, lines: np.ndarray) -> np.ndarray:
    """Both intersections (B, 2, 2) of conics (B, 3, 3) with lines (B, 3); NaN when not real."""
    a, b, c = lines[:, 0], lines[:, 1], lines[:, 2]
    nrm = a * a + b * b
    p0 = np.stack([-a * c / nrm, -b * c / nrm, np.ones_like(a)], axis=1)
    d = np.stack([-b, a, np.zeros_like(a)], axis=1)
    qa = np.einsum("bi,bij,bj->b", d, Q, d)
    qb = 2 * np.einsum("bi,bij,bj->b", d, Q, p0)
    qc = np.einsum("bi,bij,bj->b", p0, Q, p0)
    disc = qb * qb - 4 * qa * qc
    with np.errstate(invalid="ignore", divide="ignore"):
        r = np.sqrt(disc)
        t = np.stack([(-qb - r) / (2 * qa), (-qb + r) / (2 * qa)], axis=1)  # (B, 2)
    pts = p0[:, None, :2] + t[:, :, None] * d[:, None, :2]
    return pts


def conic_candidates_gain(points: np.ndarray, base: np.ndarray, *, line: np.ndarray | None = None,
                          external: np.ndarray | None = None, step: float = 0.5) -> np.ndarray:
    """Noise gain (2,) of the two candidates ``base`` (2, 2) of an ellipse construction: the
    intersections with ``line``, or the tangent points from ``external``. Each annotated point
    coordinate is moved by ``step`` px in turn, the ellipse refitted and the candidates recomputed;
    the gain is ``sqrt(sum |d candidate / d coordinate|^2)`` (pixels per pixel of independent noise)."""
    pts = np.asarray(points, float).reshape(-1, 2)
    n = len(pts)
    batch = np.repeat(pts[None], 2 * n, axis=0)
    j = np.arange(2 * n)
    batch[j, j // 2, j % 2] += step
    Q = fit_ellipse_batch(batch)
    if line is not None:
        lines = np.repeat(np.asarray(line, float)[None], 2 * n, axis=0)
    else:
        lines = Q @ np.append(np.asarray(external, float)[:2], 1.0)
    cand = conic_line_points(Q, lines)  # (B, 2, 2)
    base = np.asarray(base, float)
    straight = np.linalg.norm(cand - base[None], axis=2).sum(axis=1)
    swapped = np.linalg.norm(cand[:, ::-1] - base[None], axis=2).sum(axis=1)
    cand = np.where((swapped < straight)[:, None, None], cand[:, ::-1], cand)
    d = (cand - base[None]) / step
    gain = np.sqrt(np.sum(d ** 2, axis=(0, 2)))
    return np.where(np.isfinite(gain), gain, np.inf)


def fit_homography_robust(world_xy: np.ndarray, img: np.ndarray, threshold: float, *,
                          min_points: int = 6) -> tuple[np.ndarray | None, np.ndarray]:
    """Homography robust to mislabelled points: with at least ``min_points`` correspondences,
    ``cv2.findHomography`` RANSAC (OpenCV seeds its RANSAC with a constant, so the result is
    deterministic) finds the largest consensus within ``threshold`` px, then
    :func:`fit_homography` refits on it; with fewer points (no redundancy to vote with) the plain
    least-squares fit on all. Returns ``(H or None, inlier mask)``."""
    world_xy = np.asarray(world_xy, float).reshape(-1, 2)
    img = np.asarray(img, float).reshape(-1, 2)
    n = len(world_xy)
    everything = np.ones(n, bool)
    if n >= min_points and n - max_collinear(world_xy) >= 2:
        H, mask = cv2.findHomography(world_xy, img, cv2.RANSAC, float(threshold), maxIters=2000, confidence=0.999)
        if H is not None and mask is not None:
            inl = mask.ravel().astype(bool)
            if inl.sum() >= 4 and not inl.all():
                Hi = fit_homography(world_xy[inl], img[inl])
                if Hi is not None:
                    return Hi, inl
    return fit_homography(world_xy, img), everything
