"""The one exception type of :mod:`pnlviz.data`.

Every problem with an input file (bad JSON, unknown class, coordinates out of range, corrupt
image, missing camera key...) raises :class:`DataError`, whose message is a single line
``"<file>: <problem>"`` so that batch commands can print it as is, one line per bad file.
``<file>`` is a path, or ``"archive.zip:member.json"`` for a member of a zip archive.
"""

from __future__ import annotations

import os

__all__ = ["DataError", "member_source"]


def _one_line(text: object) -> str:
    return " ".join(str(text).splitlines()).strip()


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


def read_zip_member(zf, member: str, source: str) -> bytes:
    """The bytes of a zip member; a damaged member is a :class:`DataError` naming ``source``."""
    import zipfile

    try:
        return zf.read(member)
    except (OSError, zipfile.BadZipFile, EOFError) as e:
        raise DataError(source, f"cannot read zip member: {e}") from None
