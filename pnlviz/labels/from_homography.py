"""Training labels of a frame whose ground-plane homography is known (WC14 / TS-WorldCup style
datasets: image + homography, no line annotation).

A homography ``H`` (field metres ``(X, Y, 1)`` at z = 0 -> pixels) fixes everything on the ground
plane exactly, and nothing above it. So:

* every **ground keypoint** (57 network ids less the goal-frame corners 12, 15, 16, 19 at
  z = -2.44 m) is the projection of its world point, kept when it lies inside the image and in
  front of the camera: no line fitting, intersection or Kp1/Kp2 disambiguation is needed;
* every **ground line** (line ids 1-6, 13-23) is its world segment projected and clipped to the
  image (exact extremities, not the extreme samples of an annotation);
* the **non-planar channels** (those four keypoints, the goal posts and crossbars, line ids 7-12)
  are unknown, not absent: their loss mask is 0, as in the paper's fine-tuning on homography
  datasets. So is the boundary channel's, which would otherwise teach that posts are no lines.

The left-right disambiguation is the one of :mod:`.leftright` (the azimuth of the view, measured
on ``H`` at the centroid of the visible ground keypoints); a mirrored view is labelled through
``H @ diag(-1, -1, 1)``, the evaluator's central symmetry of the pitch.

:func:`annotation_from_homography` also writes the ground classes as a SoccerNet-style annotation
(normalised points, ``x / (W - 1)``), for the tools that take one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pnlviz.field.model import FieldModel
from pnlviz.field.names import CLASS_TO_LINE_ID, STRAIGHT_CLASSES
from pnlviz.geometry.polylines import segment_in_image

from .catalogue import NETWORK_KEYPOINT_IDS, get_catalogue
from .heatmaps import N_KEYPOINT_CHANNELS, N_LINE_CHANNELS, heatmap_targets
from .leftright import LRDecision, lr_decision
from .types import KeypointLabel, KeypointLabels, LineExtremities

__all__ = ["HomographyLabels", "NON_PLANAR_KEYPOINT_IDS", "NON_PLANAR_LINE_IDS", "annotation_from_homography",
           "homography_for_size", "homography_training_targets", "labels_from_homography"]

#: WC14 / TS-WorldCup homographies are given for 1280 x 720 frames.
WC14_SIZE = (1280, 720)

#: Sample spacing (metres) along the circles written by :func:`annotation_from_homography`.
_SPACING = 1.0


def _non_planar(model: FieldModel) -> tuple[tuple[int, ...], tuple[int, ...]]:
    kps = tuple(k for k in NETWORK_KEYPOINT_IDS if abs(float(model.keypoints[k].xyz[2])) > 1e-9)
    lines = tuple(CLASS_TO_LINE_ID[n] for n in STRAIGHT_CLASSES if model.lines[n].plane != "ground")
    return kps, lines


def _default_model() -> FieldModel:
    return get_catalogue().model


NON_PLANAR_KEYPOINT_IDS, NON_PLANAR_LINE_IDS = _non_planar(_default_model())


@dataclass
class HomographyLabels:
    labels: KeypointLabels
    extremities: dict[int, LineExtremities]
    decision: LRDecision


def homography_for_size(H_template: np.ndarray, size: tuple[int, int], *, source_size: tuple[int, int] = WC14_SIZE,
                        model: FieldModel | None = None) -> np.ndarray:
    """A WC14-convention homography (template yards -> pixels of a ``source_size`` frame) as a
    field-metres -> pixels homography for a copy of the frame resized to ``size`` (W, H):
    ``S @ H @ template_from_field``, ``S`` the pixel map of a resize
    (:func:`pnlviz.labels.resize.resize_matrix`: pixel centres move by half a pixel, as
    ``cv2.resize`` moves them; the identity at the source size)."""
    from pnlviz.labels.resize import resize_matrix

    model = model or _default_model()
    S = resize_matrix(source_size, size)
    return S @ np.asarray(H_template, float) @ np.linalg.inv(model.template_to_field_matrix)


def template_homography(H_field: np.ndarray, size: tuple[int, int], *, source_size: tuple[int, int] = WC14_SIZE,
                        model: FieldModel | None = None) -> np.ndarray:
    """The inverse of :func:`homography_for_size`: a field-metres -> pixels homography of a copy
    resized to ``size`` (W, H) as the WC14 convention's template yards -> pixels of the
    ``source_size`` frame."""
    from pnlviz.labels.resize import resize_matrix

    model = model or _default_model()
    S = resize_matrix(source_size, size)
    return np.linalg.inv(S) @ np.asarray(H_field, float) @ model.template_to_field_matrix


def _front_sign(H: np.ndarray, width: int, height: int) -> float:
    """The sign of the homogeneous w of ground points in front of the camera: that of the ground
    point seen at the bottom centre of the image (a broadcast frame's bottom row is pitch)."""
    g = np.linalg.solve(H, np.array([0.5 * (width - 1), height - 1.0, 1.0]))
    return 1.0 if g[2] > 0 else -1.0


def _clip_segment(H: np.ndarray, a: np.ndarray, b: np.ndarray, sign: float, width: int, height: int,
                  eps: float = 1e-6) -> tuple[np.ndarray, np.ndarray] | None:
    """World ground segment a-b (X, Y) -> its visible part in pixels (p, q), or None. Clipped first
    against the camera's front half-space (w > 0, in world parameters, where the map is linear),
    then against the image rectangle [0, W-1] x [0, H-1] (Liang-Barsky on the projected segment)."""
    ha = sign * (H @ np.array([a[0], a[1], 1.0]))
    hb = sign * (H @ np.array([b[0], b[1], 1.0]))
    t0, t1 = 0.0, 1.0
    wa, wb = ha[2], hb[2]
    if wa <= eps and wb <= eps:
        return None
    if wa <= eps:
        t0 = (eps - wa) / (wb - wa)
    elif wb <= eps:
        t1 = (eps - wa) / (wb - wa)
    pa, pb = ha + t0 * (hb - ha), ha + t1 * (hb - ha)
    p, q = pa[:2] / pa[2], pb[:2] / pb[2]
    d = q - p
    inside = segment_in_image(p, q, width, height)
    if inside is None or np.hypot(*(d * (inside[1] - inside[0]))) < 1e-9:
        return None
    return p + inside[0] * d, p + inside[1] * d


def _ordered(p: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The :class:`LineExtremities` order: smaller x first for lines closer to horizontal, smaller
    y first otherwise."""
    d = q - p
    axis = 0 if abs(d[0]) >= abs(d[1]) else 1
    return (p, q) if p[axis] <= q[axis] else (q, p)


def labels_from_homography(H: np.ndarray, width: int, height: int, *, lr_disambiguation: bool = True,
                           model: FieldModel | None = None) -> HomographyLabels:
    """Keypoint labels (set ``"Kp3"``, homography-projected) and ground-line extremities of a
    ``width`` x ``height`` frame whose field -> image ground homography is ``H``."""
    cat = get_catalogue(model)
    model = cat.model
    H = np.asarray(H, float)
    non_planar_kp, non_planar_lines = _non_planar(model)
    sign = _front_sign(H, width, height)
    ground_ids = [k for k in NETWORK_KEYPOINT_IDS if k not in non_planar_kp]

    def project(Hm: np.ndarray) -> dict[int, np.ndarray]:
        xyz = cat.world_xyz(ground_ids)
        h = sign * (np.column_stack([xyz[:, 0], xyz[:, 1], np.ones(len(xyz))]) @ Hm.T)
        out = {}
        for kid, v in zip(ground_ids, h):
            if v[2] <= 1e-9:
                continue
            x, y = v[0] / v[2], v[1] / v[2]
            if 0.0 <= x <= width - 1 and 0.0 <= y <= height - 1:
                out[kid] = np.array([x, y])
        return out

    inside = project(H)
    decision = LRDecision(False, False, None, "left-right disambiguation off")
    if lr_disambiguation:
        at = np.mean(list(inside.values()), axis=0) if inside else np.array([0.5 * (width - 1), 0.75 * height])
        decision = lr_decision(H, at)
    Hm = H @ np.diag([-1.0, -1.0, 1.0]) if decision.mirror else H
    if decision.mirror:
        inside = project(Hm)
    labels = KeypointLabels(width, height, homography=Hm, mirrored=decision.mirror,
                            annotated_classes=frozenset(n for n, s in model.lines.items() if s.plane == "ground"),
                            disambiguation="homography")
    labels.keypoints = {k: KeypointLabel(k, float(p[0]), float(p[1]), True, "Kp3") for k, p in sorted(inside.items())}
    labels.notes.append(f"labels projected through a ground homography ({decision.reason})")
    extremities: dict[int, LineExtremities] = {}
    for name in STRAIGHT_CLASSES:
        lid = CLASS_TO_LINE_ID[name]
        if lid in non_planar_lines:
            continue
        seg = model.lines[name]
        clipped = _clip_segment(Hm, seg.start[:2], seg.end[:2], sign, width, height)
        if clipped is None:
            continue
        p, q = _ordered(*clipped)
        n = max(2, int(np.ceil(np.hypot(*(q - p)) / 8.0)) + 1)  # a point every <= 8 px along the line
        pts = p + np.linspace(0.0, 1.0, n)[:, None] * (q - p)
        extremities[lid] = LineExtremities(lid, name, p.copy(), q.copy(), pts)
    return HomographyLabels(labels, extremities, decision)


def homography_training_targets(H: np.ndarray, width: int, height: int, *, sigma: float = 2.0, downsample: int = 2,
                                model: FieldModel | None = None):
    """``(labels, extremities, targets)`` like :func:`pnlviz.labels.training_targets`, from a
    ground homography: the non-planar keypoint and line channels and the boundary channel are
    masked out of the loss (see the module docstring)."""
    model = model or _default_model()
    hl = labels_from_homography(H, width, height, model=model)
    t = heatmap_targets(hl.labels, hl.extremities, width, height, sigma=sigma, downsample=downsample, model=model,
                        boundary=False)
    kp_ids, line_ids = _non_planar(model)
    kp_mask = np.ones(N_KEYPOINT_CHANNELS, np.float32)
    kp_mask[np.array(kp_ids, int) - 1] = 0.0
    line_mask = np.ones(N_LINE_CHANNELS, np.float32)
    line_mask[np.array(line_ids, int) - 1] = 0.0
    line_mask[N_LINE_CHANNELS - 1] = 0.0
    t.keypoint_mask, t.line_mask = kp_mask, line_mask
    return hl.labels, hl.extremities, t


def annotation_from_homography(H: np.ndarray, width: int, height: int, *, lr_disambiguation: bool = False,
                               model: FieldModel | None = None) -> dict[str, list[dict[str, float]]]:
    """The ground classes seen through ``H`` as a SoccerNet-style annotation (``{class: [{"x",
    "y"}]}``, normalised by ``(W - 1, H - 1)``): straight classes by their clipped extremities and
    points every <= 8 px between, circles by their samples inside the image."""
    model = model or _default_model()
    hl = labels_from_homography(H, width, height, lr_disambiguation=lr_disambiguation, model=model)
    Hm = hl.labels.homography
    assert Hm is not None  # labels_from_homography records the homography it projected through
    scale = np.array([width - 1.0, height - 1.0])
    out: dict[str, list[dict[str, float]]] = {}
    for e in hl.extremities.values():
        out[e.name] = [{"x": float(x), "y": float(y)} for x, y in e.points / scale]
    sign = _front_sign(Hm, width, height)
    for name, pts in model.sample_polylines(_SPACING, 0.5).items():
        if name in out or name in STRAIGHT_CLASSES:
            continue
        h = sign * (np.column_stack([pts[:, 0], pts[:, 1], np.ones(len(pts))]) @ Hm.T)
        ok = h[:, 2] > 1e-9
        xy = h[ok, :2] / h[ok, 2:3]
        xy = xy[(xy[:, 0] >= 0) & (xy[:, 0] <= width - 1) & (xy[:, 1] >= 0) & (xy[:, 1] <= height - 1)]
        if len(xy) >= 2:
            out[name] = [{"x": float(x), "y": float(y)} for x, y in xy / scale]
    return out
