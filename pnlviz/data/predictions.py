"""PnLCalib 2D prediction zips: detected keypoints and line extremities per frame.

One ``<stem>.json`` per frame::

    {"kp":    {"<id>": {"x": .., "y": .., "p": ..}, ...},                    # ids 1..73
     "lines": {"<id>": {"x_1": .., "y_1": .., "p_1": .., "x_2": .., "y_2": .., "p_2": ..}}}  # ids 1..23

Coordinates are normalised with PnLCalib's convention ``x_px = x * W``, ``y_px = y * H``
(no ``- 1``, unlike the SoccerNet annotations). Line ids map to class names through
``pnlviz.field.names.LINE_ID_TO_CLASS``.
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Callable, Collection, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .atomic import atomic_open
from .errors import DataError, member_source
from .jsonio import as_number, describe, dumps, parse_json_bytes, read_file_bytes
from .layout import keyed_members, natural_key, sort_stems
from .reading import frame_files, open_zip, read_zip_member
from .zipwriter import ZipStream

__all__ = [
    "KEYPOINT_IDS",
    "LINE_IDS",
    "Predictions",
    "parse_predictions",
    "parse_predictions_bytes",
    "predictions_info_path",
    "prediction_member",
    "prediction_zip_order",
    "predictions_to_json",
    "read_predictions",
    "read_predictions_info",
    "write_predictions",
    "write_predictions_info",
]

#: Valid PnLCalib keypoint ids (1..73) and line ids (1..23).
KEYPOINT_IDS = range(1, 74)
LINE_IDS = range(1, 24)
#: Normalised prediction coordinates must lie in this range (catches pixel-valued files).
COORD_RANGE: tuple[float, float] = (-0.5, 1.5)

_KP_FIELDS = ("x", "y", "p")
_LINE_FIELDS = ("x_1", "y_1", "p_1", "x_2", "y_2", "p_2")
_INT = re.compile(r"[0-9]+")

KeypointPred = tuple[float, float, float]
LinePred = tuple[float, float, float, float, float, float]


@dataclass
class Predictions:
    """Detections of one frame, normalised (``x_px = x * W``).

    ``keypoints[id] = (x, y, p)``; ``lines[id] = (x1, y1, p1, x2, y2, p2)``.
    """

    keypoints: dict[int, KeypointPred] = field(default_factory=dict)
    lines: dict[int, LinePred] = field(default_factory=dict)
    #: the same heatmaps read again at a detector's lower ``second_look`` thresholds, when that
    #: finds more: kept for a frame these detections leave without a camera
    #: (:func:`pnlviz.calib.looks.take_look` decides). In memory only: a zip holds one reading.
    second: "Predictions | None" = field(default=None, compare=False, repr=False)

    def keypoints_px(self, width: float, height: float) -> dict[int, KeypointPred]:
        """``{id: (x_px, y_px, p)}`` for an image of ``width`` x ``height`` pixels."""
        return {k: (x * width, y * height, p) for k, (x, y, p) in self.keypoints.items()}

    def lines_px(self, width: float, height: float) -> dict[int, LinePred]:
        """``{id: (x1_px, y1_px, p1, x2_px, y2_px, p2)}`` for a ``width`` x ``height`` image."""
        return {
            k: (x1 * width, y1 * height, p1, x2 * width, y2 * height, p2)
            for k, (x1, y1, p1, x2, y2, p2) in self.lines.items()
        }

    def points_px(self, width: float, height: float) -> dict[tuple, tuple[float, float]]:
        """Every detected point in pixels, keyed ``("kp", id)`` for keypoints and ``("line", id,
        1 | 2)`` for line ends: two detections of a frame compare point by point."""
        pts: dict[tuple, tuple[float, float]] = {("kp", k): (x, y)
                                                 for k, (x, y, _) in self.keypoints_px(width, height).items()}
        for k, (x1, y1, _, x2, y2, _) in self.lines_px(width, height).items():
            pts[("line", k, 1)], pts[("line", k, 2)] = (x1, y1), (x2, y2)
        return pts

    def keypoint_arrays(self, width: float, height: float, min_p: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(ids (N,) int, xy_px (N, 2), p (N,))`` of the keypoints with ``p >= min_p``, by id."""
        items = sorted((k, v) for k, v in self.keypoints.items() if v[2] >= min_p)
        ids = np.array([k for k, _ in items], dtype=np.int64)
        vals = np.array([v for _, v in items], dtype=np.float64).reshape(-1, 3)
        xy = vals[:, :2] * np.array([width, height], dtype=np.float64)
        return ids, xy, vals[:, 2].copy()

    def to_json(self) -> dict:
        """The JSON object of this frame (see :func:`predictions_to_json`)."""
        return predictions_to_json(self)


def _parse_id(key: Any, valid: range, what: str, source: str) -> int:
    if isinstance(key, str) and _INT.fullmatch(key):
        ident = int(key)
    elif isinstance(key, (int, np.integer)) and not isinstance(key, bool):
        ident = int(key)
    else:
        raise DataError(source, f"{what} id must be an integer, got {describe(key)}")
    if ident not in valid:
        raise DataError(source, f"{what} id {ident} out of range (valid ids are {valid.start}..{valid.stop - 1})")
    return ident


def _parse_entries(obj: Any, fields: tuple[str, ...], valid: range, what: str, source: str) -> dict:
    if not isinstance(obj, Mapping):
        raise DataError(source, f'"{what}" must be an object mapping ids to detections, got {describe(obj)}')
    out: dict[int, tuple] = {}
    lo, hi = COORD_RANGE
    for key, entry in obj.items():
        ident = _parse_id(key, valid, "keypoint" if what == "kp" else "line", source)
        if ident in out:
            raise DataError(source, f'"{what}" id {ident} appears twice')
        if not isinstance(entry, Mapping):
            raise DataError(source, f'"{what}" id {ident}: expected an object, got {describe(entry)}')
        values = []
        for name in fields:
            if name not in entry:
                raise DataError(source, f'"{what}" id {ident}: missing "{name}"')
            v = as_number(entry[name])
            if v is None:
                raise DataError(source, f'"{what}" id {ident}: "{name}" is not a number, got {describe(entry[name])}')
            if name.startswith("p") and not 0.0 <= v <= 1.0:  # NaN fails too
                raise DataError(source, f'probability out of range in "{what}" id {ident}: {name} = {v:g} '
                                        f"(must lie in [0, 1])")
            if not math.isfinite(v):
                raise DataError(source, f'non-finite value in "{what}" id {ident}: {name} = {v}')
            if not name.startswith("p") and not (lo <= v <= hi):
                raise DataError(
                    source,
                    f'coordinate out of range in "{what}" id {ident}: {name} = {v:g} '
                    f"(normalised coordinates must lie in [{lo:g}, {hi:g}])",
                )
            values.append(v)
        out[ident] = tuple(values)
    return out


def parse_predictions(obj: Any, source: str = "<predictions>") -> Predictions:
    """Validate one decoded frame object ``{"kp": {...}, "lines": {...}}`` (both keys required)."""
    if not isinstance(obj, Mapping):
        raise DataError(source, f'expected a JSON object with "kp" and "lines", got {describe(obj)}')
    for key in ("kp", "lines"):
        if key not in obj:
            raise DataError(source, f'predictions are missing "{key}" (expected {{"kp": {{...}}, "lines": {{...}}}})')
    return Predictions(
        keypoints=_parse_entries(obj["kp"], _KP_FIELDS, KEYPOINT_IDS, "kp", source),
        lines=_parse_entries(obj["lines"], _LINE_FIELDS, LINE_IDS, "lines", source),
    )


def parse_predictions_bytes(data: bytes | str, source: str) -> Predictions:
    """Decode JSON text and :func:`parse_predictions` it."""
    return parse_predictions(parse_json_bytes(data, source), source)


def predictions_to_json(pred: Predictions, source: str = "<predictions>") -> dict:
    """PnLCalib's JSON object for one frame (string ids, plain floats); validates ids and values."""
    obj = {
        "kp": {str(int(k)): dict(zip(_KP_FIELDS, map(float, v), strict=True)) for k, v in pred.keypoints.items()},
        "lines": {str(int(k)): dict(zip(_LINE_FIELDS, map(float, v), strict=True)) for k, v in pred.lines.items()},
    }
    parse_predictions(obj, source)  # same rules as reading: never write what we cannot read
    return obj


def _is_frame_json(base: str) -> bool:
    return base.endswith(".json") and base != "match_info.json" and len(base) > 5


def _frame_stem(base: str) -> str | None:
    return base[:-5] if _is_frame_json(base) else None


def read_predictions(path: str | os.PathLike, on_error: Callable[[DataError], Any] | None = None,
                     splits: Collection[str] = ()) -> dict[str, Predictions]:
    """Read a prediction zip or folder of ``<stem>.json`` (flat, all in one folder, or in split
    folders: ``valid/00042.json`` is frame ``valid/00042``; ``splits``, the dataset's, names them
    when only one is there; :func:`pnlviz.data.layout.keyed_members`).

    Returns ``{stem: Predictions}`` in natural stem order. A frame file that cannot be read or
    validated (or whose name is not valid UTF-8) raises DataError, or with ``on_error`` is passed
    to it and skipped.
    """
    def fail(err: DataError) -> None:
        if on_error is None:
            raise err
        on_error(err)

    p = Path(path)
    out: dict[str, Predictions] = {}
    zf = None if p.is_dir() else open_zip(p)
    try:
        members = dict(keyed_members(frame_files(p, zf, _frame_stem, fail), splits)[0])
        for stem in sort_stems(members):
            name = members[stem]
            source = member_source(os.fspath(p), name) if zf is not None else name
            try:
                data = read_zip_member(zf, name, source) if zf is not None else read_file_bytes(name)
                out[stem] = parse_predictions_bytes(data, source)
            except DataError as err:
                fail(err)
    finally:
        if zf is not None:
            zf.close()
    return out


def prediction_zip_order(name: str) -> tuple:
    """Sort key of the members of a prediction zip: natural order of their stems."""
    return natural_key(name[:-5] if name.endswith(".json") else name)


def prediction_member(stem: str, pred: Predictions, zip_path: str | os.PathLike) -> tuple[str, str]:
    """``(member name, JSON text)`` of one frame in a prediction zip (DataError if it is invalid)."""
    name = f"{stem}.json"
    return name, dumps(predictions_to_json(pred, member_source(zip_path, name)))


def write_predictions(path: str | os.PathLike, predictions: Mapping[str, Predictions]) -> None:
    """Write ``{stem: Predictions}`` as a flat zip of ``<stem>.json``, atomically."""
    zpath = os.fspath(path)
    texts = {}
    for stem, pred in predictions.items():
        name, text = prediction_member(stem, pred, zpath)
        if name in texts:
            raise DataError(zpath, f"two frames have the stem {str(stem)!r}")
        texts[name] = text
    with ZipStream(zpath, keep_partial=False) as zs:
        for name in sorted(texts, key=prediction_zip_order):
            zs.add(name, texts[name])


# -- provenance next to a prediction zip ---------------------------------------------------------
def predictions_info_path(path: str | os.PathLike) -> Path:
    """``preds.zip`` -> ``preds.json``: where the detector's settings (what ``pnlviz detect
    --settings`` records: the detector, its thresholds, the calibration settings its detections
    calibrate best with) are found by themselves. Kept beside the zip, not in it, so the zip stays
    exactly PnLCalib's format."""
    return Path(path).with_suffix(".json")


def write_predictions_info(path: str | os.PathLike, info: Mapping[str, Any],
                           to: str | os.PathLike | None = None) -> Path:
    """Write the detector's settings ``info`` beside prediction zip ``path`` (or to ``to``)."""
    out = predictions_info_path(path) if to is None else Path(to)
    with atomic_open(out, "w") as f:
        f.write(dumps(dict(info), indent=2) + "\n")
    return out


def read_predictions_info(path: str | os.PathLike | None, settings: str | os.PathLike | None = None) -> dict:
    """The detector's settings of prediction zip ``path``: the file ``settings`` when given
    (it must be there), else the one beside the zip ({} when there is none: a zip from PnLCalib
    or elsewhere). A file that is there but unreadable is a DataError."""
    if settings is not None:
        info = Path(settings)
        if not os.path.lexists(info):
            raise DataError(str(info), "no such file (the detector's settings, written by pnlviz detect --settings)")
    elif path is None:
        return {}
    else:
        info = predictions_info_path(path)
        if not os.path.lexists(info) or (info.is_symlink() and not info.exists()):
            return {}  # a FIFO, a device or a loop there is refused by the read below, never ignored
    obj = parse_json_bytes(read_file_bytes(info), str(info))
    if not isinstance(obj, dict):
        raise DataError(str(info), f"expected a JSON object, got {describe(obj)}")
    _check_info(obj, str(info))
    return obj


def _check_info(obj: dict, source: str) -> None:
    """The detector's settings in a sidecar, by type and range (the calibration settings are
    checked by name where they are applied: :mod:`pnlviz.pipeline.settings`)."""
    for key in ("kp_threshold", "line_threshold"):
        if key in obj:
            v = as_number(obj[key])
            if v is None or not 0.0 <= v <= 1.0:
                raise DataError(source, f"{key!r} must be a number in [0, 1], got {describe(obj[key])}")
    if "input_size" in obj:
        size = obj["input_size"]
        if not (isinstance(size, list) and len(size) == 2 and all(isinstance(v, int) and not isinstance(v, bool)
                                                                   and 16 <= v <= 16384 for v in size)):
            raise DataError(source, f"'input_size' must be two whole numbers of 16 to 16384, got {describe(size)}")
    if "calibration" in obj and not isinstance(obj["calibration"], dict):
        raise DataError(source, f"'calibration' must be an object of settings, got {describe(obj['calibration'])}")
