"""SoccerNet's camera angles: the world-to-camera rotation from pan, tilt and roll
(``R^T = Rz(pan) Rx(tilt) Rz(roll)``) and back, and the rotation of a camera looking at a point."""

from __future__ import annotations

import math

import numpy as np

from pnlviz.geometry.shapes import as_array

__all__ = ["look_at_rotation", "pan_tilt_roll_from_rotation", "rotation_from_pan_tilt_roll"]


def _rz(a) -> np.ndarray:
    """Rotation(s) about z by ``a`` (radians): (3, 3) for a scalar, (..., 3, 3) for an array."""
    a = np.asarray(a, float)
    c, s = np.cos(a), np.sin(a)
    out = np.zeros(a.shape + (3, 3))
    out[..., 0, 0], out[..., 0, 1], out[..., 1, 0], out[..., 1, 1], out[..., 2, 2] = c, -s, s, c, 1.0
    return out


def _rx(a) -> np.ndarray:
    """Rotation(s) about x by ``a`` (radians), as :func:`_rz`."""
    a = np.asarray(a, float)
    c, s = np.cos(a), np.sin(a)
    out = np.zeros(a.shape + (3, 3))
    out[..., 0, 0], out[..., 1, 1], out[..., 1, 2], out[..., 2, 1], out[..., 2, 2] = 1.0, c, -s, s, c
    return out


def rotation_from_pan_tilt_roll(pan, tilt, roll) -> np.ndarray:
    """World-to-camera rotation from SoccerNet angles (radians): ``R = (Rz(pan) Rx(tilt) Rz(roll))^T``;
    (3, 3) for scalar angles, (T, 3, 3) for arrays of T angles (the frames of a shot), each the
    same to the last bit as the scalar call.

    >>> R = rotation_from_pan_tilt_roll(np.array([0.1, 0.2]), np.array([1.2, 1.3]), np.array([0.0, 0.01]))
    >>> R.shape, bool(np.array_equal(R[1], rotation_from_pan_tilt_roll(0.2, 1.3, 0.01)))
    ((2, 3, 3), True)
    """
    return np.swapaxes(_rz(pan) @ _rx(tilt) @ _rz(roll), -1, -2)


def pan_tilt_roll_from_rotation(R: np.ndarray) -> tuple[float, float, float]:
    """Inverse of :func:`rotation_from_pan_tilt_roll` (radians). Of the two decompositions, the one
    with the smaller |roll| is returned, as the SoccerNet package does (operators avoid roll).
    ``R`` (3, 3); another shape: ArgumentError."""
    o = as_array(R, (3, 3), "R").T  # orientation = Rz(pan) Rx(tilt) Rz(roll)
    first = math.acos(max(-1.0, min(1.0, o[2, 2])))
    solutions = []
    for tilt in (first, -first):
        s = 1.0 if math.sin(tilt) > 0 else -1.0
        solutions.append((math.atan2(s * o[0, 2], -s * o[1, 2]), tilt, math.atan2(s * o[2, 0], s * o[2, 1])))
    return solutions[0] if abs(solutions[0][2]) < abs(solutions[1][2]) else solutions[1]


def look_at_rotation(position: np.ndarray, target: np.ndarray, roll: float = 0.0) -> np.ndarray:
    """World-to-camera rotation of a camera at ``position`` looking at ``target`` with the image
    'up' as close as possible to world up (-z), then rolled by ``roll`` radians about the axis.
    ``position``, ``target``: (3,) each; another shape: ArgumentError."""
    z = as_array(target, (3,), "target") - as_array(position, (3,), "position")
    z /= np.linalg.norm(z)
    down = np.array([0.0, 0.0, 1.0])
    x = np.cross(down, z)  # camera x points right when y points down
    if np.linalg.norm(x) < 1e-9:
        x = np.array([1.0, 0.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z])
    return _rz(roll).T @ R if roll else R
