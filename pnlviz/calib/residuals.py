"""The residual blocks of every refinement: keypoints, line segments and circles, each with its
analytic Jacobian. A block knows nothing of the model (camera or homography): the model hands it
the images of the model points and their derivatives with respect to its P parameters.

All distances are pixels. ``J`` arrays have one row per residual and one column per parameter.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from pnlviz.geometry.distance import closest
from pnlviz.geometry.so3 import cross


class Block(NamedTuple):
    """Residuals (n,) and, when asked, their Jacobian (n, P)."""

    r: np.ndarray
    J: np.ndarray | None


def point_block(uv: np.ndarray, J_uv: np.ndarray | None, xy: np.ndarray) -> Block:
    """Keypoints: ``uv - xy`` for projections ``uv`` (N, 2) and observations ``xy`` (N, 2),
    2 residuals per point (x then y); ``J_uv`` (N, 2, P)."""
    r = (uv - xy).ravel()
    return Block(r, None if J_uv is None else J_uv.reshape(len(r), -1))


class SegmentJacobian(NamedTuple):
    """What :func:`segment_block` needs for its Jacobian, as vector-Jacobian products (cheaper
    than the Jacobians themselves: each residual is a scalar function of a few 3-vectors)."""

    #: ``(ga, gb)``, each (n, 3) for n = 2 N rows (the N points twice: perpendicular, overshoot)
    #: -> ``ga^T dA/dparams + gb^T dB/dparams`` (n, P)
    ends_vjp: Callable[[np.ndarray, np.ndarray], np.ndarray]
    #: ``g`` (2 N, 2) -> ``g^T dq/dparams`` (2 N, P); None when the observed points are fixed
    q_vjp: Callable[[np.ndarray], np.ndarray] | None
    #: the parameter that is log(scale), None when the scale is fixed
    log_scale: int | None


def segment_block(A: np.ndarray, B: np.ndarray, q: np.ndarray, scale: float, min_depth: float,
                  jac: SegmentJacobian | None = None) -> tuple[Block, Block]:
    """Distance of observed points ``q`` (N, 2) to the images of model segments whose ends are the
    homogeneous points ``A``, ``B`` (N, 3) (``q`` lives where ``A / A_z`` does), in pixels
    (``scale``: pixels per unit of that space, one or (N,)). Two blocks of N residuals:

    * perpendicular: the signed distance to the image line ``l = A x B``. ``l`` stays right when
      an end lies behind the camera (it is the plane through the centre and the 3D line), so no
      clipping is needed;
    * overshoot: how far a point lies beyond the segment's ends along the line (0 between them),
      only when both ends are in front (``A_z, B_z > min_depth``), so that
      ``sqrt(perp^2 + over^2)`` is the distance to the segment, as the SoccerNet evaluator
      measures it.
    """
    l = cross(A, B)
    nrm = np.maximum(np.sqrt(l[:, 0] ** 2 + l[:, 1] ** 2), 1e-300)
    lq = l[:, 0] * q[:, 0] + l[:, 1] * q[:, 1] + l[:, 2]
    perp = scale * lq / nrm
    front = (A[:, 2] > min_depth) & (B[:, 2] > min_depth)
    az, bz = np.where(front, A[:, 2], 1.0), np.where(front, B[:, 2], 1.0)
    pa, pb = A[:, :2] / az[:, None], B[:, :2] / bz[:, None]
    v = pb - pa
    L = np.maximum(np.sqrt(v[:, 0] ** 2 + v[:, 1] ** 2), 1e-12)
    u = v / L[:, None]
    w = q - pa
    s = w[:, 0] * u[:, 0] + w[:, 1] * u[:, 1]
    before, after = front & (s < 0), front & (s > L)
    over = scale * np.where(before, -s, np.where(after, s - L, 0.0))
    if jac is None:
        return Block(perp, None), Block(over, None)
    n = len(A)
    ga, gb, gq = np.empty((2 * n, 3)), np.empty((2 * n, 3)), np.empty((2 * n, 2))
    # perpendicular: g = d(lq / |l_12|)/dl, through l = A x B: g.dl = (B x g).dA + (g x A).dB
    k = lq / nrm**3
    g = np.empty_like(l)
    g[:, 0] = q[:, 0] / nrm - k * l[:, 0]
    g[:, 1] = q[:, 1] / nrm - k * l[:, 1]
    g[:, 2] = 1 / nrm
    ga[:n], gb[:n], gq[:n] = cross(B, g), cross(g, A), l[:, :2] / nrm[:, None]
    # overshoot (zero rows between the ends): with s = (q - pa) . u, ds/dpa = -u - P w / L and
    # ds/dpb = P w / L (P = I - u u^T); the L of (s - L) adds dL/dpb = u, dL/dpa = -u; then
    # through pa = A_xy / A_z; over = sign (q - pa) . u (+ const) gives d/dq = sign u
    sign = np.where(before, -1.0, np.where(after, 1.0, 0.0))[:, None]
    aft = after.astype(float)[:, None]
    Pw = w - s[:, None] * u
    ga[n:] = _through_dehom(sign * (-u - Pw / L[:, None]) + aft * u, A, az)
    gb[n:] = _through_dehom(sign * (Pw / L[:, None]) - aft * u, B, bz)
    gq[n:] = sign * u
    sc = np.asarray(scale, float)  # one scale, or one per point (the frames of a shot)
    s2 = sc if sc.ndim == 0 else np.concatenate([sc, sc])[:, None]
    J = s2 * jac.ends_vjp(ga, gb)
    if jac.q_vjp is not None:
        J += s2 * jac.q_vjp(gq)
    if jac.log_scale is not None:
        J[:n, jac.log_scale] += perp
        J[n:, jac.log_scale] += over
    return Block(perp, J[:n]), Block(over, J[n:])


def _through_dehom(g: np.ndarray, P: np.ndarray, z: np.ndarray) -> np.ndarray:
    """``g^T d(x/z, y/z)/d(x, y, z)`` (n, 3) for row vectors ``g`` (n, 2) at points ``P`` (n, 3)."""
    out = np.empty((len(P), 3))
    out[:, 0] = g[:, 0] / z
    out[:, 1] = g[:, 1] / z
    out[:, 2] = -(g[:, 0] * P[:, 0] + g[:, 1] * P[:, 1]) / (z * z)
    return out


def polyline_block(poly: np.ndarray, pts: np.ndarray,
                   vertex_jacobian: Callable[[np.ndarray], np.ndarray] | None = None) -> Block:
    """Distance of observed points ``pts`` (M, 2) to a projected polyline ``poly`` (S, 2), one
    residual per point. ``vertex_jacobian(indices)`` gives d(vertex)/d(params) (n, 2, P) of the
    vertices asked for (only the ends of the closest segments are, each once per point)."""
    c = closest(pts, poly)
    if vertex_jacobian is None:
        return Block(c.distance, None)
    m = len(pts)
    Jv = vertex_jacobian(np.concatenate([c.segment, c.segment + 1]))
    unit = c.offset / np.maximum(c.distance, 1e-12)[:, None]  # d(dist)/d(closest point) = -unit
    Jc = (1 - c.t)[:, None, None] * Jv[:m] + c.t[:, None, None] * Jv[m:]
    return Block(c.distance, -(unit[:, 0, None] * Jc[:, 0] + unit[:, 1, None] * Jc[:, 1]))
