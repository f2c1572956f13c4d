"""Where a frame's observations come from, and how sources combine: the annotation and the
detections merged (the side convention resolved), and keypoint edits applied on top. Pure."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from functools import lru_cache

import numpy as np

from pnlviz.calib.observations import Observations
from pnlviz.field.model import FieldModel
from pnlviz.field.names import MIRROR

#: a keypoint edit: its new pixel position, or None for "not visible"
KeypointEdit = Sequence[float] | None


@lru_cache(maxsize=4)
def mirror_ids(model: FieldModel) -> dict[int, int]:
    """Keypoint id -> the id at the point mirrored through the pitch centre ((x, y) -> (-x, -y))."""
    ids = model.keypoint_ids
    xyz = model.keypoint_xyz(ids)
    out = {}
    for i, p in zip(ids, xyz):
        d = np.linalg.norm(xyz - p * [-1, -1, 1], axis=1)
        j = int(np.argmin(d))
        if d[j] < 1e-6:
            out[int(i)] = int(ids[j])
    return out


def mirrored(det: Observations, model: FieldModel) -> Observations:
    """The detections with their ids and line classes mirrored through the pitch centre."""
    mirror = mirror_ids(model)
    ids = np.array([mirror.get(int(i), int(i)) for i in det.kp_ids], int)
    return Observations(det.width, det.height, ids, det.kp_xy, model.keypoint_xyz(ids, pnlcalib=True), det.kp_sets,
                        det.kp_main, {MIRROR[k]: v for k, v in det.lines.items()},
                        {MIRROR[k]: v for k, v in det.circles.items()}, det.pins, det.derived)


def aligned_detections(ann: Observations, det: Observations, model: FieldModel) -> Observations:
    """The detections named on the annotation's sides: mirrored (ids and line classes) when they
    agree better with the annotation that way (keypoints with the same ids, median distance)."""
    mirror = mirror_ids(model)
    ann_xy = dict(zip(ann.kp_ids.tolist(), ann.kp_xy))
    det_xy = dict(zip(det.kp_ids.tolist(), det.kp_xy))

    def disagreement(mapping) -> float:
        d = [np.linalg.norm(ann_xy[i] - det_xy[j]) for i, j in mapping.items() if i in ann_xy and j in det_xy]
        return float(np.median(d)) if d else np.inf

    if disagreement({i: mirror.get(i, -1) for i in ann_xy}) < disagreement({i: i for i in ann_xy}):
        return mirrored(det, model)
    return det


def merge_observations(ann: Observations, det: Observations, model: FieldModel) -> Observations:
    """Annotation and detections together. PnLCalib's networks name the sides so that the goal
    nearest the camera is the left one, annotations name the true sides: when the detections
    agree better with the annotation mirrored (keypoints with the same ids, median distance),
    their ids and line classes are mirrored first. The annotation wins where both have a point
    or a class."""
    det = aligned_detections(ann, det, model)
    keep = ~np.isin(det.kp_ids, ann.kp_ids)
    return Observations(ann.width, ann.height, np.concatenate([ann.kp_ids, det.kp_ids[keep]]),
                        np.vstack([ann.kp_xy, det.kp_xy[keep]]), np.vstack([ann.kp_xyz, det.kp_xyz[keep]]),
                        np.concatenate([ann.kp_sets, det.kp_sets[keep]]),
                        np.concatenate([ann.kp_main, det.kp_main[keep]]), {**det.lines, **ann.lines},
                        {**det.circles, **ann.circles},
                        np.concatenate([ann.pins, det.pins[keep]]), np.concatenate([ann.derived, det.derived[keep]]))


def apply_keypoint_edits(obs: Observations, edits: Mapping[str, KeypointEdit], model: FieldModel) -> Observations:
    """Observations with keypoint edits applied: ``{"id": [x, y]}`` moves or adds a keypoint (at
    the catalogue position; a hand put it there, so it is pinned), ``{"id": None}`` removes it
    (not visible). A detected point of a marking where nothing painted marks it was also a point
    of that marking (:func:`pnlviz.calib.inputs.observations_from_predictions`): it leaves the
    marking with the keypoint."""
    ids, xy = list(obs.kp_ids), [tuple(p) for p in obs.kp_xy]
    sets, main, pinned, derived = list(obs.kp_sets), list(obs.kp_main), list(obs.pins), list(obs.derived)
    markings = {**obs.lines, **obs.circles}
    unmarked = model.unmarked_points()
    for key, value in edits.items():
        kid = int(key)
        if kid in ids:
            i = ids.index(kid)
            if kid in unmarked and derived[i] and unmarked[kid] in markings:
                markings[unmarked[kid]] = _without(markings[unmarked[kid]], xy[i])
            for lst in (ids, xy, sets, main, pinned, derived):
                lst.pop(i)
        if value is not None:
            ids.append(kid)
            xy.append((float(value[0]), float(value[1])))
            group = model.keypoints[kid].group
            sets.append(group)
            main.append(group == "Kp")
            pinned.append(True)
            derived.append(False)
    ids_arr = np.array(ids, int)
    lines = {k: v for k, v in markings.items() if k in obs.lines and len(v)}
    circles = {k: v for k, v in markings.items() if k in obs.circles and len(v)}
    return Observations(obs.width, obs.height, ids_arr, np.array(xy, float).reshape(-1, 2), model.keypoint_xyz(ids_arr),
                        np.array(sets, dtype="<U3"), np.array(main, bool), lines, circles,
                        np.array(pinned, bool), np.array(derived, bool))


def _without(points: np.ndarray, xy: Sequence[float]) -> np.ndarray:
    """``points`` without its first row at ``xy`` (all of them when no row is there)."""
    points = np.asarray(points, float)
    hit = np.flatnonzero(np.all(points == np.asarray(xy, float), axis=1))
    return np.delete(points, hit[:1], axis=0)
