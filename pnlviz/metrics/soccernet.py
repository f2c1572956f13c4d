"""The SoccerNet camera-calibration metric, equal to the official evaluator
(``SoccerNet.Evaluation.CameraCalibration.evaluate``, package version 0.2.0), vectorised.

Protocol, restated from the official code:

* Frames are the ground-truth annotations ``<stem>.json``; the prediction of a frame is the
  camera ``camera_<stem>.json``. A frame without a camera is *not calibrated*: it counts in the
  completeness ``CR = calibrated / total`` and in nothing else.
* Annotated points are scaled to pixels at 960 x 540 as ``x * (W - 1)``, ``y * (H - 1)``; classes
  with no point are dropped (``scale_points``).
* The camera is used as given (not rescaled to 960 x 540; the evaluator takes its image size from
  the principal point) and the pitch is projected and clipped to the 960 x 540 frame by
  :func:`pnlviz.geometry.visible_pitch` with ``evaluator_precision=True``, which is bit-identical
  to the official ``get_polylines(camera, 960, 540, sampling_factor=0.9)``.
* The distance of an annotated point to a projected polyline is :func:`point_to_polyline_distance`
  (the official ``distance_to_polyline``, same arithmetic, vectorised).
* Per threshold ``t`` (pixels): an annotated class that is also projected is a true positive when
  *every* one of its points is at a distance ``< t``; otherwise it counts as a false positive (the
  evaluator puts it in the same cell as projected classes missing from the annotation); an
  annotated class that is not projected is a false negative. ``accuracy = TP / (TP + FP + FN)``
  (0 when both are empty), ``precision = TP / (TP + FP)``, ``recall = TP / (TP + FN)``.
* The frame is also scored with its labels mirrored through the pitch centre
  (:data:`pnlviz.field.names.MIRROR`); the mirrored score is kept unless the direct one is
  strictly higher (ties go to the mirrored labelling, as in the evaluator), separately for each
  threshold.
* ``JaC@t`` = mean accuracy over calibrated frames; precision and recall are averaged over the
  calibrated frames where they are defined; final score ``FS = CR x JaC@5``.

``Goal unknown`` / ``Line unknown``: the evaluator keeps every class of the annotation file, so
these two, which have no geometry and are never projected, count as false negatives (the same
under mirroring). :func:`evaluate_dataset` therefore reads annotations with ``keep_unknown=True``
by default (``count_unknown=False`` drops them instead, which the official score does not).

Floating point: the evaluator's confusion matrix is float32, so its per-frame accuracy,
precision and recall are float32 quotients and its means are float32 means (numpy pairwise
summation, in frame order). We reproduce that so that the scores equal the official ones bit for
bit when the frames come in the same order (natural stem order here, zip order there); in another
order they differ by float32 rounding only (< 1e-6).
"""

from __future__ import annotations

import functools
import os
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pnlviz.conventions import EVAL_HEIGHT, EVAL_WIDTH
from pnlviz.data import DataError, open_dataset
from pnlviz.data.cameras import read_cameras
from pnlviz.data.dataset import Dataset
from pnlviz.field.names import MIRROR
from pnlviz.geometry.camera import Camera
from pnlviz.geometry.polylines import visible_pitch

__all__ = [
    "EVAL_WIDTH", "EVAL_HEIGHT", "DEFAULT_THRESHOLDS", "point_to_polyline_distance", "Matching",
    "ThresholdScore", "FrameResult", "Summary", "evaluate_frame", "evaluate_dataset",
]

DEFAULT_THRESHOLDS: tuple[float, ...] = (5.0, 10.0, 20.0)
#: The evaluator's false-positive weight of a class in the per-class confusion (2 extremities
#: for a line, 9 for anything with "Circle" in its name).
_FP_WEIGHT_LINE, _FP_WEIGHT_CIRCLE = 2.0, 9.0


# ------------------------------------------------------------------------------------ distances
def point_to_polyline_distance(points: np.ndarray, polyline: np.ndarray) -> np.ndarray:
    """Distance (pixels) of each point ``(N, 2)`` to the polyline ``(M, 2)``, ``(N,)``.

    The official ``distance_to_polyline`` with the same floating-point operations, for all points
    and segments at once:

    * a one-point polyline: the distance to that point;
    * otherwise, for each segment ``(o, e)``: the homogeneous line ``l = o x e`` normalised by
      ``hypot(l0, l1)``; the foot of the perpendicular ``p' = ((l0, l1, 0) x p) x l``; its position
      ``k = (p' - o).(e - o) / |e - o|^2``; if ``0 < k < 1`` the distance to the foot, else the
      distance to the nearer end (a degenerate segment gives ``k = NaN`` and lands here too);
    * the minimum over segments. NaN propagates as with ``np.min`` in the evaluator.

    The two dot products are summed left to right; the evaluator's ``np.dot`` may round its last
    bit differently, which can only matter for a foot landing exactly on a segment end, where
    both branches agree to ~1e-13 px.
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    poly = np.asarray(polyline, dtype=np.float64).reshape(-1, 2)
    px, py = p[:, 0:1], p[:, 1:2]  # (N, 1)
    # distance to every polyline vertex, as the evaluator's distance(): sqrt(dx^2 + dy^2)
    dx, dy = px - poly[None, :, 0], py - poly[None, :, 1]
    to_vertex = np.sqrt(dx * dx + dy * dy)  # (N, M)
    if len(poly) < 2:
        return to_vertex[:, 0] if len(poly) else np.full(len(p), np.nan)
    ox, oy, ex, ey = poly[:-1, 0], poly[:-1, 1], poly[1:, 0], poly[1:, 1]  # (S,)
    with np.errstate(divide="ignore", invalid="ignore"):
        # l = (ox, oy, 1) x (ex, ey, 1), normalised
        l0, l1, l2 = oy - ey, ex - ox, ox * ey - oy * ex
        norm = np.sqrt(l0 * l0 + l1 * l1)
        l0, l1, l2 = l0 / norm, l1 / norm, l2 / norm
        # m = (l0, l1, 0) x (px, py, 1) = (l1, -l0, l0 py - l1 px)  (the first two are exact)
        m0, m1, m2 = l1, -l0, l0 * py - l1 * px  # (S,), (S,), (N, S)
        # foot = m x l, dehomogenised
        q0 = m1 * l2 - m2 * l1
        q1 = m2 * l0 - m0 * l2
        q2 = m0 * l1 - m1 * l0
        fx, fy, fw = q0 / q2, q1 / q2, q2 / q2
        v1x, v1y, v1w = fx - ox, fy - oy, fw - 1.0
        v2x, v2y = ex - ox, ey - oy
        k = (v1x * v2x + v1y * v2y + v1w * 0.0) / (v2x * v2x + v2y * v2y)
        gx, gy, gw = fx - px, fy - py, fw - 1.0
        to_foot = np.sqrt(gx * gx + gy * gy + gw * gw)
    to_ends = np.minimum(to_vertex[:, :-1], to_vertex[:, 1:])
    per_segment = np.where((k > 0) & (k < 1), to_foot, to_ends)
    return np.min(per_segment, axis=1)


# ------------------------------------------------------------------------------------ results
def _ratio32(num: int, den: int) -> float:
    """The evaluator's float32 quotient of two counts, as a Python float."""
    return float(np.float32(num) / np.float32(den))


@dataclass(frozen=True)
class Matching:
    """One frame compared with the projected pitch under one labelling: as annotated, or with
    the labels mirrored. Class names are those of the projected pitch the points were compared
    with (for a mirrored matching, the mirrored names)."""

    mirrored: bool
    #: classes both labelled and projected -> distance (px) of each annotated point
    distances: dict[str, np.ndarray]
    #: projected classes that the (possibly mirrored) labels do not have
    false_positive_classes: tuple[str, ...]
    #: labelled classes that are not projected -> number of annotated points
    false_negative_classes: dict[str, int]

    def max_distance(self, name: str) -> float:
        d = self.distances.get(name)
        return float("nan") if d is None else float(np.max(d))

    def counts(self, threshold: float) -> tuple[int, int, int]:
        """``(TP, FP, FN)`` classes at ``threshold`` px (a matched class with a point too far is FP)."""
        tp = sum(bool(np.all(d < threshold)) for d in self.distances.values())
        fp = len(self.false_positive_classes) + len(self.distances) - tp
        return tp, fp, len(self.false_negative_classes)

    def class_status(self, threshold: float) -> dict[str, str]:
        """``{class: "tp" | "far" | "fp" | "fn"}``: ``far`` is a matched class with a point at
        ``>= threshold`` px (the evaluator counts it as a false positive)."""
        out = {n: ("tp" if np.all(d < threshold) else "far") for n, d in self.distances.items()}
        out.update({n: "fp" for n in self.false_positive_classes})
        out.update({n: "fn" for n in self.false_negative_classes})
        return out

    def class_confusion(self, threshold: float) -> dict[str, np.ndarray]:
        """The evaluator's per-class 2x2 confusion: ``[[points within, points beyond], [0, 0]]``
        for a matched class, ``[[0, 2 or 9], [0, 0]]`` for a false positive (9 for circles),
        ``[[0, 0], [points, 0]]`` for a false negative."""
        out: dict[str, np.ndarray] = {}
        for n in self.false_positive_classes:
            out[n] = np.array([[0.0, _FP_WEIGHT_CIRCLE if "Circle" in n else _FP_WEIGHT_LINE], [0.0, 0.0]])
        for n, count in self.false_negative_classes.items():
            out[n] = np.array([[0.0, 0.0], [float(count), 0.0]])
        for n, d in self.distances.items():
            within = int(np.count_nonzero(d < threshold))
            out[n] = np.array([[float(within), float(len(d) - within)], [0.0, 0.0]])
        return out


@dataclass(frozen=True)
class ThresholdScore:
    """A frame's score at one threshold, for the labelling the evaluator keeps."""

    threshold: float
    accuracy: float  # float32 value, as the evaluator computes it
    tp: int
    fp: int
    fn: int
    mirrored: bool
    precision: float | None  # None where the evaluator skips it (TP + FP = 0)
    recall: float | None  # None where the evaluator skips it (TP + FN = 0)

    @property
    def empty(self) -> bool:
        """Nothing annotated and nothing projected (the evaluator's accuracy is then a plain 0.0)."""
        return self.tp + self.fp + self.fn == 0


@dataclass(frozen=True)
class FrameResult:
    """The metric of one frame. ``calibrated`` is False when the frame has no camera (then
    ``scores`` and the matchings are empty)."""

    stem: str | None
    calibrated: bool
    thresholds: tuple[float, ...]
    scores: dict[float, ThresholdScore] = field(default_factory=dict)
    direct: Matching | None = None
    mirror: Matching | None = None

    def score(self, threshold: float) -> ThresholdScore:
        return self.scores[float(threshold)]

    def accuracy(self, threshold: float) -> float:
        return self.scores[float(threshold)].accuracy

    def matching(self, threshold: float) -> Matching:
        """The labelling the evaluator keeps at ``threshold``."""
        m = self.mirror if self.scores[float(threshold)].mirrored else self.direct
        assert m is not None  # a frame with scores has both matchings
        return m


def _score(direct: Matching, mirror: Matching, threshold: float) -> ThresholdScore:
    def rates(m: Matching):
        tp, fp, fn = m.counts(threshold)
        n = tp + fp + fn
        return (_ratio32(tp, n) if n else 0.0), tp, fp, fn

    acc1, *c1 = rates(direct)
    acc2, *c2 = rates(mirror)
    mirrored = not acc1 > acc2  # the evaluator keeps the mirrored labels unless strictly worse
    acc, (tp, fp, fn) = (acc2, c2) if mirrored else (acc1, c1)
    return ThresholdScore(float(threshold), acc, tp, fp, fn, mirrored,
                          _ratio32(tp, tp + fp) if tp + fp else None,
                          _ratio32(tp, tp + fn) if tp + fn else None)


def _as_camera(camera: Camera | Mapping) -> Camera:
    return camera if isinstance(camera, Camera) else Camera.from_soccernet(camera)


def _matchings(camera: Camera, annotation: Mapping[str, Any]) -> tuple[Matching, Matching]:
    projected = visible_pitch(camera, EVAL_WIDTH, EVAL_HEIGHT, spacing=0.9, evaluator_precision=True)
    scale = np.array([EVAL_WIDTH - 1, EVAL_HEIGHT - 1], dtype=np.float64)
    gt: dict[str, np.ndarray] = {}
    for name, pts in annotation.items():
        arr = np.asarray(pts, dtype=np.float64).reshape(-1, 2)
        if len(arr):  # the evaluator's scale_points drops classes without points
            gt[name] = arr * scale
    cache: dict[tuple[str, str], np.ndarray] = {}  # symmetric classes are shared by both labellings

    def match(mirrored: bool) -> Matching:
        labels = {(MIRROR[n] if mirrored else n): n for n in gt}
        distances = {}
        for name, source in labels.items():
            if name in projected:
                key = (source, name)
                if key not in cache:
                    cache[key] = point_to_polyline_distance(gt[source], projected[name])
                distances[name] = cache[key]
        return Matching(mirrored, distances,
                        tuple(n for n in projected if n not in labels),
                        {n: len(gt[s]) for n, s in labels.items() if n not in projected})

    return match(False), match(True)


def evaluate_frame(camera: Camera | Mapping | None, annotation: Mapping[str, Any],
                   thresholds: Iterable[float] = DEFAULT_THRESHOLDS, stem: str | None = None) -> FrameResult:
    """Score one frame: ``camera`` (a :class:`Camera` or a SoccerNet camera dict, used as given;
    None = not calibrated) against ``annotation`` (``{class: (N, 2) normalised points}``, the
    evaluator's class spelling, as :mod:`pnlviz.data` returns it). Distances are computed once and
    thresholded for every threshold."""
    thresholds = tuple(float(t) for t in thresholds)
    if camera is None:
        return FrameResult(stem, False, thresholds)
    direct, mirror = _matchings(_as_camera(camera), annotation)
    return FrameResult(stem, True, thresholds, {t: _score(direct, mirror, t) for t in thresholds}, direct, mirror)


# ------------------------------------------------------------------------------------ datasets
def _mean_like_evaluator(values: list[float | None], empty: list[bool] | None = None) -> float:
    """``np.mean`` over the evaluator's list: float32 values (a plain 0.0 for an empty frame's
    accuracy), so a float32 mean unless an empty frame makes it float64. NaN for no value."""
    items = [(0.0 if (empty and e) else np.float32(v)) for v, e in zip(values, empty or [False] * len(values))
             if v is not None]
    return float(np.mean(np.asarray(items))) if items else float("nan")  # the array np.mean makes of them


@dataclass
class Summary:
    """Dataset scores. ``frames`` holds every evaluated frame (calibrated or not), in order."""

    thresholds: tuple[float, ...]
    frames: list[FrameResult]
    #: ground-truth frames whose annotation could not be read (not counted), one line each
    skipped_annotations: list[str] = field(default_factory=list)
    #: camera files that could not be read (their frames count as not calibrated), one line each
    skipped_cameras: list[str] = field(default_factory=list)
    #: cameras with no annotation of the same stem (ignored, as by the evaluator)
    unmatched_cameras: list[str] = field(default_factory=list)

    @property
    def n_frames(self) -> int:
        return len(self.frames)

    @property
    def n_calibrated(self) -> int:
        return sum(f.calibrated for f in self.frames)

    @property
    def completeness(self) -> float:
        return self.n_calibrated / self.n_frames if self.frames else float("nan")

    def _calibrated(self) -> list[FrameResult]:
        return [f for f in self.frames if f.calibrated]

    def jac(self, threshold: float) -> float:
        """Mean accuracy over calibrated frames (the evaluator's ``meanAccuracies``)."""
        s = [f.score(threshold) for f in self._calibrated()]
        return _mean_like_evaluator([x.accuracy for x in s], [x.empty for x in s])

    def precision(self, threshold: float) -> float:
        """The evaluator's ``meanPrecision`` (frames with TP + FP > 0)."""
        return _mean_like_evaluator([f.score(threshold).precision for f in self._calibrated()])

    def recall(self, threshold: float) -> float:
        """The evaluator's ``meanRecall`` (frames with TP + FN > 0)."""
        return _mean_like_evaluator([f.score(threshold).recall for f in self._calibrated()])

    @property
    def final_score(self) -> float:
        """``CR x JaC@5`` (NaN when 5 px is not among the thresholds)."""
        return self.completeness * self.jac(5.0) if 5.0 in self.thresholds else float("nan")

    def per_class(self, threshold: float) -> dict[str, dict[str, float]]:
        """The evaluator's per-class ``Accuracy``, ``Precision`` and ``Recall`` from the summed
        per-class confusions of the labelling kept for each frame (class names as compared, i.e.
        mirrored for mirrored frames). NaN where a ratio is 0/0."""
        total: dict[str, np.ndarray] = {}
        for f in self._calibrated():
            for name, conf in f.matching(threshold).class_confusion(threshold).items():
                total[name] = total.get(name, 0) + conf
        out = {}
        with np.errstate(divide="ignore", invalid="ignore"):
            for name in sorted(total):
                c = total[name]
                out[name] = {"accuracy": float(np.float64(c[0, 0]) / c.sum()),
                             "precision": float(np.float64(c[0, 0]) / (c[0, 0] + c[0, 1])),
                             "recall": float(np.float64(c[0, 0]) / (c[0, 0] + c[1, 0]))}
        return out

    def by_split(self) -> dict[str, Summary]:
        """The scores of each split of a dataset in splits (frames ``<split>/<stem>``), in order
        of first appearance; ``{}`` when no frame has a split."""
        groups: dict[str, list[FrameResult]] = {}
        for f in self.frames:
            split, sep, _ = (f.stem or "").rpartition("/")  # a frame scored without a stem has no split
            if sep:
                groups.setdefault(split, []).append(f)
        return {s: Summary(self.thresholds, frames) for s, frames in groups.items()}

    def as_dict(self) -> dict[str, Any]:
        """Aggregate scores as plain data (no per-frame rows)."""
        return {
            "frames": self.n_frames, "calibrated": self.n_calibrated, "completeness": self.completeness,
            "final_score": self.final_score,
            "jac": {t: self.jac(t) for t in self.thresholds},
            "precision": {t: self.precision(t) for t in self.thresholds},
            "recall": {t: self.recall(t) for t in self.thresholds},
        }

    def rows(self) -> list[dict[str, Any]]:
        """One row per frame: stem, calibrated, ``acc@t`` for each threshold, and ``mirrored``,
        ``tp``, ``fp``, ``fn`` at the first threshold (named ``@t``). Empty cells for frames that
        are not calibrated."""
        t0 = self.thresholds[0]
        rows = []
        for f in self.frames:
            row: dict[str, Any] = {"stem": f.stem, "calibrated": int(f.calibrated)}
            for t in self.thresholds:
                row[f"acc@{t:g}"] = f.accuracy(t) if f.calibrated else ""
            s = f.score(t0) if f.calibrated else None
            row[f"mirrored@{t0:g}"] = int(s.mirrored) if s else ""
            for k in ("tp", "fp", "fn"):
                row[f"{k}@{t0:g}"] = getattr(s, k) if s else ""
            rows.append(row)
        return rows

    def table(self) -> str:
        """A small text table of the aggregate scores."""
        lines = [f"frames {self.n_frames}, calibrated {self.n_calibrated}",
                 f"{'threshold':>10} {'JaC':>8} {'precision':>10} {'recall':>8}"]
        for t in self.thresholds:
            lines.append(f"{t:>8g}px {self.jac(t):8.4f} {self.precision(t):10.4f} {self.recall(t):8.4f}")
        lines.append(f"completeness CR {self.completeness:.4f}")
        if 5.0 in self.thresholds:
            lines.append(f"final score FS = CR x JaC@5 {self.final_score:.4f}")
        return "\n".join(lines)


#: frames scored per task when a runner spreads the work (a task costs about 2 ms a frame)
EVAL_CHUNK = 32


def _evaluate_chunk(items: list[tuple[str, Any, dict]], thresholds: tuple[float, ...]) -> list[FrameResult]:
    return [evaluate_frame(cam, ann, thresholds, stem=stem) for stem, cam, ann in items]


def evaluate_dataset(gt: Dataset | str | os.PathLike, cameras: Mapping[str, Camera | Mapping] | str | os.PathLike,
                     thresholds: Iterable[float] = DEFAULT_THRESHOLDS, progress: bool = True, *,
                     count_unknown: bool = True, run: Callable[[Callable, list], list] | None = None,
                     on_error: Callable[[str], Any] | None = None) -> Summary:
    """Score every annotated frame of ``gt`` (a :class:`Dataset`, or a folder / zip path) with
    ``cameras`` (``{stem: Camera | dict}``, or a path to a zip / folder of ``camera_<stem>.json``).

    Bad annotations are skipped (not counted) and bad camera files make their frame
    uncalibrated; each is reported as one line to ``on_error`` and kept in the summary.
    ``count_unknown`` keeps ``Goal unknown`` / ``Line unknown`` as the official evaluator does.
    ``run(fn, chunks)``: how chunks of frames are scored (``pnlviz eval`` gives the batch runner,
    :func:`pnlviz.commands.batch.map_items`, with its worker processes: same results, same order);
    by default here, under a progress bar.
    """
    from tqdm import tqdm

    thresholds = tuple(float(t) for t in thresholds)
    report = on_error or (lambda line: None)
    skipped_cams: list[str] = []
    ds = gt if isinstance(gt, Dataset) else open_dataset(gt)
    if isinstance(cameras, (str, os.PathLike)):
        cameras, skipped_cams = read_cameras(cameras, on_error=report, splits=ds.splits)
    skipped_ann: list[str] = []

    def bad_annotation(stem: str, err: DataError) -> None:
        skipped_ann.append(str(err))
        report(str(err))

    items = [(stem, cameras.get(stem), ann)
             for stem, ann in ds.iter_annotations(on_error=bad_annotation, keep_unknown=count_unknown)]
    seen = {s for s, _, _ in items}
    unmatched = [s for s in cameras if s not in seen]
    frames: list[FrameResult] = []
    if run is not None:
        chunks = [items[i:i + EVAL_CHUNK] for i in range(0, len(items), EVAL_CHUNK)]
        for res in run(functools.partial(_evaluate_chunk, thresholds=thresholds), chunks):
            frames.extend(res)
        return Summary(thresholds, frames, skipped_ann, skipped_cams, unmatched)
    bar = tqdm(total=len(items), desc="eval", unit="frame", disable=not progress or None)
    try:
        for stem, cam, ann in items:
            frames.append(evaluate_frame(cam, ann, thresholds, stem=stem))
            bar.update(1)
    finally:
        bar.close()
    return Summary(thresholds, frames, skipped_ann, skipped_cams, unmatched)
