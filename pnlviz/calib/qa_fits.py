"""The cameras that judge a frame's classes (:mod:`pnlviz.calib.qa`): refitted without a class
(leave-one-class-out), the same to first order for every class at once, one camera for a class
and the others together, and how sure a camera is of where it puts a marking (its covariance
from the points it was fitted to, propagated to the marking's pixels). Pure.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from pnlviz.calib.problem import FrameData
from pnlviz.calib.qa_checks import QAParams, distances, projected_classes, trusted_projection
from pnlviz.calib.refine import CameraProblem, RefineParams
from pnlviz.field.model import FieldModel
from pnlviz.geometry.camera import Camera

def loo_camera(cam: Camera, data: FrameData, cls: str | set[str], params: QAParams) -> Camera | None:
    """The camera refitted (from ``cam``: pose and focal length, bounded loss) to every line and
    circle point of the frame except those of ``cls`` (a class or a set of them); None when the
    others are too few to fix a camera."""
    obs = data.obs
    skip = {cls} if isinstance(cls, str) else set(cls)
    lines = [n for n in obs.lines if n not in skip]
    circles = [n for n in obs.circles if n not in skip]
    n_pts = sum(len(obs.lines[n]) for n in lines) + sum(len(obs.circles[n]) for n in circles)
    if len(lines) + len(circles) < 2 or n_pts < 9:
        return None
    rp = RefineParams(alpha=1.0, refine_focal=True, refine_k1=False, loss="cauchy",
                      f_scale=params.px(3.0, obs.width), max_iter=params.loo_iter, tol=1e-6)
    prob = CameraProblem(cam, data, rp, use_keypoints=np.zeros(obs.n_keypoints, bool), lines=lines,
                         circles=circles)
    if prob.n_res < prob.n_free + 2:
        return None
    new, _ = prob.solve()
    return new if np.all(np.isfinite(new.R)) and np.all(np.isfinite(new.C)) else None


def first_order_loo(cam: Camera, data: FrameData, params: QAParams) -> dict[str, Camera]:
    """For each observed line and circle class, the camera one Gauss-Newton step takes from
    ``cam`` on the points of every *other* class (Cauchy-weighted, so that a class far off does
    not count): the leave-one-class-out camera to first order, for all classes from one
    Jacobian. It shows a class that pulled the joint camera onto itself."""
    from pnlviz.calib.solver import robust_weights

    obs = data.obs
    rp = RefineParams(alpha=1.0, refine_focal=True, refine_k1=False)
    prob = CameraProblem(cam, data, rp, use_keypoints=np.zeros(obs.n_keypoints, bool))
    if prob.n_res < prob.n_free + 2:
        return {}
    P, model = prob.problem, prob.model
    state = model.start()
    r, J = P.evaluate(state, jac=True)
    assert J is not None  # asked for
    w = robust_weights(r, "cauchy", params.px(3.0, obs.width))
    ok = np.isfinite(r) & np.all(np.isfinite(J), axis=1)
    Jw, rw = np.where(ok[:, None], J * w[:, None], 0.0), np.where(ok, r * w, 0.0)
    A, g = Jw.T @ Jw, Jw.T @ rw
    L = len(P.line_pts)
    rows = {name: np.r_[s, np.arange(s.start, s.stop) + L] for name, s in P.line_slices.items()}
    at = 2 * L
    for name, _, pts in P.circle_items:
        rows[name] = np.arange(at, at + len(pts))
        at += len(pts)
    out = {}
    for name, idx in rows.items():
        Ac = A - Jw[idx].T @ Jw[idx]
        Ac.flat[::len(Ac) + 1] += 1e-6 * np.maximum(Ac.diagonal(), 1e-9)
        try:
            delta = -np.linalg.solve(Ac, g - Jw[idx].T @ rw[idx])
        except np.linalg.LinAlgError:
            continue
        if np.all(np.isfinite(delta)):
            out[name] = model.camera(model.retract(state, delta))
    return out


def class_distances(cam: Camera, cls: str, pts: np.ndarray, model: FieldModel) -> np.ndarray:
    """Distance of a class's points to its projection by ``cam`` (inf where it has none)."""
    uv, ok = trusted_projection(cam, model.sample_polylines(0.5, 0.5)[cls])
    return distances(pts, uv[ok] if ok.sum() >= 2 else None)


def consistent(cam: Camera, data: FrameData, px: dict[str, np.ndarray], cls: str, skip: set[str],
               params: QAParams, model: FieldModel, frame_worst: Mapping[str, float] | None = None) -> bool:
    """Whether one camera fits ``cls`` and the other classes (but ``skip``) together, every
    point within ``tol_px``: the frame's camera, fitted to them all, when it does (``frame_worst``:
    each class's farthest point from it, px), else ``cam`` refitted with them all (pose, focal
    length and k1; from a camera without the class, the refit can stop in another minimum than
    the frame's). Then nothing says the class is wrong, however badly the camera without it
    extrapolated."""
    obs = data.obs
    names = [n for n in (*obs.lines, *obs.circles) if (n not in skip or n == cls) and n in px]
    tol = params.px(params.tol_px, cam.width)
    if frame_worst is not None and all(frame_worst[n] <= tol for n in names):
        return True
    lines = [n for n in obs.lines if n not in skip or n == cls]
    circles = [n for n in obs.circles if n not in skip or n == cls]
    rp = RefineParams(alpha=1.0, refine_focal=True, refine_k1=True, max_iter=params.loo_iter, tol=1e-6)
    prob = CameraProblem(cam, data, rp, use_keypoints=np.zeros(obs.n_keypoints, bool), lines=lines, circles=circles)
    if prob.n_res < prob.n_free + 2:
        return False
    joint, _ = prob.solve()
    proj = projected_classes(joint, model)
    return all(float(np.max(distances(px[n], proj.get(n)))) <= tol for n in names)


# ----------------------------------------------------------------------------- how sure a camera is
class CameraSpread:
    """How sure ``cam`` is, fitted to the line and circle points of ``data`` but ``skip``: the
    covariance of its parameters (pose, focal length, k1) for clicks :data:`CLICK_SIGMA_PX` off
    the paint, and the standard deviation it gives the pixels of any world points."""

    def __init__(self, cam: Camera, data: FrameData, skip: set[str], params: QAParams):
        from pnlviz.calib.solver import robust_weights

        obs = data.obs
        rp = RefineParams(alpha=1.0, refine_focal=True, refine_k1=True)  # the lens too: far from the points it bends
        prob = CameraProblem(cam, data, rp, use_keypoints=np.zeros(obs.n_keypoints, bool),
                             lines=[n for n in obs.lines if n not in skip],
                             circles=[n for n in obs.circles if n not in skip])
        self.model, self.state = prob.model, prob.model.start()
        self.cov = None
        if prob.n_res < prob.n_free + 2:
            return
        r, J = prob.problem.evaluate(self.state, jac=True)
        assert J is not None  # asked for
        ok = np.isfinite(r) & np.all(np.isfinite(J), axis=1)
        Jw = J[ok] * robust_weights(r[ok], "cauchy", params.px(3.0, obs.width))[:, None]
        A = Jw.T @ Jw
        # the clicks' spread about the paint, from the fit itself (robust: the median absolute residual)
        sigma = max(params.px(params.min_sigma_px, obs.width), 1.4826 * float(np.median(np.abs(r[ok]))))
        try:
            self.cov = sigma**2 * np.linalg.inv(A + 1e-9 * np.eye(len(A)) * max(np.trace(A), 1e-9))
        except np.linalg.LinAlgError:
            self.cov = None

    def std(self, X: np.ndarray) -> np.ndarray:
        """Standard deviation (px) of the projections of world points ``X`` (N, 3); inf without
        a covariance (too few points to fit the camera)."""
        if self.cov is None or not len(X):
            return np.full(len(X), np.inf)
        n = len(self.cov)
        base = self.model.camera(self.state).project(X)
        G = np.empty((len(X), 2, n))
        for k in range(n):  # d(pixels)/d(parameter) by central differences
            e = np.zeros(n)
            e[k] = 1e-6
            plus = self.model.camera(self.model.retract(self.state, e)).project(X)
            minus = self.model.camera(self.model.retract(self.state, -e)).project(X)
            G[:, :, k] = (plus - minus) / 2e-6
        var = np.einsum("nij,jk,nik->n", G, self.cov, G)
        out = np.sqrt(np.maximum(var, 0.0))
        return np.where(np.all(np.isfinite(base), axis=1) & np.isfinite(out), out, np.inf)

