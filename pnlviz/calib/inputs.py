"""Turn the two kinds of input into :class:`Observations`: PnLCalib 2D detections, and SoccerNet
line annotations (through the keypoint labels of :mod:`pnlviz.labels`)."""

from __future__ import annotations

import hashlib
import threading
from collections import OrderedDict
from collections.abc import Mapping, Set
from dataclasses import replace
from typing import Protocol

import numpy as np

from pnlviz.calib.observations import Observations
from pnlviz.field.model import FieldModel, load_field_model
from pnlviz.field.names import LINE_ID_TO_CLASS
from pnlviz.geometry.conics import fit_line, intersect_lines

class Detections(Protocol):
    """PnLCalib-format detections of one frame, as the engine reads them (what
    :class:`pnlviz.data.Predictions` is): normalised positions and confidences."""

    @property
    def keypoints(self) -> Mapping[int, tuple[float, float, float]]: ...  # id -> (x, y, p)

    @property
    def lines(self) -> Mapping[int, tuple[float, float, float, float, float, float]]: ...  # id -> 2 ends, each x, y, p


#: Keypoint ids PnLCalib's published networks predict (1..57; 58-73 are not predicted).
PREDICTED_KEYPOINTS = range(1, 58)


def auxiliary_keypoints(lines: dict[str, np.ndarray], width: int, height: int, model: FieldModel,
                        skip: Set[int] = frozenset(), beyond: float = 0.5) -> dict[int, tuple[float, float]]:
    """Keypoints at the intersections of pairs of observed straight lines (catalogue ``line_line``
    and ``extended_line_line`` definitions), kept when inside the image or at most ``beyond`` of
    its size outside it (the paper's rule for extended intersections)."""
    out = {}
    for kp in model.keypoints.values():
        d = kp.definition
        if kp.id in skip or d["kind"] not in ("line_line", "extended_line_line"):
            continue
        a, b = d["lines"]
        if a not in lines or b not in lines:
            continue
        pa, pb = lines[a], lines[b]
        x = intersect_lines(fit_line(pa), fit_line(pb))
        if x is None:
            continue
        if -beyond * width <= x[0] <= (1 + beyond) * width and -beyond * height <= x[1] <= (1 + beyond) * height:
            out[kp.id] = (float(x[0]), float(x[1]))
    return out


def on_their_markings(keypoints: Mapping[int, tuple[float, float]], lines: Mapping[str, np.ndarray],
                      circles: Mapping[str, np.ndarray],
                      model: FieldModel) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray], list[int]]:
    """``(lines, circles, ids)``: the lines and circles with the measured keypoints that no paint
    marks (:meth:`FieldModel.unmarked_points`) added as points of their marking, and those
    keypoints' ids (to be marked ``kp_derived``). The inputs are not changed.

    Id 52 too, from PnLCalib's networks, whose table puts it 0.15 m inside the centre circle
    (x = 9.0): their WC14 detections of it sit 9.03 m from the centre under the calibrated
    cameras, yet as a point of the circle it gave FS@5 0.949 on WC14 against 0.942 as a keypoint
    at the table's place (measured with a first version of the rule; its place along the circle
    is the worse error)."""
    lines, circles = dict(lines), dict(circles)
    unmarked = model.unmarked_points()
    ids = sorted(k for k in keypoints if k in unmarked)
    for kid in ids:
        marking = circles if unmarked[kid] in model.circles else lines
        marking[unmarked[kid]] = np.vstack([marking.get(unmarked[kid], np.zeros((0, 2))), [keypoints[kid][:2]]])
    return lines, circles, ids


def observations_from_predictions(pred: Detections, width: int, height: int, *, kp_threshold: float = 0.1,
                                  line_threshold: float = 0.1, auxiliary: bool = True,
                                  model: FieldModel | None = None) -> Observations:
    """Observations from PnLCalib-format detections (``pnlviz.data.Predictions``), in pixels of a
    ``width`` x ``height`` image (x_px = x * W). Keypoints use PnLCalib's positions (id 52 at
    x = 9.0, where its networks were trained). Lines are the two detected extremities of each
    line whose both ends pass ``line_threshold``; the intersections of detected line pairs add
    auxiliary keypoints where the network found none (the paper's augmentation; marked
    ``kp_derived``). A detected point of a line or circle where nothing painted marks it
    (:meth:`FieldModel.unmarked_points`) is also a point of that line or circle, and its keypoint
    is marked ``kp_derived``: where the lines and circles fix the camera, the refinement holds it
    to its marking only (across it, where the paint is), not to its place along it."""
    model = model or load_field_model()
    kps = {}
    for kid, (x, y, p) in pred.keypoints.items():
        if kid in PREDICTED_KEYPOINTS and p >= kp_threshold:
            kps[int(kid)] = (x * width, y * height)
    lines = {}
    for lid, (x1, y1, p1, x2, y2, p2) in pred.lines.items():
        if p1 >= line_threshold and p2 >= line_threshold and (x1, y1) != (x2, y2):
            lines[LINE_ID_TO_CLASS[int(lid)]] = np.array([[x1 * width, y1 * height], [x2 * width, y2 * height]])
    sets = {k: model.keypoints[k].group for k in kps}
    aux = auxiliary_keypoints(lines, width, height, model, skip=set(kps)) if auxiliary else {}
    lines, circles, unmarked = on_their_markings(kps, lines, {}, model)
    if aux:
        kps.update(aux)
        sets.update({k: "Kpe" for k in aux})
    obs = Observations.from_keypoints(width, height, kps, sets, lines=lines, circles=circles, pnlcalib_positions=True,
                                      model=model)
    return replace(obs, kp_derived=np.isin(obs.kp_ids, [*aux, *unmarked]))


#: annotations whose observations :func:`annotation_observations` keeps (the frames being edited)
ANNOTATION_CACHE = 16
_annotation_cache: OrderedDict[tuple, tuple[FieldModel, Observations]] = OrderedDict()
_annotation_lock = threading.Lock()


def _read_only(obs: Observations) -> Observations:
    """``obs`` with every array frozen (a cached value shared by its callers must not change)."""
    arrays = [obs.kp_ids, obs.kp_xy, obs.kp_xyz, obs.kp_sets, obs.kp_main, obs.kp_pinned, obs.kp_derived,
              *obs.lines.values(), *obs.circles.values()]
    for a in arrays:
        if isinstance(a, np.ndarray):
            a.setflags(write=False)
    return obs


def annotation_observations(annotation: Mapping[str, np.ndarray], width: int, height: int,
                            model: FieldModel) -> Observations:
    """:func:`observations_from_annotation`'s observations, computed once per annotation: a frame
    whose keypoints are dragged is calibrated again and again from one annotation (the keypoint
    labels take 1-12 ms of a 20-30 ms recalibration). The arrays are read-only; the dicts are
    each caller's own."""
    digest = hashlib.blake2b(digest_size=16)
    for name in sorted(annotation):
        a = np.ascontiguousarray(np.asarray(annotation[name], float))
        digest.update(f"{name}|{a.shape}|".encode())
        digest.update(a.tobytes())
    key = (digest.digest(), int(width), int(height), id(model))
    with _annotation_lock:
        hit = _annotation_cache.get(key)
        if hit is not None and hit[0] is model:  # the model is kept with it: its id is not reused
            _annotation_cache.move_to_end(key)
            obs = hit[1]
            return replace(obs, lines=dict(obs.lines), circles=dict(obs.circles))
    obs = _read_only(observations_from_annotation(annotation, width, height, model=model)[0])
    with _annotation_lock:
        _annotation_cache[key] = (model, obs)
        while len(_annotation_cache) > ANNOTATION_CACHE:
            _annotation_cache.popitem(last=False)
    return replace(obs, lines=dict(obs.lines), circles=dict(obs.circles))


def observations_from_annotation(annotation: Mapping[str, np.ndarray], width: int, height: int, *,
                                 label_params=None, model: FieldModel | None = None):
    """Observations from a SoccerNet annotation (normalised, x_px = x (W - 1)): the keypoint
    labels of every set (:func:`pnlviz.labels.keypoints_from_annotation`, all ``kp_derived``: they
    are computed from the lines) and the annotated points of every straight class and circle.
    Returns ``(observations, labels)``."""
    from pnlviz.labels import LabelParams, keypoints_from_annotation

    model = model or load_field_model()
    labels = keypoints_from_annotation(annotation, width, height, label_params or LabelParams(), model=model)
    scale = np.array([width - 1, height - 1], float)
    lines = {k: np.asarray(v, float) * scale for k, v in annotation.items() if k in model.lines and len(v) >= 2}
    circles = {k: np.asarray(v, float) * scale for k, v in annotation.items() if k in model.circles and len(v) >= 2}
    kps = {k: (lab.x, lab.y) for k, lab in labels.keypoints.items()}
    sets = {k: lab.set for k, lab in labels.keypoints.items()}
    obs = Observations.from_keypoints(width, height, kps, sets, lines=lines, circles=circles, model=model)
    return replace(obs, kp_derived=np.ones(obs.n_keypoints, bool)), labels  # every label comes from the lines
