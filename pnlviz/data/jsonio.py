"""JSON reading/writing shared by the readers: every failure becomes a one-line DataError."""

from __future__ import annotations

import json
import math
import os
from typing import Any

import numpy as np

from .errors import DataError
from .limits import MAX_JSON_BYTES
from .reading import read_file

__all__ = ["parse_json_bytes", "to_jsonable", "as_number", "describe"]


def parse_json_bytes(data: bytes | str, source: str) -> Any:
    """``json.loads`` with errors turned into ``DataError("<source>: corrupt JSON: ...")``."""
    try:
        return json.loads(data)
    except json.JSONDecodeError as e:
        raise DataError(source, f"corrupt JSON: {e.msg} (line {e.lineno}, column {e.colno})") from None
    except UnicodeDecodeError as e:
        raise DataError(source, f"corrupt JSON: not UTF-8 text ({e.reason} at byte {e.start})") from None
    except RecursionError:
        raise DataError(source, "corrupt JSON: nested too deeply") from None
    except (ValueError, TypeError) as e:  # e.g. integer literal with too many digits
        raise DataError(source, f"corrupt JSON: {e}") from None


def read_file_bytes(path: str | os.PathLike) -> bytes:
    """The bytes of ``path``; an unreadable file, or one over :data:`~pnlviz.data.limits.MAX_JSON_BYTES`,
    raises DataError."""
    return read_file(path, MAX_JSON_BYTES)


def to_jsonable(obj: Any) -> Any:
    """Convert numpy scalars/arrays and tuples inside ``obj`` to plain JSON types."""
    if isinstance(obj, dict):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.floating):
        return float(obj)
    return obj


def dumps(obj: Any, indent: int | None = None) -> str:
    """``json.dumps`` of ``to_jsonable(obj)`` (NaN/inf refused: they are not JSON)."""
    return json.dumps(to_jsonable(obj), indent=indent, allow_nan=False)


def as_number(value: Any) -> float | None:
    """``float(value)`` for an int/float (not bool) that fits a float, else None.

    Non-finite floats are returned as they are (callers report them specifically).
    """
    if isinstance(value, (bool, np.bool_)):
        return None
    if isinstance(value, (int, float, np.integer, np.floating)):
        try:
            return float(value)
        except OverflowError:  # a huge int
            return math.inf if value > 0 else -math.inf
    return None


def describe(value: Any, limit: int = 40) -> str:
    """A short one-line description of ``value`` for error messages."""
    if isinstance(value, dict):
        return "an object"
    if isinstance(value, list):
        return "a list"
    if value is None:
        return "null"
    if isinstance(value, bool):
        return f"a boolean ({str(value).lower()})"
    if isinstance(value, str):
        text = repr(value)
        return f"a string ({text[:limit] + '...' if len(text) > limit else text})"
    text = repr(value)
    return f"{type(value).__name__} ({text[:limit] + '...' if len(text) > limit else text})"
