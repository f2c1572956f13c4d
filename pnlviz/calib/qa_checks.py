"""The checks of one frame's annotation against the cameras fitted to it (:mod:`pnlviz.calib.qa`):
each class judged by the camera fitted without it (leave-one-class-out), the markings the camera
puts inside the image that nobody annotated, and the detections against the annotation. Pure:
arrays in, :class:`Finding` out.

Distances are pixels of the frame; thresholds are given at 960 px width and scale with it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pnlviz.field.model import FieldModel
from pnlviz.field.names import CIRCLE_CLASSES, MIRROR, MODEL_CLASSES
from pnlviz.geometry.camera import Camera
from pnlviz.geometry.distance import closest
from pnlviz.conventions import FINDING_KINDS

#: the kinds of finding, in the order a reviewer reads them
KINDS = FINDING_KINDS


@dataclass(frozen=True)
class QAParams:
    """What counts as wrong. Pixel values at 960 px image width (scaled with the width by
    :meth:`px`)."""

    def px(self, value: float, width: float) -> float:
        return value * width / 960.0

    tol_px: float = 8.0  #: a point this close to its class's projection sits on it
    far_px: float = 16.0  #: a point this far is off it
    rename_ratio: float = 3.0  #: another name fits this many times better (and within ``tol_px``)
    min_missing_px: float = 120.0  #: a marking is expected when this much of it is inside the image...
    missing_margin_px: float = 40.0  #: ... at least this far from the border
    min_sigma_px: float = 0.5  #: the clicks' spread about the paint is taken as at least this (px)
    det_tol_px: float = 8.0  #: a detection this far from the annotation disagrees with it
    loo_iter: int = 15  #: iterations of each leave-one-class-out refit
    max_severity: float = 10.0  #: a finding's severity is capped here
    prior_search: bool = True  #: a frame with too few keypoints is calibrated from broadcast priors (slow)


@dataclass(frozen=True)
class Finding:
    """One suspect of a frame. ``cls``: the class it is about (or None); ``keypoint``: the
    keypoint id (detections); ``severity``: >= 1, higher = more surely wrong; ``fix``: the
    suggested correction as data (see :func:`pnlviz.calib.qa.apply_fix`), or None."""

    kind: str
    message: str
    severity: float
    cls: str | None = None
    keypoint: int | None = None
    evidence: dict = field(default_factory=dict)
    fix: dict | None = None

    def to_json(self) -> dict:
        out: dict[str, Any] = {"kind": self.kind}
        if self.cls is not None:
            out["class"] = self.cls
        if self.keypoint is not None:
            out["keypoint"] = self.keypoint
        out.update(message=self.message, severity=round(float(self.severity), 3), evidence=self.evidence)
        if self.fix is not None:
            out["fix"] = self.fix
        return out


def _r(x: float) -> float | None:
    """A figure for the evidence (JSON): 2 decimals, None for infinity (no projection to measure to)."""
    return round(float(x), 2) if np.isfinite(x) else None


def _px_words(x: float) -> str:
    return f"{x:.0f} px off" if np.isfinite(x) else "out of the camera's view"


def _points_json(norm: np.ndarray) -> list[list[float]]:
    return [[round(float(x), 5), round(float(y), 5)] for x, y in norm]


# ----------------------------------------------------------------------------- projections
def projected_classes(cam: Camera, model: FieldModel, spacing: float = 0.5) -> dict[str, np.ndarray]:
    """Every class projected by ``cam`` as a polyline (pixels, unclipped), its trusted parts only
    (:func:`trusted_projection`; a class without two such points is left out)."""
    polys = model.sample_polylines(spacing, spacing)
    out = {}
    for name in MODEL_CLASSES:
        uv, ok = trusted_projection(cam, polys[name])
        if ok.sum() >= 2:
            out[name] = uv[ok]
    return out


def distances(pts: np.ndarray, poly: np.ndarray | None) -> np.ndarray:
    """Distance of each point to a polyline; inf without one."""
    if poly is None or len(poly) < 2:
        return np.full(len(pts), np.inf)
    return closest(pts, poly).distance


# ----------------------------------------------------------------------------- a class judged
def agreement(cam: Camera, annotation_px: dict[str, np.ndarray], skip: str, proj: dict[str, np.ndarray]) -> float:
    """How well the other classes fit ``cam``: the median over them of their farthest point (px)."""
    worst = [float(np.max(distances(p, proj.get(n)))) for n, p in annotation_px.items() if n != skip]
    return float(np.median(worst)) if worst else np.inf


@dataclass
class ClassVerdict:
    """One class judged by the camera fitted without it."""

    cls: str
    d: np.ndarray  #: distance of each of its points to its own projection
    others: float  #: how well the other classes agree with that camera (px)
    loo: bool  #: the camera was fitted without the class (False: the full camera, too few others)
    alt: str | None = None  #: the best other name
    d_alt: np.ndarray | None = None  #: the distances to that name's projection
    snapped: np.ndarray | None = None  #: each point moved onto the class's projection (pixels)
    spread: float = 0.0  #: how unsure that camera is of where the class is (px, one standard deviation)


def marking_std(spread, cls: str, pts: np.ndarray, model: FieldModel) -> float:
    """How sure the camera is of where ``cls`` is, near the annotated points ``pts``: the median
    standard deviation (px) of its projected samples closest to them."""
    X = model.sample_polylines(2.0, 1.0)[cls]
    uv, ok = trusted_projection(spread.model.camera(spread.state), X)
    if ok.sum() < 2:
        return np.inf
    near = np.argmin(np.linalg.norm(uv[ok][None] - pts[:, None], axis=2), axis=1)
    return float(np.median(spread.std(X[ok][np.unique(near)])))


def judge_class(cls: str, pts: np.ndarray, cam: Camera, loo: bool, annotation_px: dict[str, np.ndarray],
                model: FieldModel, spread=None) -> ClassVerdict:
    """``cls`` judged by ``cam``: its points' distances to its projection and to the best other
    name's, how well the others agree, how sure the camera is there (``spread``: a
    :class:`pnlviz.calib.qa_fits.CameraSpread`, at the class, else at the other name)."""
    proj = projected_classes(cam, model)
    d = distances(pts, proj.get(cls))
    verdict = ClassVerdict(cls, d, agreement(cam, annotation_px, cls, proj), loo)
    if cls in proj:
        verdict.snapped = pts - closest(pts, proj[cls]).offset
    best, best_d = None, None
    for name in MODEL_CLASSES:
        if name == cls or name not in proj:
            continue
        dn = distances(pts, proj[name])
        if best_d is None or np.max(dn) < np.max(best_d):
            best, best_d = name, dn
    verdict.alt, verdict.d_alt = best, best_d
    if spread is not None:
        verdict.spread = marking_std(spread, cls, pts, model)
        if not np.isfinite(verdict.spread) and best is not None:
            verdict.spread = marking_std(spread, best, pts, model)
    return verdict


def _relation(cls: str, alt: str) -> str:
    swapped = cls.replace("left", "@").replace("right", "left").replace("@", "right").strip()
    if MIRROR.get(cls) == alt or swapped == alt.strip():
        return "the other side"
    return "a neighbouring marking"


def class_findings(v: ClassVerdict, width: float, height: float, params: QAParams) -> list[Finding]:
    """The findings of one class's verdict (pixels of a ``width`` x ``height`` frame): a better
    name, points off the projection (fix: each moved onto it, or dropped when the camera does not
    see the class), or points of two markings (fix: the stray ones dropped)."""
    tol, far = params.px(params.tol_px, width), params.px(params.far_px, width)
    # an unsure camera (few other classes, or all on one side) asks for more before it says "off"
    tol, far = max(tol, 3.0 * v.spread), max(far, 6.0 * v.spread)
    if not np.isfinite(v.others) or v.others > far or not np.isfinite(v.spread):
        return []  # the other classes do not agree on a camera: nothing to judge this one by
    worst, n = float(np.max(v.d)), len(v.d)
    if worst <= far:
        return []
    ev: dict[str, Any] = {"points": n, "max_px": _r(worst), "median_px": _r(np.median(v.d)), "others_px": _r(v.others),
          "camera_std_px": _r(v.spread), "left_out": v.loo}
    confidence = 1.0 if v.loo else 0.5
    if v.alt is not None and v.d_alt is not None and np.max(v.d_alt) <= tol and np.max(v.d_alt) * params.rename_ratio < worst:
        ev.update(alt=v.alt, alt_max_px=_r(np.max(v.d_alt)))
        sev = min(params.max_severity, worst / tol) * confidence
        return [Finding("wrong_class", f"{v.cls!r} fits the pitch as {v.alt!r} ({_relation(v.cls, v.alt)}): "
                        f"{_px_words(worst)} under its name, {np.max(v.d_alt):.0f} px under the other",
                        max(sev, 1.0), v.cls, evidence=ev, fix={"op": "rename", "class": v.cls, "to": v.alt})]
    off = np.flatnonzero(v.d > far)
    on = np.flatnonzero(v.d <= tol)
    if len(on) >= 2 and len(off) < n:
        ev.update(off_points=off.tolist())
        sev = min(params.max_severity, float(np.max(v.d[off])) / tol) * confidence
        return [Finding("split_class", f"{len(off)} of the {n} points of {v.cls!r} cannot be on the marking the "
                        f"others are on ({_px_words(float(np.max(v.d[off])))})", max(sev, 1.0), v.cls,
                        evidence=ev, fix={"op": "drop_points", "class": v.cls, "points": off.tolist()})]
    sev = min(params.max_severity, float(np.median(v.d)) / tol) * confidence
    if sev < 1.0:
        return []
    fix: dict[str, Any]
    if v.snapped is not None and np.all(np.isfinite(v.snapped)):
        norm = np.clip(v.snapped / [width - 1, height - 1], 0.0, 1.0)
        fix = {"op": "move_points", "class": v.cls, "points": _points_json(norm)}
    else:
        fix = {"op": "drop_points", "class": v.cls, "points": list(range(n))}
    return [Finding("off_projection", f"{v.cls!r} sits off the camera's projection of it (median "
                    f"{_px_words(float(np.median(v.d)))}) while the other classes agree ({v.others:.1f} px)", sev,
                    v.cls, evidence=ev, fix=fix)]


# ----------------------------------------------------------------------------- markings left out
def _inner_length(uv: np.ndarray, ok: np.ndarray, width: float, height: float, margin: float) -> float:
    """Length (px) of the parts of a polyline (its trusted vertices ``ok``) at least ``margin``
    inside the image."""
    inside = ok & ((uv[:, 0] >= margin) & (uv[:, 0] <= width - 1 - margin) & (uv[:, 1] >= margin)
                   & (uv[:, 1] <= height - 1 - margin))
    seg = np.linalg.norm(np.diff(uv, axis=0), axis=1)
    return float(np.sum(np.where(inside[:-1] & inside[1:], seg, 0.0)))


def trusted_projection(cam: Camera, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixels of world points and which of them to trust: in front of the camera, near the image
    without the lens too, and not moved far by it (a strong lens model folds far-away markings
    back into the image: they are not there)."""
    uv = cam.project(X)
    pin = cam.project(X, distort=False)
    W, H = cam.width, cam.height
    with np.errstate(invalid="ignore"):
        ok = (np.all(np.isfinite(uv), axis=1) & (pin[:, 0] > -0.25 * W) & (pin[:, 0] < 1.25 * W)
              & (pin[:, 1] > -0.25 * H) & (pin[:, 1] < 1.25 * H) & (np.linalg.norm(uv - pin, axis=1) < 0.2 * W))
    return np.where(ok[:, None], uv, 0.0), ok


def missing_findings(cam: Camera, annotated: set[str], model: FieldModel, params: QAParams,
                     renamed_to: set[str]) -> list[Finding]:
    """Markings the camera puts well inside the image that the annotation does not have."""
    W, H = cam.width, cam.height
    need, margin = params.px(params.min_missing_px, W), params.px(params.missing_margin_px, W)
    polys = model.sample_polylines(0.5, 0.5)
    out = []
    for name in MODEL_CLASSES:
        if name in annotated or name in renamed_to:
            continue
        uv, ok = trusted_projection(cam, polys[name])
        inner = _inner_length(uv, ok, W, H, margin)
        if inner < need:
            continue
        poly = uv[ok & (uv[:, 0] >= 0) & (uv[:, 0] <= W - 1) & (uv[:, 1] >= 0) & (uv[:, 1] <= H - 1)]
        scale = np.array([W - 1, H - 1], float)
        sev = min(params.max_severity, inner / need)
        step = max(1, len(poly) // (12 if name in CIRCLE_CLASSES else 4))
        points = np.clip(poly[::step] / scale, 0, 1)
        out.append(Finding("missing_class", f"{name!r} is {inner:.0f} px inside the image by the camera but "
                           "not annotated", sev, name, evidence={"inside_px": _r(inner)},
                           fix={"op": "add_class", "class": name,
                                "points": _points_json(points)}))
    return out


# ----------------------------------------------------------------------------- detections
def detection_findings(ann_obs, det_obs, cam: Camera, annotation_px: dict[str, np.ndarray],
                       params: QAParams) -> list[Finding]:
    """Keypoints and lines where the detections (named on the annotation's sides) and the
    annotation disagree, each with which of the two the camera backs."""
    from pnlviz.geometry.conics import fit_line

    tol = params.px(params.det_tol_px, ann_obs.width)
    out = []
    ann_xy = dict(zip(ann_obs.kp_ids.tolist(), ann_obs.kp_xy))
    for kid, xyz, dxy in zip(det_obs.kp_ids.tolist(), det_obs.kp_xyz, det_obs.kp_xy):
        if kid not in ann_xy:
            continue
        d = float(np.linalg.norm(ann_xy[kid] - dxy))
        if d <= tol:
            continue
        uv = cam.project(xyz[None])
        ann_cam, det_cam = float(np.linalg.norm(uv[0] - ann_xy[kid])), float(np.linalg.norm(uv[0] - dxy))
        backs = "the detection" if det_cam < ann_cam else "the annotation"
        out.append(Finding("detection_disagreement", f"keypoint {kid}: detected {d:.0f} px from where the "
                           f"annotation's lines put it; the camera backs {backs}",
                           min(params.max_severity, d / tol), keypoint=int(kid),
                           evidence={"distance_px": _r(d), "annotation_to_camera_px": _r(ann_cam),
                                     "detection_to_camera_px": _r(det_cam)}))
    for name, ends in det_obs.lines.items():
        pts = annotation_px.get(name)
        if pts is None or len(pts) < 2 or name in CIRCLE_CLASSES:
            continue
        line = fit_line(pts)
        d = float(np.max(np.abs(np.asarray(ends, float) @ line[:2] + line[2])))
        if d <= tol:
            continue
        out.append(Finding("detection_disagreement", f"{name!r}: its detected points lie up to {d:.0f} px from "
                           "the annotated line", min(params.max_severity, d / tol), name,
                           evidence={"distance_px": _r(d)}))
    return out
