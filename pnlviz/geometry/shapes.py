"""The shape checks at the entry of the geometry functions that take arrays: an array of another
shape is refused with its argument's name, never reshaped into something else (an (N, 2) array
read as fewer 3-D points, a (2, 3, 1) array as two points)."""

from __future__ import annotations

import numpy as np

from pnlviz.errors import ArgumentError

__all__ = ["as_array", "as_points"]


def _float_array(value, name: str) -> np.ndarray:
    """``value`` as a float array (a float array as it is); ArgumentError naming ``name`` when it
    is not numbers."""
    if isinstance(value, np.ndarray) and value.dtype == float:
        return value
    try:
        return np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ArgumentError(f"{name}: expected an array of numbers, got {str(value)[:60]!r}") from None


def as_points(value, dims: int, name: str, what: str = "points") -> np.ndarray:
    """``value`` as a float array of shape (N, ``dims``); else ArgumentError naming ``name``.

    >>> as_points([[1, 2]], 2, "uv").shape
    (1, 2)
    >>> as_points(np.zeros((4, 3)), 2, "uv")
    Traceback (most recent call last):
    ...
    pnlviz.ArgumentError: uv: expected points (N, 2), got an array of shape (4, 3)
    """
    arr = _float_array(value, name)
    if arr.ndim != 2 or arr.shape[1] != dims:
        raise ArgumentError(f"{name}: expected {what} (N, {dims}), got an array of shape {arr.shape}")
    return arr


def as_array(value, shape: tuple[int | None, ...], name: str) -> np.ndarray:
    """``value`` as a float array of ``shape`` (None: any length there); else ArgumentError
    naming ``name``.

    >>> as_array(np.eye(3), (3, 3), "R").shape
    (3, 3)
    >>> as_array([1.0, 2.0], (3,), "C")
    Traceback (most recent call last):
    ...
    pnlviz.ArgumentError: C: expected an array of shape (3,), got (2,)
    """
    arr = _float_array(value, name)
    if arr.ndim != len(shape) or any(s is not None and n != s for n, s in zip(arr.shape, shape)):
        want = "(" + ", ".join("N" if s is None else str(s) for s in shape) + ("," if len(shape) == 1 else "") + ")"
        raise ArgumentError(f"{name}: expected an array of shape {want}, got {arr.shape}")
    return arr
