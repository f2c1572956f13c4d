"""The one exception type of :mod:`pnlviz.data`.

Every problem with an input file (bad JSON, unknown class, coordinates out of range, corrupt
image, missing camera key...) raises :class:`DataError`, whose message is a single line
``"<file>: <problem>"`` so that batch commands can print it as is, one line per bad file.
``<file>`` is a path, or ``"archive.zip:member.json"`` for a member of a zip archive.
"""

from __future__ import annotations

import os

__all__ = ["DataError", "member_source", "escape_controls"]

#: Control characters that a terminal acts on (ESC, BEL, CSI...), shown escaped in messages;
#: tab, newline and carriage return are left to the callers.
_CONTROLS = {c: f"\\x{c:02x}" for c in [*range(0x00, 0x20), *range(0x7f, 0xa0)] if chr(c) not in "\t\n\r"}


def escape_controls(text: str) -> str:
    """``text`` with terminal control characters shown as ``\\x1b``: a file name holding
    ``ESC[2J`` never clears the screen it is printed on."""
    return text.translate(_CONTROLS)


def _printable(text: str) -> str:
    """File names that are not valid UTF-8 (surrogate escapes) shown as ``\\xff``: always printable."""
    try:
        return text.encode("utf-8", "surrogateescape").decode("utf-8", "backslashreplace")
    except UnicodeEncodeError:  # a lone surrogate that is no escape (e.g. from a JSON "\\udcff")
        return text.encode("utf-8", "backslashreplace").decode("utf-8")


def _one_line(text: object) -> str:
    return escape_controls(_printable(" ".join(str(text).splitlines()).strip()))


class DataError(ValueError):
    """A problem with the content of one input file.

    ``DataError(source, problem)``; ``str(err)`` is ``"<source>: <problem>"`` on one line.
    The two parts stay available as ``err.source`` and ``err.problem``. Instances pickle
    (worker processes can send them back).
    """

    def __init__(self, source: str | os.PathLike | None, problem: str):
        source = "<input>" if source is None else _one_line(os.fspath(source) if isinstance(source, os.PathLike) else source)
        problem = _one_line(problem)
        super().__init__(source, problem)
        self.source = source
        self.problem = problem

    def __str__(self) -> str:
        return f"{self.source}: {self.problem}"


def member_source(zip_path: str | os.PathLike, member: str) -> str:
    """The ``<file>`` part of an error message for ``member`` inside ``zip_path``."""
    return f"{os.fspath(zip_path)}:{member}"


from pnlviz.errors import ArgumentError as ArgumentError  # noqa: E402 - defined once, for every room (re-exported)
