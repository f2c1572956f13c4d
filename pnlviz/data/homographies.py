"""WC14 / TS-WorldCup ground-truth homographies: ``{stem: 3x3 nested list}`` JSON files.

The homographies map template points (yards, 115 x 74, origin at a corner) to image pixels
(1280 x 720 for WC14). This module only reads/writes and validates them.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from typing import Any

import numpy as np

from .atomic import atomic_write_text
from .errors import DataError
from .jsonio import as_number, describe, dumps, parse_json_bytes, read_file_bytes
from .layout import sort_stems

__all__ = ["parse_homographies", "read_homographies", "write_homographies"]


def _parse_matrix(value: Any, stem: str, source: str) -> np.ndarray:
    if not (isinstance(value, list) and len(value) == 3 and all(isinstance(r, list) and len(r) == 3 for r in value)):
        raise DataError(source, f"homography of frame {stem!r} must be a 3x3 nested list, got {describe(value)}")
    out = np.empty((3, 3), dtype=np.float64)
    for i, row in enumerate(value):
        for j, v in enumerate(row):
            x = as_number(v)
            if x is None:
                raise DataError(source, f"homography of frame {stem!r} [{i}][{j}] is not a number, got {describe(v)}")
            if not np.isfinite(x):
                raise DataError(source, f"homography of frame {stem!r} [{i}][{j}] is not finite ({x})")
            out[i, j] = x
    return out


def parse_homographies(obj: Any, source: str = "<homographies>") -> dict[str, np.ndarray]:
    """Validate a decoded ``{stem: 3x3}`` object -> ``{stem: (3, 3) float64}`` in natural order."""
    if not isinstance(obj, Mapping):
        raise DataError(source, f"expected a JSON object mapping frame stems to 3x3 matrices, got {describe(obj)}")
    parsed = {}
    for stem, value in obj.items():
        if not isinstance(stem, str):
            raise DataError(source, f"frame stems must be strings, got {describe(stem)}")
        parsed[stem] = _parse_matrix(value, stem, source)
    return {s: parsed[s] for s in sort_stems(parsed)}


def read_homographies(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Read a homography JSON file (e.g. WC14 ground truth) -> ``{stem: (3, 3) array}``."""
    source = os.fspath(path)
    return parse_homographies(parse_json_bytes(read_file_bytes(path), source), source)


def write_homographies(path: str | os.PathLike, homographies: Mapping[str, Any]) -> None:
    """Write ``{stem: 3x3}`` atomically (validated: 3x3, finite)."""
    source = os.fspath(path)
    obj = {}
    for stem, h in homographies.items():
        arr = np.asarray(h, dtype=np.float64)
        if arr.shape != (3, 3) or not np.all(np.isfinite(arr)):
            raise DataError(source, f"homography of frame {str(stem)!r} must be a finite 3x3 matrix")
        obj[str(stem)] = arr.tolist()
    atomic_write_text(path, dumps(obj, indent=1))
