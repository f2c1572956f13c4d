"""Calibration settings from outside (a detector's sidecar, a config): checked by name, type and
range before they reach :class:`pnlviz.calib.calibrate.CalibParams`, so that ``"refine_k1":
"maybe"`` or ``"alpha": 7.5`` is refused in one line instead of being applied."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from pnlviz.calib.solver import LOSSES
from pnlviz.calib.voting import SUBSETS
from pnlviz.data.errors import DataError

__all__ = ["check_settings"]

#: Ranges of the numeric settings (closed intervals); the others must be > 0.
_RANGES: dict[str, tuple[float, float]] = {
    "alpha": (0.0, 1.0), "min_hfov_deg": (0.01, 179.0), "max_hfov_deg": (0.01, 179.0), "tol": (1e-15, 0.5),
    "min_points": (3, 1000), "refine_top": (1, 1000), "class_tolerance_px": (0.0, 1000.0),  # 0: off
    "min_height_m": (0.0, 1000.0),  # 0: any camera above the pitch
    "shot_min_score": (0.0, 1.0),  # each of the two scores; 0: a shot fits every detection
}
_POSITIVE_MAX = 1e6


def _number(key: str, value: Any, integer: bool) -> str | None:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or (integer and not isinstance(value, int)):
        return f"must be {'a whole number' if integer else 'a number'}, got {value!r}"[:120]
    low, high = _RANGES.get(key, (0.0, _POSITIVE_MAX))
    if not math.isfinite(value) or not (low <= value <= high) or (key not in _RANGES and value <= 0):
        return f"= {value!r} is out of range ({'above' if key not in _RANGES else 'from'} {low:g} to {high:g})"
    return None


def _problem(key: str, value: Any, default: Any) -> str | None:
    if isinstance(default, bool):
        return None if isinstance(value, bool) else f"must be true or false, got {value!r}"[:120]
    if isinstance(default, (int, float)):
        return _number(key, value, isinstance(default, int))
    if key == "final_loss":
        return None if value in LOSSES else f"must be one of {', '.join(LOSSES)}, got {value!r}"[:120]
    if key == "subsets":
        ok = isinstance(value, (list, tuple)) and value and all(v in SUBSETS for v in value)
        return None if ok else f"must be a list of {', '.join(SUBSETS)}, got {value!r}"[:120]
    if key == "shot_min_score" and not (isinstance(value, (list, tuple)) and len(value) == 2):
        return f"must be two scores [keypoint, line], got {value!r}"[:120]
    if isinstance(default, tuple):  # ransac_thresholds, shot_min_score
        if not isinstance(value, (list, tuple)) or not value:
            return f"must be a list of numbers, got {value!r}"[:120]
        return next((p for p in (_number(key, v, False) for v in value) if p), None)
    return None


def check_settings(settings: Any, source: str) -> dict:
    """``settings`` (name -> value) checked against the fields of ``CalibParams``: unknown names,
    wrong types and values out of range are a :class:`DataError` naming ``source`` and the setting."""
    from pnlviz.calib.calibrate import CalibParams

    if settings is None:
        return {}
    if not isinstance(settings, Mapping):
        raise DataError(source, f'"calibration" must be an object of settings, got {type(settings).__name__}')
    defaults = CalibParams()
    known = set(CalibParams.__dataclass_fields__)
    for key, value in settings.items():
        if key not in known:
            raise DataError(source, f"unknown calibration setting {str(key)[:40]!r} "
                                    f"(known: {', '.join(sorted(known))})")
        problem = _problem(key, value, getattr(defaults, key))
        if problem:
            raise DataError(source, f"calibration setting {key!r} {problem}")
    return dict(settings)
