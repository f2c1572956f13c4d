"""Non-linear refinement of a camera against keypoints, lines and circles.

State: rotation ``R``, centre ``C``, focal ``f`` (``fy = aspect * f`` with the aspect of the
starting camera) and radial ``k1``; principal point fixed. Any of focal/k1 can be held fixed: the
PnL refinement holds K fixed and optimises the pose only, as in the paper.

Residuals, all in pixels:

* keypoints: projection (with k1) minus detection, 2 per point;
* straight classes, two per observed point (undistorted): the distance to the image of the
  infinite 3D line, and how far the point lies beyond the projected segment's ends along it (0
  between them), so that together they give the distance to the segment, which is what the
  SoccerNet evaluator measures. The image line is ``l = a x b`` with ``a, b`` the segment ends in
  camera coordinates: the plane through the camera centre and the 3D line, which stays valid
  when an end lies behind the camera, so no clipping against the camera plane is needed (the
  paper clips the segment at the camera plane instead). With an end behind the camera only the
  perpendicular term is used;
* circles: distance of each observed point to the circle class projected as a dense polyline
  (every ``circle_step`` metres, with lens distortion). A closed-form conic distance (Sampson) was
  tried first and dropped: it is badly wrong for the thin ellipses of far penalty arcs seen at
  grazing angles, and led the optimiser into false minima.

Line and circle terms are weighted by ``sqrt(alpha)`` and point terms by ``sqrt(1 - alpha)`` (the
paper's cost, in squares). The solver is a small Levenberg-Marquardt loop written here because the
Jacobian is analytic, including the pose as rotation updates ``R <- exp([dw]x) R`` re-linearised
at every step, which scipy's fixed parametrisation cannot express, and the focal length and k1
(through the implicit undistortion of observed line points). Robust losses are applied by
iteratively reweighting rows.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pnlviz.calib.observations import Observations
from pnlviz.field.model import FieldModel, load_field_model
from pnlviz.geometry.camera import Camera


def so3_exp(w: np.ndarray) -> np.ndarray:
    theta = float(np.linalg.norm(w))
    K = np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])
    if theta < 1e-12:
        return np.eye(3) + K
    return np.eye(3) + np.sin(theta) / theta * K + (1 - np.cos(theta)) / theta**2 * (K @ K)


def _skew(v: np.ndarray) -> np.ndarray:
    """(N, 3) -> (N, 3, 3) cross-product matrices."""
    z = np.zeros(len(v))
    return np.stack([np.stack([z, -v[:, 2], v[:, 1]], -1),
                     np.stack([v[:, 2], z, -v[:, 0]], -1),
                     np.stack([-v[:, 1], v[:, 0], z], -1)], axis=1)


def point_to_polyline_distance(pts: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Euclidean distance of each point (M, 2) to the polyline (S, 2), vectorised over M x S."""
    return closest_on_polyline(pts, poly)[0]


def closest_on_polyline(pts: np.ndarray, poly: np.ndarray):
    a, b = poly[:-1], poly[1:]
    ab = b - a
    L2 = np.maximum(np.sum(ab * ab, axis=1), 1e-18)
    ap = pts[:, None, :] - a[None]
    t = np.clip(np.einsum("msk,sk->ms", ap, ab) / L2, 0.0, 1.0)
    d = ap - t[..., None] * ab[None]
    d2 = np.einsum("msk,msk->ms", d, d)
    j = np.argmin(d2, axis=1)
    m = np.arange(len(pts))
    return np.sqrt(d2[m, j]), j, t[m, j], d[m, j]


@dataclass(frozen=True)
class RefineParams:
    alpha: float = 0.6  #: weight of line/circle terms vs keypoints (paper: 0.6)
    refine_focal: bool = True
    refine_k1: bool = False
    loss: str = "linear"  #: linear, huber, soft_l1 or cauchy
    f_scale: float = 2.0  #: pixels where the robust loss bends
    max_iter: int = 50
    tol: float = 1e-8  #: stop when the cost drops by less than this fraction
    k1_bound: float = 1.0  #: |k1| limit (SN22 fits push k1 to +0.4..0.6 at 15-30 deg FOV; a 0.5 cap cost 0.8 FS)
    circle_step: float = 0.5  #: metres between samples of projected circles (chord error < 4 mm)


def _robust_weights(r: np.ndarray, loss: str, c: float) -> np.ndarray:
    """sqrt of the IRLS weight rho'(s) for s = (r/c)^2."""
    if loss == "linear":
        return np.ones_like(r)
    s = (r / c) ** 2
    if loss == "huber":
        return np.sqrt(np.where(s <= 1, 1.0, 1 / np.sqrt(np.maximum(s, 1e-30))))
    if loss == "soft_l1":
        return (1 + s) ** -0.25
    if loss == "cauchy":
        return (1 + s) ** -0.5
    raise ValueError(f"unknown loss {loss!r}")


class CameraProblem:
    """Residuals (and their Jacobian) of a camera against :class:`Observations`."""

    def __init__(self, cam0: Camera, obs: Observations, params: RefineParams = RefineParams(),
                 model: FieldModel | None = None, use_keypoints: np.ndarray | None = None):
        model = model or load_field_model()
        self.cam0, self.params = cam0, params
        self.aspect = cam0.fy / cam0.fx
        mask = np.ones(obs.n_keypoints, bool) if use_keypoints is None else use_keypoints
        self.kp_xyz, self.kp_xy = obs.kp_xyz[mask], obs.kp_xy[mask]
        # straight classes: each observed point with the 3D ends of its class
        ends_a, ends_b, pts, self.line_slices = [], [], [], {}
        n = 0
        for name, p in obs.lines.items():
            seg = model.lines[name]
            ends_a.append(np.repeat(seg.start[None], len(p), 0))
            ends_b.append(np.repeat(seg.end[None], len(p), 0))
            pts.append(p)
            self.line_slices[name] = slice(n, n + len(p))
            n += len(p)
        self.line_a = np.vstack(ends_a) if ends_a else np.zeros((0, 3))
        self.line_b = np.vstack(ends_b) if ends_b else np.zeros((0, 3))
        self.line_pts = np.vstack(pts) if pts else np.zeros((0, 2))
        # circles: dense world samples of each class and its observed points
        self.circle_items = []
        for name, p in obs.circles.items():
            arc = model.circles[name]
            k = max(8, int(np.radians(arc.end_deg - arc.start_deg) * arc.radius / params.circle_step))
            world = arc.point_at(np.linspace(np.radians(arc.start_deg), np.radians(arc.end_deg), k + 1))
            self.circle_items.append((name, world, np.asarray(p, float)))
        n_circle = sum(len(p) for _, _, p in self.circle_items)
        self.n_res = 2 * len(self.kp_xy) + 2 * len(self.line_pts) + n_circle
        has_curves = len(self.line_pts) + n_circle > 0
        self.w_pt = np.sqrt(1 - params.alpha) if has_curves else 1.0
        self.w_ln = np.sqrt(params.alpha) if len(self.kp_xy) else 1.0
        self.n_free = 6 + params.refine_focal + params.refine_k1

    # ------------------------------------------------------------------ projection + Jacobian
    def _project(self, X, R, C, f, k1, jac: bool):
        """Pixels (N, 2) of world points and, with ``jac``, d(uv)/d(dw, C, log f, k1) (N, 2, 8)."""
        c0 = self.cam0
        Xc = (X - C) @ R.T
        z = np.where(Xc[:, 2] > 1e-6, Xc[:, 2], 1e-6)  # points crossing the camera plane: huge residual
        xn, yn = Xc[:, 0] / z, Xc[:, 1] / z
        r2 = xn * xn + yn * yn
        g = 1 + k1 * r2
        fy = f * self.aspect
        uv = np.stack([f * xn * g + c0.cx, fy * yn * g + c0.cy], axis=1)
        if not jac:
            return uv, None
        # d(xn, yn)/dXc
        Dn = np.zeros((len(X), 2, 3))
        Dn[:, 0, 0] = 1 / z
        Dn[:, 0, 2] = -xn / z
        Dn[:, 1, 1] = 1 / z
        Dn[:, 1, 2] = -yn / z
        # d(distorted)/d(xn, yn), times focal
        Dd = np.empty((len(X), 2, 2))
        Dd[:, 0, 0] = f * (g + 2 * k1 * xn * xn)
        Dd[:, 0, 1] = f * 2 * k1 * xn * yn
        Dd[:, 1, 0] = fy * 2 * k1 * xn * yn
        Dd[:, 1, 1] = fy * (g + 2 * k1 * yn * yn)
        Juv_Xc = Dd @ Dn  # (N, 2, 3)
        dXc = np.concatenate([-_skew(Xc), np.broadcast_to(-R, (len(X), 3, 3))], axis=2)  # (N, 3, 6)
        J = np.empty((len(X), 2, 8))
        J[:, :, :6] = Juv_Xc @ dXc
        J[:, :, 6] = uv - [c0.cx, c0.cy]  # d/d log f
        J[:, 0, 7] = f * xn * r2  # d/d k1
        J[:, 1, 7] = fy * yn * r2
        return uv, J

    def _undistort_norm(self, pts: np.ndarray, f: float, k1: float, jac: bool = False):
        """Undistorted normalised points q (N, 2) of pixels and, with ``jac``, dq/d(log f, k1)
        (N, 2, 2). ``q = x_d s`` with ``s (1 + k1 |x_d|^2 s^2) = 1`` (fixed point; k1 is small)."""
        c0 = self.cam0
        xd = np.stack([(pts[:, 0] - c0.cx) / f, (pts[:, 1] - c0.cy) / (f * self.aspect)], axis=1)
        rd2 = np.sum(xd * xd, axis=1)
        s = np.ones_like(rd2)
        if k1 != 0.0:
            for _ in range(8):
                s = 1.0 / (1.0 + k1 * rd2 * s * s)
        q = xd * s[:, None]
        if not jac:
            return q
        # implicit derivatives of s: F = s (1 + k1 rd2 s^2) - 1 = 0
        dF_ds = 1 + 3 * k1 * rd2 * s * s
        ds_drd2 = -k1 * s**3 / dF_ds
        ds_dk1 = -rd2 * s**3 / dF_ds
        Jq = np.empty((len(q), 2, 2))
        Jq[:, :, 0] = -q - (2 * rd2 * ds_drd2)[:, None] * xd  # d x_d / d log f = -x_d, d rd2 = -2 rd2
        Jq[:, :, 1] = xd * ds_dk1[:, None]
        return q, Jq

    def _eval(self, R, C, f, k1, jac: bool = False):
        """Weighted residuals and, with ``jac``, their Jacobian w.r.t. (dw, C, log f, k1) (n, 8)."""
        res, J = [], []
        if len(self.kp_xy):
            uv, Juv = self._project(self.kp_xyz, R, C, f, k1, jac)
            res.append(self.w_pt * (uv - self.kp_xy).ravel())
            if jac:
                J.append(self.w_pt * Juv.reshape(-1, 8))
        if len(self.line_pts):
            a = (self.line_a - C) @ R.T
            b = (self.line_b - C) @ R.T
            l = np.cross(a, b)
            q, Jq = self._undistort_norm(self.line_pts, f, k1, jac=True) if jac else (
                self._undistort_norm(self.line_pts, f, k1), None)
            nrm = np.sqrt(l[:, 0] ** 2 + l[:, 1] ** 2)
            lq = l[:, 0] * q[:, 0] + l[:, 1] * q[:, 1] + l[:, 2]
            res.append(self.w_ln * f * lq / nrm)
            # the segment's ends: how far a point lies beyond them along the line (0 when it lies
            # between), so that sqrt(perpendicular^2 + overshoot^2) is the distance to the segment,
            # as the evaluator measures it; only when both ends are in front of the camera
            front = (a[:, 2] > 1e-3) & (b[:, 2] > 1e-3)
            az, bz = np.where(front, a[:, 2], 1.0), np.where(front, b[:, 2], 1.0)
            pa, pb = a[:, :2] / az[:, None], b[:, :2] / bz[:, None]
            v = pb - pa
            L = np.maximum(np.sqrt(np.sum(v * v, axis=1)), 1e-12)
            u = v / L[:, None]
            s_ = np.sum((q - pa) * u, axis=1)
            before = front & (s_ < 0)
            after = front & (s_ > L)
            over = np.where(before, -s_, np.where(after, s_ - L, 0.0))
            res.append(self.w_ln * f * over)
            if jac:
                qh = np.hstack([q, np.ones((len(q), 1))])
                dd_dl = f * (qh / nrm[:, None] - (lq / nrm**3)[:, None] * np.stack([l[:, 0], l[:, 1], np.zeros(len(l))], 1))
                negR = np.broadcast_to(-R, (len(a), 3, 3))
                da = np.concatenate([-_skew(a), negR], axis=2)
                db = np.concatenate([-_skew(b), negR], axis=2)
                dl = -_skew(b) @ da + _skew(a) @ db  # d(a x b) = da x b + a x db
                Jperp = np.empty((len(q), 8))
                Jperp[:, :6] = np.einsum("nk,nkj->nj", dd_dl, dl)
                # intrinsics: perp = f (l . q) / |l_12|, q depends on f and k1
                dperp_dq = f * l[:, :2] / nrm[:, None]
                Jperp[:, 6:] = np.einsum("nk,nkj->nj", dperp_dq, Jq)
                Jperp[:, 6] += f * lq / nrm
                J.append(self.w_ln * Jperp)
                # overshoot: s = (q - pa).u, d s/d pa = -u - P w / L, d s/d pb = P w / L with
                # w = q - pa and P = I - u u^T
                w_ = q - pa
                Pw = w_ - np.sum(w_ * u, axis=1)[:, None] * u
                ds_pa = -u - Pw / L[:, None]
                ds_pb = Pw / L[:, None]
                sign = np.where(before, -1.0, np.where(after, 1.0, 0.0))
                # the L term of (s - L): dL/dpb = u, dL/dpa = -u
                dr_pa = sign[:, None] * ds_pa + np.where(after, 1.0, 0.0)[:, None] * u
                dr_pb = sign[:, None] * ds_pb - np.where(after, 1.0, 0.0)[:, None] * u

                def dproj(p3, z):  # d(x/z, y/z)/d(p3)
                    D = np.zeros((len(p3), 2, 3))
                    D[:, 0, 0] = D[:, 1, 1] = 1 / z
                    D[:, 0, 2] = -p3[:, 0] / z**2
                    D[:, 1, 2] = -p3[:, 1] / z**2
                    return D

                Jover = np.zeros((len(q), 8))
                Jover[:, :6] = f * (np.einsum("nk,nkj->nj", dr_pa, dproj(a, az) @ da)
                                    + np.einsum("nk,nkj->nj", dr_pb, dproj(b, bz) @ db))
                # intrinsics: over = f * sign * (q - pa) . u (+ const): d/dq = f sign u
                Jover[:, 6:] = np.einsum("nk,nkj->nj", f * sign[:, None] * u, Jq)
                Jover[:, 6] += f * over
                J.append(self.w_ln * Jover)
        for _, world, pts in self.circle_items:
            Xc2 = (world - C) @ R.T
            front = Xc2[:, 2] > 1e-3
            if front.sum() < 2:
                res.append(np.full(len(pts), 1e3))
                if jac:
                    J.append(np.zeros((len(pts), 8)))
                continue
            poly, Jp = self._project(world[front], R, C, f, k1, jac)
            dist, j, t, d = closest_on_polyline(pts, poly)
            res.append(self.w_ln * dist)
            if jac:
                unit = d / np.maximum(dist, 1e-12)[:, None]  # d(dist)/d(closest point) = -unit
                Jc = (1 - t)[:, None, None] * Jp[j] + t[:, None, None] * Jp[j + 1]
                J.append(-self.w_ln * np.einsum("nk,nkj->nj", unit, Jc))
        r = np.concatenate(res) if res else np.zeros(0)
        return (r, np.vstack(J) if J else np.zeros((0, 8))) if jac else r

    # ------------------------------------------------------------------ public helpers
    def residuals(self, cam: Camera | None = None) -> np.ndarray:
        """Weighted residuals at ``cam`` (default: the starting camera)."""
        cam = cam or self.cam0
        return self._eval(cam.R, cam.C, cam.fx, cam.radial[0])

    def class_residuals(self, cam: Camera | None = None) -> dict[str, np.ndarray]:
        """Unweighted distances (px) of each line/circle class's points at ``cam``."""
        cam = cam or self.cam0
        r = self._eval(cam.R, cam.C, cam.fx, cam.radial[0])
        start = 2 * len(self.kp_xy)
        n = len(self.line_pts)
        perp, over = r[start:start + n], r[start + n:start + 2 * n]
        dist = np.sqrt(perp**2 + over**2) / self.w_ln
        out = {name: dist[s] for name, s in self.line_slices.items()}
        start += 2 * n
        for name, _, pts in self.circle_items:
            out[name] = np.abs(r[start:start + len(pts)]) / self.w_ln
            start += len(pts)
        return out

    def camera(self, R, C, f, k1) -> Camera:
        radial = np.array(self.cam0.radial, float)
        radial[0] = k1
        c0 = self.cam0
        return Camera(f, f * self.aspect, c0.cx, c0.cy, R, C, c0.width, c0.height, radial, c0.tangential, c0.thin_prism)

    # ------------------------------------------------------------------ Levenberg-Marquardt
    def _full_jacobian(self, R, C, f, k1):
        _, J = self._eval(R, C, f, k1, jac=True)
        p = self.params
        cols = list(range(6)) + ([6] if p.refine_focal else []) + ([7] if p.refine_k1 else [])
        return J[:, cols]

    def solve(self) -> tuple[Camera, dict]:
        p = self.params
        R, C, f, k1 = self.cam0.R, self.cam0.C.copy(), self.cam0.fx, float(self.cam0.radial[0])
        if self.n_res < self.n_free:
            return self.cam0, {"success": False, "message": "fewer residuals than parameters", "iterations": 0}

        def robust_cost(r):
            if p.loss == "linear":
                return 0.5 * float(r @ r)
            s = (r / p.f_scale) ** 2
            rho = {"huber": lambda s: np.where(s <= 1, s, 2 * np.sqrt(s) - 1),
                   "soft_l1": lambda s: 2 * (np.sqrt(1 + s) - 1),
                   "cauchy": lambda s: np.log1p(s)}[p.loss](s)
            return 0.5 * p.f_scale**2 * float(np.sum(rho))

        r = self._eval(R, C, f, k1)
        cost = robust_cost(r)
        lam, it, success = 1e-3, 0, False
        J = None
        for it in range(1, p.max_iter + 1):
            if J is None:
                J = self._full_jacobian(R, C, f, k1)
                w = _robust_weights(r, p.loss, p.f_scale)
                Jw, rw = J * w[:, None], r * w
                A, g = Jw.T @ Jw, Jw.T @ rw
            while True:
                D = np.diag(np.maximum(np.diag(A), 1e-9))
                try:
                    delta = -np.linalg.solve(A + lam * D, g)
                except np.linalg.LinAlgError:
                    lam *= 10
                    if lam > 1e12:
                        break
                    continue
                R2 = so3_exp(delta[:3]) @ R
                C2 = C + delta[3:6]
                i = 6
                f2, k12 = f, k1
                if p.refine_focal:
                    f2 = f * np.exp(np.clip(delta[i], -1.0, 1.0))  # at most a factor e per step
                    i += 1
                if p.refine_k1:
                    k12 = float(np.clip(k1 + delta[i], -p.k1_bound, p.k1_bound))
                with np.errstate(all="ignore"):  # a wild trial step is simply rejected below
                    r2 = self._eval(R2, C2, f2, k12)
                    cost2 = robust_cost(r2)
                if np.isfinite(cost2) and cost2 <= cost:
                    break
                lam *= 4
                if lam > 1e12:
                    break
            if lam > 1e12:
                success = True  # no descent direction left: at a minimum
                break
            rel = (cost - cost2) / max(cost, 1e-30)
            R, C, f, k1, r, cost = R2, C2, f2, k12, r2, cost2
            lam = max(lam / 3, 1e-12)
            J = None
            if rel < p.tol or np.linalg.norm(delta) < 1e-12:
                success = True
                break
        return self.camera(R, C, f, k1), {"success": success, "cost": cost, "iterations": it}


def refine_camera(cam0: Camera, obs: Observations, params: RefineParams = RefineParams(), *,
                  use_keypoints: np.ndarray | None = None, model: FieldModel | None = None) -> tuple[Camera, dict]:
    """Refine ``cam0`` against ``obs`` (see :class:`CameraProblem`). Returns the camera and a
    diagnostics dict (success, cost, iterations)."""
    return CameraProblem(cam0, obs, params, model, use_keypoints).solve()
