"""Planar homographies: applying them, and the WC14 template <-> field <-> image chain."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from pnlviz.geometry.shapes import as_array, as_points

if TYPE_CHECKING:  # imported at run time inside the function (camera imports this module's room)
    from pnlviz.geometry.camera import Camera


def apply_homography(H: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Map 2D points (N, 2) through a homography ``H`` (3, 3); points mapped to infinity become
    NaN. Other shapes: ArgumentError naming the argument."""
    pts = as_points(pts, 2, "pts")
    h = np.hstack([pts, np.ones((len(pts), 1))]) @ as_array(H, (3, 3), "H").T
    with np.errstate(divide="ignore", invalid="ignore"):
        out = h[:, :2] / h[:, 2:]
    out[np.abs(h[:, 2]) < 1e-15] = np.nan
    return out


def normalize_homography(H: np.ndarray) -> np.ndarray:
    """``H`` (3, 3) scaled so that its Frobenius norm is 1 and H[2, 2] >= 0 (a canonical
    representative)."""
    H = as_array(H, (3, 3), "H")
    H = H / np.linalg.norm(H)
    return -H if H[2, 2] < 0 else H


def field_to_image_from_template(H_template: np.ndarray, template_to_field: np.ndarray) -> np.ndarray:
    """A WC14 homography (template yards -> image) as a field-metres -> image homography."""
    return np.asarray(H_template, float) @ np.linalg.inv(template_to_field)


def nearest_rotation(r1: np.ndarray, r2: np.ndarray) -> np.ndarray:
    """The rotation matrix nearest (Frobenius) to ``[r1, r2, r1 x r2]`` for unit vectors r1, r2
    (3,) not parallel: the polar factor ``M (M^T M)^(-1/2)``, in closed form since ``M^T M`` is
    ``[[1, c, 0], [c, 1, 0], [0, 0, 1 - c^2]]`` with ``c = r1 . r2`` (what an SVD gives, without one).

    >>> R = nearest_rotation(np.array([1.0, 0.0, 0.0]), np.array([0.1, 1.0, 0.0]) / np.hypot(0.1, 1.0))
    >>> bool(np.allclose(R @ R.T, np.eye(3)) and np.isclose(np.linalg.det(R), 1.0))
    True
    """
    c = float(r1[0] * r2[0] + r1[1] * r2[1] + r1[2] * r2[2])
    a, b = 1 / math.sqrt(1 + c), 1 / math.sqrt(1 - c)
    R = np.empty((3, 3))
    R[:, 0] = 0.5 * ((a + b) * r1 + (a - b) * r2)
    R[:, 1] = 0.5 * ((a - b) * r1 + (a + b) * r2)
    n = math.sqrt((1 + c) * (1 - c))
    R[0, 2] = (r1[1] * r2[2] - r1[2] * r2[1]) / n
    R[1, 2] = (r1[2] * r2[0] - r1[0] * r2[2]) / n
    R[2, 2] = (r1[0] * r2[1] - r1[1] * r2[0]) / n
    return R


def camera_from_ground_homography(H_field_to_image: np.ndarray, width: float, height: float, *,
                                  refine: bool = False) -> Camera | None:
    """The pinhole camera whose ground-plane homography (field metres (X, Y, 1) at z = 0 ->
    pixels) is ``H_field_to_image``, for a ``width`` x ``height`` image; None when degenerate.

    Model: square pixels, zero skew, principal point at the image centre, no distortion, so
    ``H ~ K [r1 r2 t]`` with ``K = [[f, 0, W/2], [0, f, H/2], [0, 0, 1]]``. Writing ``A`` for H
    with the principal point moved to the origin, the columns ``b_i = diag(1/f, 1/f, 1) a_i`` of
    ``K^-1 H`` must be orthogonal and of equal norm. Both constraints are linear in ``u = 1/f^2``;
    ``u`` is their least-squares solution (the two equations are weighted after scaling ``A`` to
    unit norm) and must be positive. The rotation columns are the normalised ``b1, b2`` with
    ``r3 = r1 x r2``, projected onto SO(3) by SVD; ``t = b3 / sqrt(|b1| |b2|)`` and
    ``C = -R^T t``. H is known up to sign: flipping it keeps ``C_x, C_y`` and flips ``C_z``, so
    the sign with the camera above the pitch (``C_z < 0``, z pointing down) is taken, which puts
    the visible pitch in front of the camera.

    A homography has 8 degrees of freedom and this camera 7, so a measured homography (e.g. a
    hand-annotated WC14 one) is not exactly a camera's: the closed form then spreads the mismatch
    unevenly; ``refine=True`` polishes f, R and C against ``H`` (:func:`_refine_to_homography`).
    """
    from pnlviz.geometry.camera import Camera

    H = as_array(H_field_to_image, (3, 3), "H_field_to_image")
    if not np.all(np.isfinite(H)):
        return None
    cx, cy = width / 2.0, height / 2.0
    A = np.array([[1.0, 0.0, -cx], [0.0, 1.0, -cy], [0.0, 0.0, 1.0]]) @ H
    norm = np.linalg.norm(A)
    if not norm > 0:
        return None
    A = A / norm
    a1, a2 = A[:, 0], A[:, 1]
    # orthogonality:   u (a1x a2x + a1y a2y) + a1z a2z = 0
    # equal norms:     u (a1x^2 + a1y^2 - a2x^2 - a2y^2) + a1z^2 - a2z^2 = 0
    p = np.array([a1[0] * a2[0] + a1[1] * a2[1], a1[0] ** 2 + a1[1] ** 2 - a2[0] ** 2 - a2[1] ** 2])
    q = np.array([a1[2] * a2[2], a1[2] ** 2 - a2[2] ** 2])
    pp = float(p @ p)
    if not pp > 1e-24:
        return None
    u = -float(p @ q) / pp
    if not (u > 0 and np.isfinite(u)):
        return None
    f = 1.0 / np.sqrt(u)
    B = A * np.array([[1.0 / f], [1.0 / f], [1.0]])
    n1, n2 = np.linalg.norm(B[:, 0]), np.linalg.norm(B[:, 1])
    if not (n1 > 0 and n2 > 0):
        return None
    R = nearest_rotation(B[:, 0] / n1, B[:, 1] / n2)
    t = B[:, 2] / np.sqrt(n1 * n2)
    C = -R.T @ t
    if C[2] > 0:  # the other sign of H: r1, r2 and t change sign, r3 does not
        R, t = R * np.array([-1.0, -1.0, 1.0]), -t
        C = -R.T @ t
    if not (np.all(np.isfinite(C)) and C[2] < 0):
        return None
    if refine:
        f, R, C = _refine_to_homography(H, f, R, C, width, height)
    return Camera(f, f, cx, cy, R, C, float(width), float(height))


def _refine_to_homography(H: np.ndarray, f: float, R: np.ndarray, C: np.ndarray, width: float, height: float):
    """``(f, R, C)`` refined by nonlinear least squares on the image distance between ``H`` and the
    camera over a 16 x 9 grid of pixels whose back-projection through ``H`` lies in front of the
    camera (unchanged when fewer than 4 do, or when the solver fails)."""
    import cv2
    from scipy.optimize import least_squares

    cx, cy = width / 2.0, height / 2.0
    # ground points seen at a grid of pixels, through H (the sign of H is irrelevant here)
    gu, gv = np.meshgrid(np.linspace(0, width, 16), np.linspace(0, height, 9))
    uv = np.stack([gu.ravel(), gv.ravel()], axis=1)
    X = apply_homography(np.linalg.inv(H), uv)
    Xc = (np.hstack([X, np.zeros((len(X), 1))]) - C) @ R.T
    keep = np.isfinite(X).all(axis=1) & (Xc[:, 2] > 0)
    if keep.sum() < 4:
        return f, R, C
    X, uv = X[keep], uv[keep]
    scale = max(width, height)

    def residuals(p):
        Rk = cv2.Rodrigues(p[1:4])[0] @ R
        xc = (np.hstack([X, np.zeros((len(X), 1))]) - p[4:7]) @ Rk.T
        fk = f * np.exp(p[0])
        return (np.stack([fk * xc[:, 0] / xc[:, 2] + cx, fk * xc[:, 1] / xc[:, 2] + cy], 1) - uv).ravel() / scale

    sol = least_squares(residuals, np.r_[0.0, 0.0, 0.0, 0.0, C], x_scale=np.r_[1e-2, 1e-2, 1e-2, 1e-2, 1.0, 1.0, 1.0])
    if sol.success and np.all(np.isfinite(sol.x)) and sol.x[6] < 0:
        return f * np.exp(sol.x[0]), cv2.Rodrigues(sol.x[1:4])[0] @ R, sol.x[4:7]
    return f, R, C
