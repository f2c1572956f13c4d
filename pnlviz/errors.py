"""The error every room may raise for a wrong argument of the Python API (a leaf: it imports
nothing of pnlviz)."""

from __future__ import annotations

__all__ = ["ArgumentError"]


class ArgumentError(ValueError):
    """A wrong argument of the Python API (:mod:`pnlviz.api`, :class:`pnlviz.Camera`); the message
    starts with its name. Shown (and importable) as ``pnlviz.ArgumentError``.

    >>> import pnlviz
    >>> try:
    ...     pnlviz.calibrate({1: (0.0, 0.0)}, image_size=(0, 540))
    ... except pnlviz.ArgumentError as exc:
    ...     print(exc)
    image_size: expected two whole numbers of pixels in 16..16384, got (0, 540)
    """

    __module__ = "pnlviz"
