"""Find the label errors of one frame: its annotation judged by the cameras fitted to it.

:func:`check_frame` calibrates the frame from its annotation (the one path per frame,
:func:`pnlviz.calib.frame.calibrate_frame`), then judges each class by the camera refitted
*without* it (leave-one-class-out, so that a wrong class cannot pull the camera that judges it;
the other gross suspects are left out with it when enough remains; a class that both the frame's
camera and the first-order camera without it fit within ``far_px`` is not judged again, nor one that
a single camera fits together with all the others), and reports:

* ``wrong_class``: the class's points fit the pitch far better under another name (the mirrored
  side, a neighbouring marking); fix: rename it;
* ``off_projection``: its points sit off the camera's projection of it while the other classes
  agree; fix: move each onto the projection (drop them when the camera does not see the class);
* ``split_class``: some of its points are on the marking and some cannot be (two arcs, a jump);
  fix: drop the stray points;
* ``missing_class``: a marking the camera puts well inside the image is not annotated; fix: add
  it where the camera puts it (points to check);
* ``detection_disagreement``: detections and annotation disagree where both exist (which of the
  two the camera backs is in the evidence);
* ``no_camera``: the annotation gives no camera at all.

Each finding has a severity (>= 1); the frame's score is the largest plus a quarter of the others
(higher = more likely wrong); a frame without findings scores below 1, by how close its worst
class comes to being off. A fix is data (``{"op": "rename" | "drop_points" | "move_points" |
"add_class", ...}``) that :func:`apply_fix` applies to an annotation. Pure: nothing here reads or writes files.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from itertools import pairwise
from typing import Any

import numpy as np

from pnlviz.calib.frame import Failure, FrameCalibration, FrameInputs, FrameSettings, calibrate_frame
from pnlviz.calib.problem import FrameData
from pnlviz.calib.qa_checks import (KINDS, Finding, QAParams, class_findings, detection_findings, distances,
                                    judge_class, missing_findings, projected_classes, trusted_projection)
from pnlviz.calib.qa_fits import CameraSpread, class_distances, consistent, first_order_loo, loo_camera
from pnlviz.conventions import EVAL_SIZE
from pnlviz.field.model import FieldModel, load_field_model
from pnlviz.field.names import MODEL_CLASSES
from pnlviz.geometry.camera import Camera

__all__ = ["KINDS", "Finding", "FindingMarks", "FrameQA", "QAParams", "apply_fix", "check_frame", "finding_marks",
           "frame_score"]


@dataclass
class FrameQA:
    """One frame's verdict: its ``score`` (higher = more likely wrong), the ``findings`` (most
    severe first), the camera they were judged by (None: no camera) and the time it took."""

    score: float
    findings: list[Finding] = field(default_factory=list)
    camera: Camera | None = None
    ms: float = 0.0

    @property
    def kinds(self) -> list[str]:
        return [f.kind for f in self.findings]

    def to_json(self, stem: str | None = None) -> dict:
        out: dict[str, Any] = {} if stem is None else {"stem": stem}
        out.update(score=round(float(self.score), 4), findings=[f.to_json() for f in self.findings])
        return out


def frame_score(findings: list[Finding], baseline: float = 0.0) -> float:
    """The largest severity plus a quarter of the others; ``baseline`` (< 1) without findings."""
    if not findings:
        return float(min(max(baseline, 0.0), 0.99))
    sev = sorted((f.severity for f in findings), reverse=True)
    return float(sev[0] + 0.25 * sum(sev[1:]))


def _normalised(annotation: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    out = {}
    for name, pts in annotation.items():
        p = np.asarray(pts, float).reshape(-1, 2)
        if name in MODEL_CLASSES and len(p):
            out[name] = p
    return out


def _judge_classes(cam: Camera, data: FrameData, px: dict[str, np.ndarray], params: QAParams,
                   model: FieldModel) -> tuple[list[Finding], float]:
    """The findings of every class with a point ``far_px`` off the frame's camera or off the
    first-order camera without it (:func:`first_order_loo`), each judged again by the camera
    fitted without it (a class both fit is consistent with the others: nothing says it is
    wrong); and how close the worst class comes to a finding (its farthest point over
    ``far_px``)."""
    fitted = set(data.obs.lines) | set(data.obs.circles)
    proj = projected_classes(cam, model)
    far = params.px(params.far_px, cam.width)
    worst = {cls: float(np.max(distances(pts, proj.get(cls)))) for cls, pts in px.items()}
    frame_worst = dict(worst)  # under the frame's camera (worst grows with the screen below)
    suspects = {cls for cls, w in worst.items() if w > far}
    screen = first_order_loo(cam, data, params)
    findings, closest = [], 0.0
    for cls, pts in px.items():
        if cls in screen:  # a class that pulled the joint camera onto itself is off the one without it
            worst[cls] = max(worst[cls], float(np.max(class_distances(screen[cls], cls, pts, model))))
        if worst[cls] <= far:  # no point off: nothing to judge again
            closest = max(closest, worst[cls] / far)
            continue
        cam_c: Camera | None = cam
        skip: set[str] = {cls}
        if cls in fitted:  # without the class, and without the other gross suspects when enough is left
            cam_c, skip = loo_camera(cam, data, suspects | {cls}, params), suspects | {cls}
            if cam_c is None:
                cam_c, skip = loo_camera(cam, data, cls, params), {cls}
        spread = CameraSpread(cam_c or cam, data, skip, params)
        verdict = judge_class(cls, pts, cam_c or cam, cam_c is not None, px, model, spread)
        new = class_findings(verdict, cam.width, cam.height, params)
        if new and new[0].kind != "wrong_class" and cam_c is not None and cls in fitted and \
                consistent(cam_c, data, px, cls, suspects - {cls}, params, model, frame_worst):
            new = []
        findings += new
        if not new and np.isfinite(verdict.others):
            closest = max(closest, min(worst[cls], float(np.max(verdict.d))) / far)
    return findings, closest


def _camera_without(cam: Camera, data: FrameData, findings: list[Finding], params: QAParams) -> Camera:
    """The camera refitted without the classes found wrong (the camera itself when none are, or
    when the others cannot fix one)."""
    bad = {f.cls for f in findings if f.kind in ("wrong_class", "off_projection") and f.cls is not None}
    if not bad:
        return cam
    return loo_camera(cam, data, bad, params) or cam


#: how the frame's camera is fitted for judging it: the default pipeline with two RANSAC
#: thresholds and one candidate refined (on the first 100 SN22 frames: JaC@5 0.914 as the default's,
#: 12% less time)
QA_SETTINGS = FrameSettings(overrides={"ransac_thresholds": (10.0, 40.0), "refine_top": 1})


def frame_camera(ann: dict[str, np.ndarray], size: tuple[int, int], settings: FrameSettings,
                 model: FieldModel, priors: bool = True):
    """The frame's calibration and the class left out to get it (None: none). Without the
    broadcast-prior search first (slow, and a frame with keypoints enough does not need it); with
    it (``priors``) for a frame with too few keypoints. When the whole annotation gives no camera, one class
    may be what breaks it: each is left out in turn, and the camera that fits the others best
    (the smallest median class residual) is kept."""
    from dataclasses import replace

    fast = replace(settings, overrides={**settings.overrides, "prior_search": False})
    fc = calibrate_frame(FrameInputs(size, ann), fast, model)
    if fc.ok:
        return fc, None
    if fc.failure is not None and fc.failure.code in ("too_few_keypoints", "degenerate", "no_inliers") and priors:
        slow = calibrate_frame(FrameInputs(size, ann), settings, model)
        if slow.ok or len(ann) < 3:
            return slow, None
    best: tuple[FrameCalibration, str | None] = (fc, None)
    best_fit = np.inf
    for cls in ann if len(ann) >= 3 else ():
        fc_c = calibrate_frame(FrameInputs(size, {k: v for k, v in ann.items() if k != cls}), fast, model)
        if fc_c.ok and fc_c.result is not None and fc_c.result.line_residuals:
            fit = float(np.median(list(fc_c.result.line_residuals.values())))
            if fit < best_fit:
                best, best_fit = (fc_c, cls), fit
    return best


def check_frame(annotation: Mapping[str, np.ndarray], size: tuple[int, int] = EVAL_SIZE, detections=None,
                params: QAParams = QAParams(), model: FieldModel | None = None,
                settings: FrameSettings = QA_SETTINGS, calibration=None) -> FrameQA:
    """Judge one frame's annotation (SoccerNet, normalised: x_px = x (W - 1)) at ``size`` (W, H);
    with ``detections`` (PnLCalib format, :class:`pnlviz.data.Predictions`), compare them with it.
    ``calibration``: the frame's :class:`pnlviz.calib.frame.FrameCalibration` from its annotation
    when the caller has it already (the app's view of the frame), instead of calibrating it here.
    Never raises on bad geometry: a frame without a camera says so."""
    from pnlviz.calib.inputs import observations_from_predictions
    from pnlviz.calib.sources import aligned_detections

    model = model or load_field_model()
    t0 = time.perf_counter()
    ann = _normalised(annotation)
    W, H = size
    if calibration is not None and ann:
        fc = calibration
    else:
        fc, _ = frame_camera(ann, size, settings, model, params.prior_search) if ann else (None, None)
    if fc is None or not fc.ok:
        why, code = "no annotated class with geometry", "no_input"
        if fc is not None:
            res = fc.result
            failure = fc.failure or Failure(getattr(res, "failure_code", None) or "failed",
                                            getattr(res, "failure", None) or "not calibrated")
            why, code = failure.message, failure.code
        f = Finding("no_camera", f"the annotation gives no camera: {why}", 1.0, evidence={"failure": code})
        return FrameQA(frame_score([f]), [f], None, 1e3 * (time.perf_counter() - t0))
    cam = fc.result.camera
    data = FrameData.build(fc.observations, model)
    px = {k: v * [W - 1, H - 1] for k, v in ann.items()}
    findings, closest = _judge_classes(cam, data, px, params, model)
    judge = _camera_without(cam, data, findings, params)
    renamed = {f.fix["to"] for f in findings if f.kind == "wrong_class" and f.fix is not None}
    flagged = {f.cls for f in findings}
    proj = projected_classes(judge, model)
    agree = [float(np.max(distances(p, proj.get(n)))) for n, p in px.items() if n not in flagged]
    if agree and max(agree) <= params.px(params.far_px, W):  # a camera the whole annotation agrees with
        findings += missing_findings(judge, set(ann), model, params, renamed)
    if detections is not None:
        det = observations_from_predictions(detections, W, H, auxiliary=False, model=model)
        det = aligned_detections(fc.observations, det, model)
        findings += detection_findings(fc.observations, det, judge, px, params)
    findings.sort(key=lambda f: -f.severity)
    return FrameQA(frame_score(findings, 0.99 * min(closest, 1.0)), findings, judge,
                   1e3 * (time.perf_counter() - t0))


def apply_fix(annotation: Mapping[str, np.ndarray], fix: Mapping) -> dict[str, np.ndarray]:
    """The annotation with a finding's suggested fix applied (a new dict; the input is not
    changed): ``rename`` moves a class's points to another name (joining that class's points if
    it has some); ``drop_points`` removes points of a class by index (the class goes when none
    is left); ``move_points`` gives each point of a class a new position, ``add_class`` a class
    its points (normalised)."""
    out = {k: np.asarray(v, float).reshape(-1, 2).copy() for k, v in annotation.items()}
    op, cls = fix.get("op"), fix.get("class")
    if not isinstance(cls, str):
        raise ValueError(f"fix {fix!r}: 'class' must name a class")
    if cls not in out and op != "add_class":
        raise ValueError(f"fix {fix!r}: the annotation has no class {cls!r}")
    if op == "rename":
        pts = out.pop(cls)
        out[fix["to"]] = np.vstack([out[fix["to"]], pts]) if fix["to"] in out else pts
    elif op == "drop_points":
        keep = np.ones(len(out[cls]), dtype=np.bool_)
        keep[np.asarray(fix["points"], int)] = False
        if keep.any():
            out[cls] = out[cls][keep]
        else:
            del out[cls]
    elif op in ("add_class", "move_points"):
        pts = np.asarray(fix["points"], float).reshape(-1, 2)
        if op == "move_points" and len(pts) != len(out[cls]):
            raise ValueError(f"fix {fix!r}: {len(pts)} points for the {len(out[cls])} of {cls!r}")
        out[cls] = pts
    else:
        raise ValueError(f"unknown fix {fix!r}: op is one of rename, drop_points, move_points, add_class")
    return out


@dataclass
class FindingMarks:
    """What to draw for one finding, in pixels of the frame: ``annotated`` the class where the
    annotation put it (its points, in order; empty for a marking left out), ``expected`` where the
    judging camera puts the class (polylines: its trusted, visible parts; and the name a rename
    gives it), ``points`` the points the fix is about (the stray points it drops, where it
    moves or adds the class's points; for a keypoint, where the camera puts it)."""

    finding: Finding
    annotated: np.ndarray
    expected: list[np.ndarray]
    points: np.ndarray


def _visible_parts(uv: np.ndarray, ok: np.ndarray, W: int, H: int, margin: float) -> list[np.ndarray]:
    """The runs of consecutive trusted points of a projected polyline within ``margin`` px of the image."""
    with np.errstate(invalid="ignore"):
        keep = (ok & (uv[:, 0] > -margin) & (uv[:, 0] < W - 1 + margin)
                & (uv[:, 1] > -margin) & (uv[:, 1] < H - 1 + margin))
    cuts = np.flatnonzero(np.diff(keep.astype(np.int8)))
    bounds = np.concatenate([[0], cuts + 1, [len(uv)]])
    return [uv[a:b] for a, b in pairwise(bounds) if keep[a] and b - a >= 2]


def finding_marks(qa: FrameQA, annotation: Mapping[str, np.ndarray], size: tuple[int, int],
                  model: FieldModel | None = None) -> list[FindingMarks]:
    """Each finding of ``qa`` (the verdict on ``annotation``, normalised, at ``size``) as what to
    draw over the frame; a finding about nothing drawable (no camera) is left out."""
    model = model or load_field_model()
    W, H = size
    scale = np.array([W - 1, H - 1], float)
    cam = qa.camera.scaled(W, H) if qa.camera is not None else None
    ann = _normalised(annotation)
    polys = model.sample_polylines(0.5, 0.25)
    none = np.zeros((0, 2))
    out = []
    for f in qa.findings:
        annotated, expected, points = none, [], none
        if f.cls is not None:
            if f.cls in ann:
                annotated = ann[f.cls] * scale
            names = [f.cls] + ([f.fix["to"]] if f.fix and f.fix.get("op") == "rename" else [])
            for name in names:
                if cam is not None and name in polys:
                    expected += _visible_parts(*trusted_projection(cam, polys[name]), W, H, 0.1 * W)
        elif f.keypoint is not None and cam is not None and f.keypoint in model.keypoints:
            uv, ok = trusted_projection(cam, model.keypoint_xyz([f.keypoint]))  # as the classes' marks
            if ok.all():
                points = uv.reshape(-1, 2)
        fix = f.fix or {}
        if fix.get("op") == "drop_points" and len(annotated):
            points = annotated[np.asarray(fix["points"], int)]
        elif fix.get("op") in ("move_points", "add_class"):
            points = np.asarray(fix["points"], float).reshape(-1, 2) * scale
        if len(annotated) or expected or len(points):
            out.append(FindingMarks(f, annotated, expected, points))
    return out
