"""Rotations and cross products on small arrays, written out component by component (NumPy's
general ``cross`` and ``stack`` cost more than the arithmetic at these sizes)."""

from __future__ import annotations

import math

import numpy as np

from pnlviz.errors import ArgumentError


def so3_exp(w: np.ndarray) -> np.ndarray:
    """Rotation matrix (3, 3) of the rotation vector ``w`` (3,), radians (Rodrigues' formula).

    >>> bool(np.allclose(so3_exp(np.array([0.0, 0.0, np.pi / 2])) @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]))
    True
    """
    if np.shape(w) != (3,):
        raise ArgumentError(f"w: expected a rotation vector (3,), got an array of shape {np.shape(w)}")
    x, y, z = float(w[0]), float(w[1]), float(w[2])
    theta = math.sqrt(x * x + y * y + z * z)
    K = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    if theta < 1e-12:
        K.flat[::4] += 1.0
        return K
    a, b = math.sin(theta) / theta, (1 - math.cos(theta)) / (theta * theta)
    R = a * K + b * (K @ K)
    R.flat[::4] += 1.0
    return R


_NEXT, _AFTER = np.array([1, 2, 0]), np.array([2, 0, 1])


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product over the last axis of two arrays of shape (..., 3), broadcasting."""
    return (a.take(_NEXT, axis=-1) * b.take(_AFTER, axis=-1)
            - a.take(_AFTER, axis=-1) * b.take(_NEXT, axis=-1))
