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
import zipfile
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .atomic import atomic_open
from .errors import DataError, member_source, read_zip_member
from .jsonio import as_number, describe, dumps, parse_json_bytes, read_file_bytes
from .layout import find_root, is_junk, natural_key, sort_stems, split_member

__all__ = [
    "KEYPOINT_IDS",
    "LINE_IDS",
    "Predictions",
    "parse_predictions",
    "parse_predictions_bytes",
    "predictions_info_path",
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

    def keypoints_px(self, width: float, height: float) -> dict[int, KeypointPred]:
        """``{id: (x_px, y_px, p)}`` for an image of ``width`` x ``height`` pixels."""
        return {k: (x * width, y * height, p) for k, (x, y, p) in self.keypoints.items()}

    def lines_px(self, width: float, height: float) -> dict[int, LinePred]:
        """``{id: (x1_px, y1_px, p1, x2_px, y2_px, p2)}`` for a ``width`` x ``height`` image."""
        return {
            k: (x1 * width, y1 * height, p1, x2 * width, y2 * height, p2)
            for k, (x1, y1, p1, x2, y2, p2) in self.lines.items()
        }

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


def read_predictions(path: str | os.PathLike) -> dict[str, Predictions]:
    """Read a prediction zip (flat, or all files in one folder) or a folder of ``<stem>.json``.

    Returns ``{stem: Predictions}`` in natural stem order.
    """
    p = Path(path)
    out: dict[str, Predictions] = {}
    if p.is_dir():
        names = [e.name for e in os.scandir(p) if e.is_file() and not is_junk(e.name) and _is_frame_json(e.name)]
        for name in sort_stems(n[:-5] for n in names):
            out[name] = parse_predictions_bytes(read_file_bytes(p / f"{name}.json"), os.fspath(p / f"{name}.json"))
        return out
    zpath = os.fspath(p)
    try:
        zf = zipfile.ZipFile(p)
    except (OSError, zipfile.BadZipFile) as e:
        raise DataError(zpath, f"cannot open zip archive: {e}") from None
    with zf:
        names = [n for n in zf.namelist() if not is_junk(n)]
        root = find_root(names, _is_frame_json)
        members = {}
        for n in names:
            prefix, base = split_member(n)
            if prefix == root and _is_frame_json(base):
                members[base[:-5]] = n
        for stem in sort_stems(members):
            source = member_source(zpath, members[stem])
            data = read_zip_member(zf, members[stem], source)
            out[stem] = parse_predictions_bytes(data, source)
    return out


def write_predictions(path: str | os.PathLike, predictions: Mapping[str, Predictions]) -> None:
    """Write ``{stem: Predictions}`` as a flat zip of ``<stem>.json``, atomically."""
    zpath = os.fspath(path)
    texts = {}
    for stem, pred in predictions.items():
        name = f"{stem}.json"
        if name in texts:
            raise DataError(zpath, f"two frames have the stem {str(stem)!r}")
        texts[name] = dumps(predictions_to_json(pred, member_source(zpath, name)))
    with atomic_open(zpath, "wb") as f, zipfile.ZipFile(f, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        for name in sorted(texts, key=lambda n: natural_key(n[:-5])):
            zf.writestr(name, texts[name])


# -- provenance next to a prediction zip ---------------------------------------------------------
def predictions_info_path(path: str | os.PathLike) -> Path:
    """``preds.zip`` -> ``preds.json``: what ``pnlviz detect`` records about the detections (the
    detector, its thresholds, the calibration settings they calibrate best with). Kept beside the
    zip, not in it, so the zip stays exactly PnLCalib's format."""
    return Path(path).with_suffix(".json")


def write_predictions_info(path: str | os.PathLike, info: Mapping[str, Any]) -> Path:
    out = predictions_info_path(path)
    with atomic_open(out, "w") as f:
        f.write(dumps(dict(info), indent=2) + "\n")
    return out


def read_predictions_info(path: str | os.PathLike) -> dict:
    """The info written next to prediction zip ``path`` ({} when there is none: a zip from
    PnLCalib or elsewhere). A file that is there but unreadable is a DataError."""
    info = predictions_info_path(path)
    if not info.is_file():
        return {}
    obj = parse_json_bytes(read_file_bytes(info), str(info))
    if not isinstance(obj, dict):
        raise DataError(str(info), f"expected a JSON object, got {describe(obj)}")
    return obj
