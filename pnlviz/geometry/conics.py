"""Conics in the image: ellipse fitting, line/ellipse intersections and tangent points.

A conic is kept as its symmetric 3x3 matrix ``Q`` (``x^T Q x = 0`` for homogeneous image points
``x = (u, v, 1)``), which makes every operation below a line of linear algebra:

* the line through two points is their cross product, two lines meet at their cross product;
* the tangents from an external point ``e`` touch the conic where the polar line ``Q e`` meets it.

The ellipse fit is the direct least-squares method of Fitzgibbon et al. in the numerically stable
form of Halir & Flusser (1998), on normalised coordinates (centred and scaled to unit RMS radius),
which keeps it well conditioned for the pixel coordinates of a broadcast frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pnlviz.geometry.shapes import as_array, as_points


class ConicError(ValueError):
    """Raised when no ellipse fits the points (too few or degenerate points)."""


def line_through(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Homogeneous line through two 2D points."""
    return np.cross(np.append(np.asarray(p, float)[:2], 1.0), np.append(np.asarray(q, float)[:2], 1.0))


def fit_line(points: np.ndarray) -> np.ndarray:
    """Total-least-squares homogeneous line (a, b, c), a^2 + b^2 = 1, through 2D points (N >= 2, 2)
    (another shape: ArgumentError)."""
    pts = as_points(points, 2, "points")
    mean = pts.mean(axis=0)
    _, _, vt = np.linalg.svd(pts - mean, full_matrices=False)
    normal = vt[-1]
    return np.array([normal[0], normal[1], -normal @ mean])


def intersect_lines(l1: np.ndarray, l2: np.ndarray) -> np.ndarray | None:
    """Intersection of two homogeneous lines (3,) as a 2D point, or None when they are parallel."""
    x = np.cross(as_array(l1, (3,), "l1"), as_array(l2, (3,), "l2"))
    if abs(x[2]) < 1e-12 * max(1.0, np.abs(x[:2]).max()):
        return None
    return x[:2] / x[2]


@dataclass(frozen=True)
class Conic:
    Q: np.ndarray  # symmetric 3x3

    @classmethod
    def from_coeffs(cls, a, b, c, d, e, f) -> "Conic":
        """From ``a u^2 + b uv + c v^2 + d u + e v + f = 0``."""
        return cls(np.array([[a, b / 2, d / 2], [b / 2, c, e / 2], [d / 2, e / 2, f]], dtype=float))

    @classmethod
    def from_ellipse(cls, center, axes, angle_rad: float) -> "Conic":
        """From centre (u, v), semi-axes (a, b) and the angle of the first axis."""
        cu, cv = center
        A, B = axes
        c, s = np.cos(angle_rad), np.sin(angle_rad)
        # x^T Q x with x expressed in the ellipse frame: (R^T (x - c))^2 / diag(A^2, B^2) = 1
        M = np.array([[c, s], [-s, c]])
        D = np.diag([1 / A**2, 1 / B**2])
        Q2 = M.T @ D @ M
        ctr = np.array([cu, cv])
        Q = np.zeros((3, 3))
        Q[:2, :2] = Q2
        Q[:2, 2] = Q[2, :2] = -Q2 @ ctr
        Q[2, 2] = ctr @ Q2 @ ctr - 1
        return cls(Q)

    @property
    def is_ellipse(self) -> bool:
        Q = self.Q
        return bool(Q[0, 0] * Q[1, 1] - Q[0, 1] ** 2 > 0)

    def ellipse_params(self) -> tuple[np.ndarray, np.ndarray, float]:
        """Centre (2,), semi-axes (2,) and angle of the first axis (radians)."""
        if not self.is_ellipse:
            raise ConicError("conic is not an ellipse")
        Q2, q = self.Q[:2, :2], self.Q[:2, 2]
        center = np.linalg.solve(Q2, -q)
        k = -(center @ q + self.Q[2, 2])  # value so that (x-c)^T Q2 (x-c) = k
        w, V = np.linalg.eigh(Q2 / k)
        if np.any(w <= 0):
            raise ConicError("conic is an imaginary ellipse")
        axes = 1 / np.sqrt(w)
        return center, axes, float(np.arctan2(V[1, 0], V[0, 0]))

    def residuals(self, pts: np.ndarray) -> np.ndarray:
        """Algebraic residual ``x^T Q x`` of 2D points (N, 2)."""
        X = np.hstack([np.asarray(pts, float).reshape(-1, 2), np.ones((len(pts), 1))])
        return np.einsum("ni,ij,nj->n", X, self.Q, X)

    def sample(self, n: int = 100) -> np.ndarray:
        """n points (n, 2) along an ellipse."""
        center, axes, ang = self.ellipse_params()
        t = np.linspace(0, 2 * np.pi, n, endpoint=False)
        c, s = np.cos(ang), np.sin(ang)
        pts = np.stack([axes[0] * np.cos(t), axes[1] * np.sin(t)], axis=1)
        return pts @ np.array([[c, s], [-s, c]]) + center

    def intersect_line(self, line: np.ndarray) -> np.ndarray:
        """Real intersections (0, 1 or 2 points, shape (k, 2)) with a homogeneous line."""
        a, b, c = np.asarray(line, float)
        nrm = a * a + b * b
        if nrm == 0:
            return np.zeros((0, 2))
        p0 = np.array([-a * c / nrm, -b * c / nrm, 1.0])  # foot of the origin on the line
        d = np.array([-b, a, 0.0])
        qa, qb, qc = d @ self.Q @ d, 2 * d @ self.Q @ p0, p0 @ self.Q @ p0
        scale = max(abs(qa), abs(qb), abs(qc))
        if scale == 0:
            return np.zeros((0, 2))
        qa, qb, qc = qa / scale, qb / scale, qc / scale
        if abs(qa) < 1e-15:
            ts = [] if abs(qb) < 1e-15 else [-qc / qb]
        else:
            disc = qb * qb - 4 * qa * qc
            if disc < 0:
                return np.zeros((0, 2))
            r = np.sqrt(disc)
            # numerically stable roots
            q = -0.5 * (qb + np.copysign(r, qb))
            ts = [q / qa, qc / q] if q != 0 else [0.0]
        pts = np.array([(p0 + t * d)[:2] for t in ts])
        return pts.reshape(-1, 2)

    def polar(self, point: np.ndarray) -> np.ndarray:
        return self.Q @ np.append(np.asarray(point, float)[:2], 1.0)

    def tangent_points(self, external: np.ndarray) -> np.ndarray:
        """The points where the two tangents from ``external`` touch the conic, (k, 2); empty when
        the point lies inside."""
        return self.intersect_line(self.polar(external))


def fit_ellipse(points: np.ndarray) -> Conic:
    """Direct least-squares ellipse through >= 5 points (N, 2) (Halir & Flusser). Raises
    ConicError; another shape: ArgumentError."""
    pts = as_points(points, 2, "points")
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    if len(pts) < 5:
        raise ConicError(f"an ellipse needs at least 5 points, got {len(pts)}")
    mean = pts.mean(axis=0)
    scale = np.sqrt(np.mean(np.sum((pts - mean) ** 2, axis=1)))
    if scale == 0:
        raise ConicError("all points coincide")
    x, y = ((pts - mean) / scale).T
    D1 = np.stack([x * x, x * y, y * y], axis=1)
    D2 = np.stack([x, y, np.ones_like(x)], axis=1)
    S1, S2, S3 = D1.T @ D1, D1.T @ D2, D2.T @ D2
    try:
        T = -np.linalg.solve(S3, S2.T)
    except np.linalg.LinAlgError as exc:
        raise ConicError("degenerate points (collinear?)") from exc
    M = S1 + S2 @ T
    M = np.array([M[2] / 2, -M[1], M[0] / 2])  # C1^-1 M with C1 the ellipse constraint 4ac - b^2
    w, V = np.linalg.eig(M)
    V = np.real(V)
    cond = 4 * V[0] * V[2] - V[1] ** 2
    ok = np.flatnonzero(cond > 0)
    if len(ok) == 0:
        raise ConicError("no ellipse fits these points")
    a1 = V[:, ok[0]]
    a = np.concatenate([a1, T @ a1])
    # undo the normalisation: u = s x + m  =>  x = (u - m) / s
    N = np.array([[1 / scale, 0, -mean[0] / scale], [0, 1 / scale, -mean[1] / scale], [0, 0, 1]])
    Qn = Conic.from_coeffs(*a).Q
    Q = N.T @ Qn @ N
    return Conic(Q / np.linalg.norm(Q))
