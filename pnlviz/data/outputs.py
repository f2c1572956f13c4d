"""Where a command may write: never over one of its inputs, never inside (or over) a dataset.

An output inside a dataset folder would become part of the dataset (a ``preds.json`` there is a
bogus frame); an output over an input destroys it. :func:`check_output` is called before any
work starts; :class:`OutputError` makes the command exit with status 2.
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
    """Raise :class:`OutputError` (a DataError, one line) when ``out`` is one of ``inputs`` (files
    that must not be overwritten), or is, or lies inside, one of ``datasets`` (dataset folders or
    zips), or cannot be written (:func:`check_writable`). ``what`` names the output in the message
    (the option that gave it). None entries are ignored."""
    target = _resolved(out)
    source = f"{what} {os.fspath(out)}"
    for inp in inputs:
        if inp is not None and _same_file(target, _resolved(inp)):
            raise OutputError(source, f"would overwrite the input {os.fspath(inp)}")
    for ds in datasets:
        if ds is None:
            continue
        root = _resolved(ds)
        if _same_file(target, root):
            raise OutputError(source, f"would overwrite the dataset {os.fspath(ds)}")
        if root.is_dir() and root in target.parents:
            raise OutputError(source, f"is inside the dataset folder {os.fspath(ds)}: it would become part of "
                                      f"the dataset; write it elsewhere")
    check_writable(out, what, folder)  # after the checks above, whose messages say more
