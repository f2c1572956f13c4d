"""Atomic file writes: a temporary file in the destination folder, then :func:`os.replace`.

A reader (or a crash) never sees a half-written file: it sees the old content or the new one.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import IO

__all__ = ["atomic_open", "atomic_write_bytes", "atomic_write_text", "refuse_non_regular"]


def refuse_non_regular(path: str | os.PathLike) -> None:
    """Raise :class:`~pnlviz.data.outputs.OutputError` when ``path`` exists and is not a regular
    file: the rename would replace a device node, a FIFO or a symbolic link."""
    from .filekind import output_problem
    from .outputs import OutputError

    problem = output_problem(path)
    if problem:
        raise OutputError(os.fspath(path), problem)


@contextlib.contextmanager
def atomic_open(path: str | os.PathLike, mode: str = "wb", encoding: str | None = None) -> Iterator[IO]:
    """Open a temporary file next to ``path`` for writing; on success it replaces ``path``.

    ``mode`` is ``"wb"`` or ``"w"`` (text, UTF-8 unless ``encoding`` is given). If the body
    raises, the temporary file is removed and ``path`` is left untouched. Parent folders are
    created. The data is flushed and fsync'ed before the rename.
    """
    if mode not in ("w", "wb"):
        raise ValueError(f"atomic_open: mode must be 'w' or 'wb', not {mode!r}")
    from .filekind import naming

    path = Path(path)
    refuse_non_regular(path)
    with naming(path):
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        f: IO
        if mode == "w":
            f = os.fdopen(fd, "w", encoding=encoding or "utf-8", newline="")
        else:
            f = os.fdopen(fd, "wb")
        with f:
            yield f
            f.flush()
            os.fsync(f.fileno())
        # mkstemp creates files with mode 0600; give the result the usual permissions.
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        refuse_non_regular(path)
        os.replace(tmp, path)
    except OSError as e:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        if e.filename is None and e.errno is not None:  # a write on a full disk: name the output
            raise OSError(e.errno, e.strerror or str(e), os.fspath(path)) from None
        raise
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically."""
    with atomic_open(path, "wb") as f:
        f.write(data)


def atomic_write_text(path: str | os.PathLike, text: str, encoding: str = "utf-8") -> None:
    """Write ``text`` to ``path`` atomically (no newline translation)."""
    with atomic_open(path, "w", encoding=encoding) as f:
        f.write(text)
