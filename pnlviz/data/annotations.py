"""SoccerNet-Calibration line annotations.

Format: a JSON object ``{class name: [{"x": .., "y": ..}, ...]}`` with normalised image
coordinates, ``x_px = x * (W - 1)``, ``y_px = y * (H - 1)`` (the official evaluator's
``scale_points``). In memory an annotation is ``dict[str, np.ndarray]``, one ``(N, 2)``
float64 array of normalised points per class, keyed by the evaluator's spelling of the class
(``"Goal left post left "`` with its trailing space).
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from typing import Any

import numpy as np

from pnlviz.field.names import IGNORED_CLASSES, canonical_class_name, close_class_names

from .errors import DataError
from .jsonio import as_number, describe, dumps, parse_json_bytes, read_file_bytes
from .atomic import atomic_write_text

__all__ = [
    "Annotation",
    "COORD_RANGE",
    "MIN_POINTS",
    "parse_annotation",
    "parse_annotation_bytes",
    "read_annotation",
    "annotation_to_json",
    "write_annotation",
    "to_pixels",
    "from_pixels",
]

#: In-memory annotation: class name -> (N, 2) float64 normalised points.
Annotation = dict[str, np.ndarray]

#: Normalised annotation coordinates must lie in this closed range (points a little outside
#: the frame are common: annotators click past the border).
COORD_RANGE: tuple[float, float] = (-0.5, 1.5)
#: Fewest points a class with geometry may have (a line needs 2; so does a circle arc).
MIN_POINTS = 2
#: Most points a class may have: SoccerNet's have 2 to 37 (a circle, in SN22 and WC14); a hand or a tool that
#: gave a class thousands would make every judge and fit of it slow and large in memory (650,000
#: points in one class took 4.4 GB in ``qa``)
MAX_POINTS = 500


def _name_for_message(name: Any) -> str:
    text = repr(name)
    return text if len(text) <= 80 else text[:77] + "..."


def _unknown_class_problem(name: str) -> str:
    problem = f"unknown class {_name_for_message(name)}"
    hits = close_class_names(name, n=3)
    if hits:
        quoted = [repr(h) for h in hits]
        listed = quoted[0] if len(quoted) == 1 else ", ".join(quoted[:-1]) + " or " + quoted[-1]
        problem += f" (did you mean {listed}?)"
    return problem


def _parse_points(points: Any, cls: str, source: str, ignored: bool) -> np.ndarray:
    label = repr(cls)
    if not isinstance(points, list):
        raise DataError(source, f"class {label}: expected a list of points, got {describe(points)}")
    if len(points) > MAX_POINTS:
        raise DataError(source, f"class {label} has {len(points):,} points; at most {MAX_POINTS:,} per class are read")
    out = np.empty((len(points), 2), dtype=np.float64)
    lo, hi = COORD_RANGE
    for i, p in enumerate(points):
        if not isinstance(p, Mapping) or "x" not in p or "y" not in p:
            raise DataError(
                source, f'class {label} point {i}: expected an object with "x" and "y", got {describe(p)}'
            )
        for j, key in enumerate(("x", "y")):
            v = as_number(p[key])
            if v is None:
                raise DataError(source, f'class {label} point {i}: "{key}" is not a number, got {describe(p[key])}')
            if not math.isfinite(v):
                raise DataError(source, f"non-finite coordinate in class {label} point {i}: {key} = {v}")
            if not ignored and not (lo <= v <= hi):
                raise DataError(
                    source,
                    f"coordinate out of range in class {label} point {i}: {key} = {v:g} "
                    f"(normalised coordinates must lie in [{lo:g}, {hi:g}])",
                )
            out[i, j] = v
    if not ignored and len(points) < MIN_POINTS:
        kind = "circle" if cls.startswith("Circle") else "line"
        raise DataError(
            source, f"{kind} class {label} has {len(points)} point{'s' if len(points) != 1 else ''}, needs at least {MIN_POINTS}"
        )
    return out


def parse_annotation(obj: Any, source: str = "<annotation>", keep_unknown: bool = False) -> Annotation:
    """Validate a decoded annotation JSON object and convert it to ``{class: (N, 2) array}``.

    Class names are mapped to the evaluator's spelling (the goal post with or without its
    trailing space). ``Goal unknown`` / ``Line unknown`` are accepted and dropped unless
    ``keep_unknown``; their points are only checked for structure and finiteness.
    Raises :class:`DataError` (message ``"<source>: <problem>"``) on any problem.
    """
    if not isinstance(obj, Mapping):
        raise DataError(
            source, f"expected a JSON object mapping class names to lists of points, got {describe(obj)}"
        )
    out: Annotation = {}
    for name, points in obj.items():
        if not isinstance(name, str):
            raise DataError(source, f"class names must be strings, got {describe(name)}")
        cls = canonical_class_name(name)
        if cls is None:
            raise DataError(source, _unknown_class_problem(name))
        if cls in out:
            raise DataError(source, f"class {cls!r} appears twice (spelled {name!r} the second time)")
        ignored = cls in IGNORED_CLASSES
        # ignored classes are kept here (a duplicate spelling is still caught), popped below
        out[cls] = _parse_points(points, cls, source, ignored)
    if not keep_unknown:
        for cls in IGNORED_CLASSES:
            out.pop(cls, None)
    return out


def parse_annotation_bytes(data: bytes | str, source: str, keep_unknown: bool = False) -> Annotation:
    """Decode JSON text and :func:`parse_annotation` it."""
    return parse_annotation(parse_json_bytes(data, source), source, keep_unknown=keep_unknown)


def read_annotation(path: str | os.PathLike, keep_unknown: bool = False) -> Annotation:
    """Read and validate one annotation JSON file."""
    source = os.fspath(path)
    return parse_annotation_bytes(read_file_bytes(path), source, keep_unknown=keep_unknown)


def annotation_to_json(annotation: Mapping[str, Any], source: str = "<annotation>") -> dict[str, list[dict[str, float]]]:
    """The JSON object of an annotation: canonical class spelling, plain Python floats.

    ``annotation`` maps class names to ``(N, 2)`` arrays (or lists of pairs) of normalised
    points. Unknown class names and malformed point arrays raise :class:`DataError`.
    """
    out: dict[str, list[dict[str, float]]] = {}
    for name, points in annotation.items():
        cls = canonical_class_name(name)
        if cls is None:
            raise DataError(source, _unknown_class_problem(name))
        if cls in out:
            raise DataError(source, f"class {cls!r} appears twice")
        try:
            arr = np.asarray(points, dtype=np.float64)
        except (TypeError, ValueError):
            arr = None
        if arr is not None and arr.size == 0:
            arr = arr.reshape(0, 2)
        if arr is None or arr.ndim != 2 or arr.shape[1] != 2:
            raise DataError(source, f"class {cls!r}: points must be an (N, 2) array of numbers")
        if not np.all(np.isfinite(arr)):
            raise DataError(source, f"non-finite coordinate in class {cls!r}")
        out[cls] = [{"x": float(x), "y": float(y)} for x, y in arr]
    return out


def write_annotation(path: str | os.PathLike, annotation: Mapping[str, Any]) -> None:
    """Write an annotation JSON file atomically (canonical class spelling)."""
    atomic_write_text(path, dumps(annotation_to_json(annotation, os.fspath(path))))


def to_pixels(points: Any, width: int, height: int) -> np.ndarray:
    """Normalised SoccerNet points ``(N, 2)`` -> pixels: ``x * (W - 1)``, ``y * (H - 1)``."""
    pts = np.asarray(points, dtype=np.float64)
    return pts * np.array([width - 1, height - 1], dtype=np.float64)


def from_pixels(points: Any, width: int, height: int) -> np.ndarray:
    """Pixels ``(N, 2)`` -> normalised SoccerNet points: ``x / (W - 1)``, ``y / (H - 1)``."""
    pts = np.asarray(points, dtype=np.float64)
    return pts / np.array([width - 1, height - 1], dtype=np.float64)
