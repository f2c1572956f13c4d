"""The error every room may raise for a wrong argument of the Python API (a leaf: it imports
nothing of pnlviz)."""

from __future__ import annotations

__all__ = ["ArgumentError"]


class ArgumentError(ValueError):
    """A wrong argument of the Python API (:mod:`pnlviz.api`, :class:`pnlviz.Camera`); the message
    starts with its name. Shown (and importable) as ``pnlviz.ArgumentError``."""

    __module__ = "pnlviz"
