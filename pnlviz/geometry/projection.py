"""Projections with their Jacobians, for the refinements in :mod:`pnlviz.calib`.

The camera is the refinements' model: ``x_cam = R (X - C)``, pixels ``u = f x g + cx``,
``v = a f y g + cy`` with ``(x, y)`` the normalised coordinates, ``g = 1 + k1 (x^2 + y^2)`` and
the aspect ``a = fy / fx`` fixed. Derivatives are taken with respect to the 8 parameters
``(dw (3), dC (3), log f, k1)``, the rotation updated on the left (``R <- exp([dw]x) R``), so the
Jacobian is always taken at ``dw = 0``. The rotation and the focal length may differ from point
to point (the frames of a shot in :mod:`pnlviz.calib.shot`); the centre and k1 are one.
"""

from __future__ import annotations

import numpy as np

from pnlviz.geometry.shapes import as_array, as_points

#: depth (metres) at which points are clamped before dividing: behind the camera they get a huge,
#: smooth residual instead of a sign flip
CLAMP_DEPTH = 1e-6
N_CAMERA_PARAMS = 8


def to_camera(X: np.ndarray, R: np.ndarray, C: np.ndarray) -> np.ndarray:
    """Camera coordinates (N, 3) of world points ``X`` (N, 3), centre ``C`` (3,); ``R`` is one
    rotation (3, 3) or one per point (N, 3, 3) (the frames of a shot, each point with its frame's).
    Other shapes: ArgumentError naming the argument.

    >>> R = np.stack([np.eye(3), np.diag([1.0, -1.0, -1.0])])
    >>> to_camera(np.array([[1.0, 2.0, 3.0], [1.0, 2.0, 3.0]]), R, np.zeros(3)).tolist()
    [[1.0, 2.0, 3.0], [1.0, -2.0, -3.0]]
    """
    X, C = as_points(X, 3, "X"), as_array(C, (3,), "C")
    if R.ndim == 3:
        return np.einsum("nij,nj->ni", as_array(R, (len(X), 3, 3), "R"), X - C)
    return (X - C) @ as_array(R, (3, 3), "R").T


def project_k1(X: np.ndarray, R: np.ndarray, C: np.ndarray, f: float, aspect: float, cx: float, cy: float,
               k1: float, jac: bool = False) -> tuple[np.ndarray, np.ndarray | None]:
    """Pixels (N, 2) of world points (N, 3) and, with ``jac``, d(pixels)/d(params) (N, 2, 8).

    >>> uv, J = project_k1(np.array([[0.0, 0.0, 10.0]]), np.eye(3), np.zeros(3), 1000.0, 1.0, 480.0, 270.0, 0.0, True)
    >>> uv.tolist(), J.shape
    ([[480.0, 270.0]], (1, 2, 8))
    """
    X, R, C = np.asarray(X, float), np.asarray(R, float), np.asarray(C, float)
    if X.ndim != 2 or X.shape[1] != 3 or R.shape != (3, 3) or C.shape != (3,):
        raise ValueError(f"project_k1: X (N, 3), R (3, 3), C (3,) expected, got {X.shape}, {R.shape}, {C.shape}")
    return camera_to_pixels(to_camera(X, R, C), R, f, aspect, cx, cy, k1, jac)


def camera_to_pixels(Xc: np.ndarray, R: np.ndarray, f: float | np.ndarray, aspect: float, cx: float, cy: float,
                     k1: float, jac: bool = False) -> tuple[np.ndarray, np.ndarray | None]:
    """:func:`project_k1` from camera coordinates ``Xc`` (N, 3) (``R`` is needed for the
    Jacobian only; another shape of ``Xc``: ArgumentError); points behind the camera are clamped to
    :data:`CLAMP_DEPTH`. ``f`` and ``R``
    may be given per point, (N,) and (N, 3, 3) (the frames of a shot).

    >>> Xc = np.array([[1.0, 0.5, 10.0], [1.0, 0.5, 10.0]])
    >>> camera_to_pixels(Xc, np.eye(3), np.array([1000.0, 2000.0]), 1.0, 480.0, 270.0, 0.0)[0].tolist()
    [[580.0, 320.0], [680.0, 370.0]]
    """
    Xc = as_points(Xc, 3, "Xc")
    z = np.maximum(Xc[:, 2], CLAMP_DEPTH)
    p = Xc[:, :2] / z[:, None]  # normalised
    xn, yn = p[:, 0], p[:, 1]
    r2 = xn * xn + yn * yn
    g = 1 + k1 * r2
    fa = f * aspect
    uv = np.empty((len(Xc), 2))
    uv[:, 0] = f * g * xn + cx
    uv[:, 1] = fa * g * yn + cy
    if not jac:
        return uv, None
    # d(normalised point)/d(dw, dC), with dXc = -[Xc]x dw - R dC (row 0 for xn, row 1 for yn):
    #   dxn/ddw = (-xn yn, zr + xn^2, -yn), dyn/ddw = (-(zr + yn^2), xn yn, xn), with zr = Xc_z / z
    #   (1 but for points clamped behind the camera); dp/dC = (p R[2] - R[:2]) / z
    n = len(Xc)
    zr, xy = Xc[:, 2] / z, xn * yn
    D = np.empty((n, 2, 6))
    D[:, 0, 0], D[:, 0, 1], D[:, 0, 2] = -xy, zr + xn * xn, -yn
    D[:, 1, 0], D[:, 1, 1], D[:, 1, 2] = -(zr + yn * yn), xy, xn
    D[:, :, 3:] = (p[:, :, None] * R[..., None, 2, :] - R[..., :2, :]) * (1.0 / z)[:, None, None]
    # then the lens and the focal length: d(pixels)/dp = diag(f, f aspect) (g I + 2 k1 p p^T)
    J = np.empty((n, 2, N_CAMERA_PARAMS))
    if k1 == 0.0:  # g = 1 and no cross term: one focal length, or one per point
        J[:, :, :6] = D * (np.array([[f], [fa]]) if np.ndim(f) == 0 else np.stack([f, fa], -1)[:, :, None])
    else:
        dx, dy, k2 = D[:, 0], D[:, 1], 2 * k1 * xy
        J[:, 0, :6] = (f * (g + 2 * k1 * xn * xn))[:, None] * dx + (f * k2)[:, None] * dy
        J[:, 1, :6] = (fa * k2)[:, None] * dx + (fa * (g + 2 * k1 * yn * yn))[:, None] * dy
    J[:, :, 6] = uv - (cx, cy)  # d/d log f
    J[:, 0, 7], J[:, 1, 7] = xn * r2 * f, yn * r2 * fa  # d/d k1
    return uv, J


def undistort_k1(pts: np.ndarray, f: float | np.ndarray, aspect: float, cx: float, cy: float, k1: float,
                 jac: bool = False) -> tuple[np.ndarray, np.ndarray | None]:
    """Undistorted normalised coordinates q (N, 2) of pixels (N, 2) and, with ``jac``,
    dq/d(log f, k1) (N, 2, 2). ``q = x_d s`` with ``s (1 + k1 |x_d|^2 s^2) = 1``, solved by 8
    fixed-point steps (k1 is small). ``f`` may be given per point (N,).

    >>> q, _ = undistort_k1(np.array([[580.0, 320.0], [680.0, 370.0]]), np.array([1000.0, 2000.0]), 1.0, 480.0, 270.0, 0.0)
    >>> q.tolist()
    [[0.1, 0.05], [0.1, 0.05]]
    """
    pts = as_points(pts, 2, "pts", "pixels")
    xd = np.empty((len(pts), 2))
    xd[:, 0] = (pts[:, 0] - cx) / f
    xd[:, 1] = (pts[:, 1] - cy) / (f * aspect)
    rd2 = xd[:, 0] * xd[:, 0] + xd[:, 1] * xd[:, 1]
    s = np.ones_like(rd2)
    if k1 != 0.0:
        c = k1 * rd2
        for _ in range(8):
            s = 1.0 / (1.0 + c * s * s)
    q = xd * s[:, None]
    if not jac:
        return q, None
    # implicit derivatives of s: F = s (1 + k1 rd2 s^2) - 1 = 0; d x_d / d log f = -x_d
    dF_ds = 1 + 3 * k1 * rd2 * s * s
    ds_drd2 = -k1 * s**3 / dF_ds
    ds_dk1 = -rd2 * s**3 / dF_ds
    Jq = np.empty((len(q), 2, 2))
    Jq[:, :, 0] = -q - (2 * rd2 * ds_drd2)[:, None] * xd
    Jq[:, :, 1] = xd * ds_dk1[:, None]
    return q, Jq


def dehomogenize(xh: np.ndarray, jac: bool = False) -> tuple[np.ndarray, np.ndarray | None]:
    """``(x / w, y / w)`` (N, 2) of homogeneous points (N, 3) and, with ``jac``, its derivative
    with respect to ``(x, y, w)`` (N, 2, 3). Another shape: ArgumentError."""
    xh = as_points(xh, 3, "xh", "homogeneous points")
    w = xh[:, 2]
    p = xh[:, :2] / w[:, None]
    if not jac:
        return p, None
    D = np.zeros((len(xh), 2, 3))
    D[:, 0, 0] = D[:, 1, 1] = 1 / w
    D[:, 0, 2] = -p[:, 0] / w
    D[:, 1, 2] = -p[:, 1] / w
    return p, D
