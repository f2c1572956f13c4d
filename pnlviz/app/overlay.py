"""What the app draws over a frame, as geometry in image pixels: the pitch projected through the
known, the initial (voted) and the refined camera, the annotated lines, the detector's lines, the
keypoints coloured by set, their residuals, "ghosts" (catalogue keypoints the camera puts in
the frame that nobody observed: click one to choose its id, drag it to place it), and the label-error
finder's findings (the class where the annotation put it and where the camera expects it).

:func:`overlay_geometry` is pure; :mod:`pnlviz.app.workspace` turns it into the marks the page
draws over the frame (:mod:`pnlviz.app.pagedraw`; the frame image itself is sent once per frame).
:func:`render` draws the same on the pixels, for pictures and for the 3D view's frustum.
"""

from __future__ import annotations

from collections.abc import Set
from dataclasses import dataclass, field

import cv2
import numpy as np

from pnlviz.app.state import FrameView
from pnlviz.field.model import FieldModel, load_field_model
from pnlviz.geometry.lens import imaged
from pnlviz.geometry.polylines import project_polylines
from pnlviz.viz import (
    FINDING_ANNOTATED_RGB,
    FINDING_EXPECTED_RGB,
    blank_canvas,
    caption,
    class_colour,
    draw_annotation,
    draw_findings,
    draw_pitch,
    ring,
)

#: RGB colours of the keypoint sets, as in the paper's figure (Kp red, Kpe yellow, Kp1 blue,
#: Kp2 pink, Kp3 green)
SET_RGB = {"Kp": (230, 40, 40), "Kpe": (255, 220, 0), "Kp1": (30, 120, 255), "Kp2": (255, 90, 200),
           "Kp3": (60, 200, 60)}
INITIAL_RGB = (0, 200, 255)  # cyan-blue: pitch through the voted camera, before PnL
REFINED_RGB = (255, 220, 60)  # amber: pitch through the final camera
CASING_RGB = (30, 24, 0)  # a dark edge under the amber pitch: it stays visible on the white markings
REFERENCE_RGB = (255, 80, 255)  # magenta: pitch through a known camera (synthetic ground truth)
RESIDUAL_RGB = (255, 0, 0)
DETECTED_RGB = (255, 255, 255)  # white: detected line extremities
GHOST_RGB = (200, 200, 200)
PIN_RGB = (0, 0, 0)  # black box: a pinned keypoint (placed or moved by hand)
OCCLUDED_RGB = (128, 128, 128)  # an occluded keypoint's colour is mixed half with this grey
FLAGGED_RGB = (255, 90, 0)  # orange box: a pinned keypoint the camera cannot agree with

#: BGR of the same, for OpenCV drawing
SET_BGR = {k: v[::-1] for k, v in SET_RGB.items()}

#: what each layer is, for the legend: name -> (colour, description)
LEGEND = {
    "refined_pitch": (REFINED_RGB, "pitch through the calibrated camera"),
    "initial_pitch": (INITIAL_RGB, "pitch through the voted camera, before PnL"),
    "reference_pitch": (REFERENCE_RGB, "pitch through the known camera"),
    "residuals": (RESIDUAL_RGB, "keypoint -> where the camera puts it"),
    "detected_lines": (DETECTED_RGB, "detected line extremities"),
    "ghosts": (GHOST_RGB, "not observed: click to choose, drag to place"),
    "pins": (PIN_RGB, "box: pinned (placed by hand); the camera is fitted to it"),
    "flagged": (FLAGGED_RGB, "orange box: pinned, but the camera cannot agree with it"),
    "finding_annotated": (FINDING_ANNOTATED_RGB, "label error: the class where the annotation put it"),
    "finding_expected": (FINDING_EXPECTED_RGB, "label error: where the camera expects it; circled: the fix"),
}


@dataclass
class Layers:
    annotation: bool = True
    keypoints: bool = True
    ids: bool = True
    initial_pitch: bool = False
    refined_pitch: bool = True
    residuals: bool = True
    reference_pitch: bool = True
    detected_lines: bool = True
    ghosts: bool = True
    findings: bool = True


@dataclass
class Segments:
    """Line segments in image pixels: ``points`` (N, 2, 2), ``colors`` (N, 3) RGB uint8."""

    points: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 2)))
    colors: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), np.uint8))

    def __len__(self) -> int:
        return len(self.points)

    @classmethod
    def from_polylines(cls, polylines, color) -> Segments:
        """Consecutive points of each polyline joined; one colour for all, or one per polyline."""
        pts, cols = [], []
        for i, line in enumerate(polylines):
            line = np.asarray(line, float).reshape(-1, 2)
            if len(line) < 2:
                continue
            pts.append(np.stack([line[:-1], line[1:]], axis=1))
            c = color[i] if isinstance(color, list) else color
            cols.append(np.tile(np.asarray(c, np.uint8), (len(line) - 1, 1)))
        if not pts:
            return cls()
        return cls(np.concatenate(pts), np.concatenate(cols))


@dataclass
class Markers:
    """Points to draw and grab: ``keys`` (what each is: a keypoint id, or (class, index) of an
    annotated point), ``uv`` (N, 2) pixels, ``colors`` (N, 3) RGB uint8, ``labels`` (N,) text."""

    keys: list = field(default_factory=list)
    uv: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    colors: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), np.uint8))
    labels: list[str] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.keys)


@dataclass
class Overlay:
    """Everything drawn over one frame, in image pixels."""

    segments: dict[str, Segments]  # layer name -> segments
    keypoints: Markers  # observed keypoints (key: id)
    ghosts: Markers  # catalogue keypoints the camera puts in the frame, not observed (key: id)
    line_points: Markers  # points of the annotated lines and circles (key: (class, index))
    residuals: dict[int, float]  # keypoint id -> reprojection error, pixels
    pinned: list[int] = field(default_factory=list)  # observed keypoints placed or moved by hand
    flagged: dict[int, float] = field(default_factory=dict)  # pinned ids the camera cannot agree with -> px


#: how far a drawn pitch line may stray from the projected one, image pixels (0.4 screen pixels at
#: 4x): the projection is sampled finely (0.5 m along lines, 0.25 m along circles) and then
#: simplified to this tolerance, which leaves about a seventh of the segments (straight lines
#: collapse to a few, curves keep what they need) and so a seventh of the browser's work
PITCH_TOLERANCE_PX = 0.1


def simplify_polyline(uv: np.ndarray, tolerance: float = PITCH_TOLERANCE_PX) -> np.ndarray:
    """``uv`` (N, 2) with the points removed that lie within ``tolerance`` of the polyline
    through the others (Douglas-Peucker); the end points stay."""
    uv = np.asarray(uv, float).reshape(-1, 2)
    if len(uv) < 3:
        return uv
    origin = uv.min(axis=0)  # float32 inside OpenCV: keep the numbers small
    kept = cv2.approxPolyDP((uv - origin).astype(np.float32).reshape(-1, 1, 2), tolerance, False)
    return kept.reshape(-1, 2).astype(float) + origin


def _pitch(camera, W: int, H: int, model: FieldModel, color) -> Segments:
    polys = project_polylines(camera.scaled(W, H) if (camera.width, camera.height) != (W, H) else camera,
                              model.sample_polylines(0.5, 0.25), W, H, skip_folded=True)
    return Segments.from_polylines([simplify_polyline(p) for p in polys.values()], color)


def _ghosts(view: FrameView, model: FieldModel, hidden: set[int]) -> Markers:
    cam = view.camera
    if cam is None:
        return Markers()
    W, H = view.size
    seen = {int(k) for k in view.observations.kp_ids} if view.observations is not None else set()
    ids = [int(k) for k in model.keypoint_ids if int(k) not in seen and int(k) not in hidden]
    if not ids:
        return Markers()
    xyz = model.keypoint_xyz(ids)
    uv = cam.project(xyz)  # NaN behind the camera: never inside
    with np.errstate(invalid="ignore"):
        inside = (uv[:, 0] >= 0) & (uv[:, 0] <= W - 1) & (uv[:, 1] >= 0) & (uv[:, 1] <= H - 1) & imaged(cam, xyz)
    keep = [i for i in range(len(ids)) if inside[i]]
    return Markers([ids[i] for i in keep], uv[keep].reshape(-1, 2),
                   np.tile(np.array(GHOST_RGB, np.uint8), (len(keep), 1)), [str(ids[i]) for i in keep])


def finding_segments(marks) -> dict[str, Segments]:
    """Label-error findings (:func:`pnlviz.calib.qa.finding_marks`) as two layers: the classes as
    annotated, and where the camera expects them with the fix's points circled."""
    annotated = [m.annotated for m in marks if len(m.annotated) >= 2]
    annotated += [ring(p, 3.0, 8) for m in marks for p in m.annotated]
    expected = [part for m in marks for part in m.expected] + [ring(p, 8.0) for m in marks for p in m.points]
    return {"finding_annotated": Segments.from_polylines(annotated, FINDING_ANNOTATED_RGB),
            "finding_expected": Segments.from_polylines(expected, FINDING_EXPECTED_RGB)}


def overlay_geometry(view: FrameView, layers: Layers = Layers(), model: FieldModel | None = None,
                     hidden: Set[int] = frozenset(), findings=(), occluded: Set[int] = frozenset()) -> Overlay:
    """The overlays of ``view`` that ``layers`` asks for. ``hidden``: keypoint ids marked absent
    (no ghost is offered for them); ``findings``: the frame's label-error findings to draw
    (:func:`pnlviz.calib.qa.finding_marks`); ``occluded``: keypoint ids marked occluded, drawn
    greyed with their id in brackets ("(12)")."""
    model = model or load_field_model()
    W, H = view.size
    res = view.result
    seg: dict[str, Segments] = {}
    if layers.reference_pitch and view.reference_camera is not None:
        seg["reference_pitch"] = _pitch(view.reference_camera, W, H, model, REFERENCE_RGB)
    if res is not None and res.ok:
        if layers.initial_pitch and res.initial_camera is not None:
            seg["initial_pitch"] = _pitch(res.initial_camera, W, H, model, INITIAL_RGB)
        if layers.refined_pitch:
            seg["refined_pitch"] = _pitch(res.camera, W, H, model, REFINED_RGB)
            pitch = seg["refined_pitch"]
            casing = np.tile(np.array(CASING_RGB, np.uint8), (len(pitch), 1))
            seg["refined_pitch_casing"] = Segments(pitch.points, casing)
    line_points = Markers()
    if view.annotation:
        names = list(view.annotation)
        polys = [np.asarray(view.annotation[n], float).reshape(-1, 2) * [W - 1, H - 1] for n in names]
        colours = [class_colour(n)[::-1] for n in names]
        if layers.annotation:
            seg["annotation"] = Segments.from_polylines(polys, colours)
        keys = [(n, i) for n, p in zip(names, polys) for i in range(len(p))]
        cols = [c for c, p in zip(colours, polys) for _ in range(len(p))]
        uv = np.concatenate(polys) if keys else np.zeros((0, 2))
        line_points = Markers(keys, uv, np.array(cols, np.uint8).reshape(-1, 3), [n.strip() for n, _ in keys])
    if layers.detected_lines and view.detections is not None:
        ends = [((x1, y1), (x2, y2)) for x1, y1, _, x2, y2, _ in view.detections.lines_px(W, H).values()]
        seg["detected_lines"] = Segments.from_polylines(ends, DETECTED_RGB)
    obs = view.observations
    markers, residuals = Markers(), {}
    if obs is not None and obs.n_keypoints:
        ids = [int(k) for k in obs.kp_ids]
        kp_colours = np.array([SET_RGB.get(str(s), (255, 255, 255)) for s in obs.kp_sets], np.uint8)
        dim = np.array([k in occluded for k in ids], bool)
        kp_colours[dim] = (kp_colours[dim].astype(np.uint16) + OCCLUDED_RGB) // 2
        markers = Markers(ids, obs.kp_xy.copy(), kp_colours, [f"({k})" if k in occluded else str(k) for k in ids])
        camera = res.camera if res is not None else None  # None unless res.ok
        if camera is not None:
            proj = camera.project(obs.kp_xyz)
            good = np.all(np.isfinite(proj), axis=1)
            residuals = {k: float(np.hypot(*(proj[i] - obs.kp_xy[i]))) for i, k in enumerate(ids) if good[i]}
            if layers.residuals and good.any():
                seg["residuals"] = Segments(np.stack([obs.kp_xy[good], proj[good]], axis=1),
                                            np.tile(np.array(RESIDUAL_RGB, np.uint8), (int(good.sum()), 1)))
    if layers.findings and findings:
        seg.update(finding_segments(findings))
    ghosts = _ghosts(view, model, set(hidden)) if layers.ghosts else Markers()
    pinned = [int(k) for k in obs.kp_ids[obs.pins]] if obs is not None else []
    flagged = dict(res.flagged) if res is not None and res.ok else {}
    return Overlay(seg, markers, ghosts, line_points, residuals, pinned, flagged)


def render(view: FrameView, image: np.ndarray | None, layers: Layers = Layers(), max_width: int = 1280,
           findings=()) -> np.ndarray:
    """The frame (``image``, BGR, or a neutral canvas when None) with its overlays drawn on the
    pixels, RGB uint8, at most ``max_width`` wide (for pictures and the 3D view's frustum);
    ``findings`` as :func:`overlay_geometry`."""
    W, H = view.size
    img = image.copy() if image is not None else blank_canvas(W, H)
    res = view.result
    if layers.reference_pitch and view.reference_camera is not None:
        draw_pitch(img, view.reference_camera, colour=REFERENCE_RGB[::-1], thickness=1)
    camera = res.camera if res is not None else None  # None unless res.ok
    if res is not None and camera is not None:
        if layers.initial_pitch and res.initial_camera is not None:
            draw_pitch(img, res.initial_camera, colour=INITIAL_RGB[::-1], thickness=1)
        if layers.refined_pitch:
            draw_pitch(img, camera, colour=REFINED_RGB[::-1], thickness=2)
    if layers.annotation and view.annotation:
        draw_annotation(img, view.annotation, thickness=1, radius=2)
    if layers.findings and findings:
        draw_findings(img, findings)
    geom = overlay_geometry(view, Layers(annotation=False, initial_pitch=False, refined_pitch=False,
                                         reference_pitch=False, ghosts=False, detected_lines=layers.detected_lines,
                                         residuals=layers.residuals))
    for name in ("detected_lines", "residuals"):
        s = geom.segments.get(name)
        for (a, b), c in zip(s.points if s is not None else (), s.colors if s is not None else ()):
            cv2.line(img, tuple(int(round(x)) for x in a), tuple(int(round(x)) for x in b),
                     tuple(int(x) for x in c[::-1]), 1 if name == "residuals" else 2, cv2.LINE_AA)
    if layers.keypoints:
        for (x, y), col, label in zip(geom.keypoints.uv, geom.keypoints.colors, geom.keypoints.labels):
            c = (int(round(x)), int(round(y)))
            cv2.circle(img, c, 5, (0, 0, 0), 2, cv2.LINE_AA)
            cv2.circle(img, c, 4, tuple(int(v) for v in col[::-1]), -1, cv2.LINE_AA)
            if layers.ids:
                cv2.putText(img, label, (c[0] + 6, c[1] - 6), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 0), 3, cv2.LINE_AA)
                cv2.putText(img, label, (c[0] + 6, c[1] - 6), cv2.FONT_HERSHEY_SIMPLEX, 0.45,
                            tuple(int(v) for v in col[::-1]), 1, cv2.LINE_AA)
    if view.error or (res is not None and not res.ok):
        caption(img, f"{view.stem}: {view.error or (res.failure if res is not None else '')}")
    if W > max_width:
        img = cv2.resize(img, (max_width, int(round(H * max_width / W))), interpolation=cv2.INTER_AREA)
    return img[:, :, ::-1].copy()
