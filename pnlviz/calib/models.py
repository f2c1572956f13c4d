"""The two models a frame is refined with, seen by the residual blocks the same way: how model
points map into the image, with derivatives with respect to the model's parameters, and how a
step of those parameters updates the model (always linearised at the current model).

* :class:`CameraModel`: rotation, centre, focal length and radial k1 (principal point and aspect
  fixed); 8 parameters ``(dw, dC, log f, k1)``, the rotation updated on the left.
* :class:`HomographyModel`: a ground homography ``M`` in normalised field coordinates
  (``Xn = (s X, s Y, 1)``, s = 1/50 m); 8 parameters ``P`` (a 3x3 matrix without ``P[2, 2]``),
  ``M <- M (I + P)``: well scaled, and no entry of H singled out (``H[2, 2] = 1`` breaks down
  when the field origin lies near the camera's horizon line).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pnlviz.calib.residuals import SegmentJacobian
from pnlviz.geometry.camera import MIN_DEPTH, Camera
from pnlviz.geometry.projection import camera_to_pixels, dehomogenize, to_camera, undistort_k1
from pnlviz.geometry.so3 import cross, so3_exp

#: field metres -> the homography model's normalised coordinates
FIELD_SCALE = 1.0 / 50.0


@dataclass(frozen=True)
class CameraState:
    R: np.ndarray
    C: np.ndarray
    f: float
    k1: float


class CameraModel:
    """A camera as the refinements see it; pixel geometry (principal point, aspect, other
    distortion terms) from ``cam0``. ``free``: the parameters that move (indices into the 8)."""

    n_params = 8
    log_scale = 6
    min_depth = MIN_DEPTH

    def __init__(self, cam0: Camera, refine_focal: bool = True, refine_k1: bool = False, k1_bound: float = 1.0):
        self.cam0 = cam0
        self.aspect = cam0.fy / cam0.fx
        self.free = list(range(6)) + ([6] if refine_focal else []) + ([7] if refine_k1 else [])
        self.k1_bound = k1_bound

    def start(self, cam: Camera | None = None) -> CameraState:
        cam = cam or self.cam0
        return CameraState(cam.R, cam.C.copy(), cam.fx, float(cam.radial[0]))

    def camera(self, s: CameraState) -> Camera:
        c0 = self.cam0
        radial = np.array(c0.radial, float)
        radial[0] = s.k1
        return Camera(s.f, s.f * self.aspect, c0.cx, c0.cy, s.R, s.C, c0.width, c0.height, radial, c0.tangential,
                      c0.thin_prism)

    def retract(self, s: CameraState, delta: np.ndarray) -> CameraState:
        """The state after a step ``delta`` of the free parameters (focal length at most a factor
        e per step, k1 within its bound)."""
        f, k1 = s.f, s.k1
        if 6 in self.free:
            f = s.f * math.exp(min(max(float(delta[6]), -1.0), 1.0))
        if 7 in self.free:
            k1 = min(max(s.k1 + float(delta[self.free.index(7)]), -self.k1_bound), self.k1_bound)
        return CameraState(so3_exp(delta[:3]) @ s.R, s.C + delta[3:6], f, k1)

    def held(self, s: CameraState, delta: np.ndarray) -> np.ndarray | None:
        """The free parameters a step ``delta`` cannot move (see :func:`levenberg_marquardt`):
        k1 at its bound, pushed further out by the step; None when there is none."""
        if 7 not in self.free:
            return None
        i = self.free.index(7)
        if abs(s.k1) < self.k1_bound or s.k1 * float(delta[i]) <= 0:
            return None
        fixed = np.zeros(len(delta), bool)
        fixed[i] = True
        return fixed

    # ------------------------------------------------------------------ what the blocks need
    @staticmethod
    def lift(X: np.ndarray) -> np.ndarray:
        """World points as this model takes them: as they are."""
        return X

    def transform(self, X: np.ndarray, s: CameraState) -> np.ndarray:
        """Model points (N, 3) in the blocks' homogeneous image space: camera coordinates."""
        return to_camera(X, s.R, s.C)

    def pixels(self, Xc: np.ndarray, s: CameraState, jac: bool = False, X: np.ndarray | None = None):
        """Pixels (N, 2) of transformed points and, with ``jac``, their derivative (N, 2, 8)."""
        c0 = self.cam0
        return camera_to_pixels(Xc, s.R, s.f, self.aspect, c0.cx, c0.cy, s.k1, jac)

    def project(self, X: np.ndarray, s: CameraState, jac: bool = False):
        return self.pixels(self.transform(X, s), s, jac, X)

    @staticmethod
    def front(Xc: np.ndarray) -> np.ndarray:
        return Xc[:, 2] > MIN_DEPTH

    def observed(self, pts: np.ndarray, s: CameraState, jac: bool = False):
        """Observed pixels in the segments' space (undistorted normalised) and their derivative."""
        c0 = self.cam0
        return undistort_k1(pts, s.f, self.aspect, c0.cx, c0.cy, s.k1, jac)  # dq/d(log f, k1)

    def scale(self, s: CameraState) -> float:
        return s.f

    def segment_jacobian(self, A: np.ndarray, B: np.ndarray, dq: np.ndarray, s: CameraState,
                         Xa: np.ndarray, Xb: np.ndarray) -> SegmentJacobian:
        """Vector-Jacobian products of the segment ends: a rotation step turns them
        (``dA = -[A]x dw``, so ``g^T dA = (A x g) . dw``), a centre step moves them by ``-R dC``
        (``g^T dA = -(g^T R) dC``); the observed points move with f and k1 through the
        undistortion."""
        n = self.n_params
        A2, B2 = np.vstack([A, A]), np.vstack([B, B])

        def ends_vjp(ga, gb):
            out = np.zeros((len(ga), n))
            out[:, :3] = cross(A2, ga) + cross(B2, gb)
            out[:, 3:6] = -(ga + gb) @ s.R
            return out

        def q_vjp(g):
            Jq = np.vstack([dq, dq])
            out = np.zeros((len(g), n))
            out[:, 6] = g[:, 0] * Jq[:, 0, 0] + g[:, 1] * Jq[:, 1, 0]
            out[:, 7] = g[:, 0] * Jq[:, 0, 1] + g[:, 1] * Jq[:, 1, 1]
            return out

        return SegmentJacobian(ends_vjp, q_vjp, self.log_scale)


class HomographyModel:
    """A ground homography (see the module docstring); the state is ``M`` with
    ``H = M diag(s, s, 1)``."""

    n_params = 8
    log_scale = None
    min_depth = 0.0
    free = list(range(8))

    def start(self, H: np.ndarray) -> np.ndarray:
        return np.asarray(H, float) @ np.diag([1 / FIELD_SCALE, 1 / FIELD_SCALE, 1.0])

    @staticmethod
    def homography(M: np.ndarray) -> np.ndarray:
        return M @ np.diag([FIELD_SCALE, FIELD_SCALE, 1.0])

    def retract(self, M: np.ndarray, delta: np.ndarray) -> np.ndarray:
        return M @ (np.eye(3) + np.append(delta, 0.0).reshape(3, 3))

    # ------------------------------------------------------------------ what the blocks need
    @staticmethod
    def lift(X: np.ndarray) -> np.ndarray:
        """Ground points (N, 3) as normalised homogeneous field points (s X, s Y, 1)."""
        out = np.ones((len(X), 3))
        out[:, :2] = X[:, :2] * FIELD_SCALE
        return out

    @staticmethod
    def _dxh(M: np.ndarray, Xn: np.ndarray) -> np.ndarray:
        """d(M (I + P) Xn)/dP at P = 0, (N, 3, 8): column (i, j) is M[:, i] Xn[j]."""
        return np.einsum("ri,nj->nrij", M, Xn).reshape(len(Xn), 3, 9)[:, :, :8]

    @staticmethod
    def transform(Xn: np.ndarray, M: np.ndarray) -> np.ndarray:
        """Model points (N, 3) in the blocks' homogeneous image space: ``M Xn``."""
        return Xn @ M.T

    def pixels(self, xh: np.ndarray, M: np.ndarray, jac: bool = False, Xn: np.ndarray | None = None):
        """Pixels (N, 2) of transformed points and, with ``jac`` (and their ``Xn``), their
        derivative (N, 2, 8)."""
        uv, D = dehomogenize(xh, jac)
        if not jac:
            return uv, None
        assert D is not None and Xn is not None, "the derivative needs the model points Xn"
        return uv, D @ self._dxh(M, Xn)

    def project(self, Xn: np.ndarray, M: np.ndarray, jac: bool = False):
        return self.pixels(self.transform(Xn, M), M, jac, Xn)

    @staticmethod
    def front(xh: np.ndarray) -> np.ndarray:
        return xh[:, 2] > 0

    @staticmethod
    def observed(pts: np.ndarray, M: np.ndarray, jac: bool = False):
        return pts, None

    @staticmethod
    def scale(M: np.ndarray) -> float:
        return 1.0

    def segment_jacobian(self, A: np.ndarray, B: np.ndarray, dq, M: np.ndarray, Xa: np.ndarray,
                         Xb: np.ndarray) -> SegmentJacobian:
        """Vector-Jacobian products of the segment ends (the observed pixels are fixed)."""
        da, db = self._dxh(M, Xa), self._dxh(M, Xb)
        da2, db2 = np.concatenate([da, da]), np.concatenate([db, db])

        def ends_vjp(ga, gb):
            return np.einsum("nk,nkj->nj", ga, da2) + np.einsum("nk,nkj->nj", gb, db2)

        return SegmentJacobian(ends_vjp, None, None)
