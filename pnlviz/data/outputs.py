"""Where a command may write: never into, over or under what it reads.

An output inside a dataset folder would become part of the dataset (a ``preds.json`` there is a
bogus frame); an output over an input destroys it; an output folder that holds an input (the
dataset's annotations, the detections, the edits folder) would write its files among them, over
them. :func:`check_output` is called before any work starts; :class:`OutputError` (one line naming
both paths) makes the command exit with status 2.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path

from .errors import DataError
from .filekind import os_error_text, output_problem

__all__ = ["OutputError", "check_output", "check_writable"]

PathLike = str | os.PathLike


class OutputError(DataError):
    """An output path that would overwrite an input or land inside a dataset (a usage error)."""


def _resolved(path: PathLike) -> Path:
    return Path(os.path.abspath(path)).resolve()


def _same_file(a: Path, b: Path) -> bool:
    if a == b:
        return True
    try:
        return os.path.samefile(a, b)  # hard links, case-insensitive file systems
    except OSError:
        return False


def check_writable(out: PathLike, what: str = "--out", folder: bool = False) -> None:
    """Raise :class:`OutputError` when ``out`` exists and is not what is written there (a regular
    file, or a folder with ``folder``): a device node, a FIFO or a symbolic link is never
    replaced; or when the nearest existing folder above it cannot be written (read-only file
    system, permission)."""
    source = f"{what} {os.fspath(out)}"
    problem = output_problem(out, folder)
    if problem:
        raise OutputError(source, problem)
    parent = Path(os.path.abspath(out))
    if not (folder and parent.is_dir()):
        parent = parent.parent
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    if not os.access(parent, os.W_OK):
        try:
            os.statvfs(parent)
            reason = "read-only file system" if os.statvfs(parent).f_flag & os.ST_RDONLY else "permission denied"
        except OSError as e:
            reason = os_error_text(e)
        raise OutputError(source, f"cannot write in {os.fspath(parent)}: {reason}")


def check_output(out: PathLike, *, inputs: Iterable[PathLike | None] = (), datasets: Iterable[PathLike | None] = (),
                 what: str = "--out", folder: bool = False) -> None:
    """Raise :class:`OutputError` (a DataError, one line naming both paths) when ``out`` is one of
    ``inputs`` (files or folders that must not be overwritten), or is, or lies inside, one of
    ``datasets`` (dataset folders or zips, edits folders), or when ``out`` holds one of them (an
    output folder above an input: its files would be written among and over the input's), or when
    it cannot be written (:func:`check_writable`). ``what`` names the output in the message (the
    option that gave it). None entries are ignored."""
    target = _resolved(out)
    source = f"{what} {os.fspath(out)}"
    for inp in inputs:
        if inp is None:
            continue
        path = _resolved(inp)
        if _same_file(target, path):
            raise OutputError(source, f"would overwrite the input {os.fspath(inp)}")
        if target in path.parents:
            raise OutputError(source, f"holds the input {os.fspath(inp)}: writing there would write over it; "
                                      f"write elsewhere")
    for ds in datasets:
        if ds is None:
            continue
        root = _resolved(ds)
        if _same_file(target, root):
            raise OutputError(source, f"would overwrite the dataset {os.fspath(ds)}")
        if root.is_dir() and root in target.parents:
            raise OutputError(source, f"is inside the dataset folder {os.fspath(ds)}: it would become part of "
                                      f"the dataset; write it elsewhere")
        if target in root.parents:
            raise OutputError(source, f"holds the dataset {os.fspath(ds)}: writing there would write over it; "
                                      f"write elsewhere")
    check_writable(out, what, folder)  # after the checks above, whose messages say more
