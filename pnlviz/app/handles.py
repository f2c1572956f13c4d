"""Setting a viser handle's properties without sending what did not change (no GUI of its own)."""

from __future__ import annotations

import numpy as np

__all__ = ["update_changed"]


def update_changed(handle, **props) -> None:
    """Set those ``props`` of a viser handle (scene node or widget) that differ from what it has:
    an unchanged value is not sent again (every scene message makes the browser draw again)."""
    for name, value in props.items():
        old = getattr(handle, name)
        if isinstance(old, np.ndarray):  # viser keeps arrays in their wire type (float32, uint8)
            new = np.asarray(value)
            same = old.shape == new.shape and np.array_equal(old, new.astype(old.dtype, copy=False))
        elif isinstance(value, (np.ndarray, tuple, list)):
            same = np.shape(old) == np.shape(value) and np.array_equal(old, value)
        else:
            same = old == value
        if not same:
            setattr(handle, name, value)
