"""The app's own files in its edits folder (the cuts of a clip, the triage cache), read through
one guarded reader: whatever is found there, reading never blocks, never runs out of memory and
never loses what a user made.

* a path that is not a regular file (a FIFO would block the reader, ``/dev/zero`` never ends, a
  socket, a folder) is not opened: it is **set aside** (renamed ``<name>.damaged-<time>``) with a
  warning, and the app goes on as if it were not there;
* a file over its size cap, not UTF-8 or not the JSON it should be is set aside the same way,
  never read as "nothing" and then written over (hand-made cuts would be lost);
* a file of JSON lines keeps its good lines: the bad ones are skipped and counted in one warning.

Every problem is one line in the ``warnings`` list the caller passes (the edits folder's).
"""

from __future__ import annotations

import json
import os
import stat
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from .filekind import kind_of
from .limits import MAX_JSON_BYTES, format_bytes

__all__ = ["MAX_LINES_BYTES", "JsonLinesFile", "read_state_json", "regular_or_set_aside", "set_aside", "state_folder",
           "state_lines"]

#: the largest file of JSON lines read (a cache: beyond this it is set aside and made anew)
MAX_LINES_BYTES = 256 * 1024 * 1024


def set_aside(path: Path, reason: str, warnings: list[str]) -> Path | None:
    """Rename ``path`` to ``<name>.damaged-<time>`` (kept, never deleted) with one warning; the
    new path, None when it could not be moved (then it is left as it is, and not read)."""
    stamp = time.strftime("%Y%m%d-%H%M%S")
    target = path.with_name(f"{path.name}.damaged-{stamp}")
    n = 1
    while os.path.lexists(target):
        target = path.with_name(f"{path.name}.damaged-{stamp}.{n}")
        n += 1
    try:
        os.replace(path, target)
    except OSError as exc:
        warnings.append(f"{path}: {reason}; not read, and it cannot be moved aside ({exc.strerror or exc})")
        return None
    warnings.append(f"{path}: {reason}; moved aside to {target.name}")
    return target


def regular_or_set_aside(path: Path, warnings: list[str], limit: int) -> bool:
    """True when ``path`` is a regular file within ``limit`` bytes; False when it is missing, or
    (set aside) anything else."""
    try:
        st = os.stat(path)  # follows a link: a link to /dev/zero is a character device
    except FileNotFoundError:
        if os.path.islink(path):  # a dangling link
            set_aside(path, "a symbolic link to nothing", warnings)
        return False
    except OSError as exc:
        set_aside(path, f"cannot be read ({exc.strerror or exc})", warnings)
        return False
    if not stat.S_ISREG(st.st_mode):
        set_aside(path, f"is {kind_of(st.st_mode)}, not a regular file", warnings)
        return False
    if st.st_size > limit:
        set_aside(path, f"too large ({format_bytes(st.st_size)}, the limit is {format_bytes(limit)})", warnings)
        return False
    return True


def _read_regular(path: Path, limit: int) -> bytes:
    """The bytes of a regular file, opened without blocking and read up to ``limit`` (+1)."""
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):  # replaced since it was looked at
            raise OSError(f"{path} is not a regular file")
        os.set_blocking(fd, True)
        with os.fdopen(fd, "rb", closefd=False) as f:
            return f.read(limit + 1)
    finally:
        os.close(fd)


def read_state_json(path: Path, warnings: list[str], check: Callable[[Any], Any] | None = None,
                    limit: int = MAX_JSON_BYTES) -> Any | None:
    """The JSON value of one of the app's files (``check(value)`` may convert it, raising
    ValueError or TypeError for a value it does not accept); None when there is none. A file that
    is not a regular file, is too large, or does not parse is set aside with a warning."""
    path = Path(path)
    if not regular_or_set_aside(path, warnings, limit):
        return None
    try:
        data = _read_regular(path, limit)
        if len(data) > limit:
            raise ValueError(f"too large (over {format_bytes(limit)})")
        value = json.loads(data.decode("utf-8"))
        return check(value) if check is not None else value
    except OSError as exc:
        set_aside(path, f"cannot be read ({exc.strerror or exc})", warnings)
    except (ValueError, TypeError, RecursionError) as exc:  # JSON, UTF-8 and check errors
        set_aside(path, f"damaged ({str(exc)[:120] or type(exc).__name__})", warnings)
    return None


def state_lines(path: Path, warnings: list[str], limit: int = MAX_LINES_BYTES) -> Iterator[tuple[int, int, Any]]:
    """``(offset, length, value)`` of each line of a file of JSON lines that parses; the others
    are skipped and counted in one warning. A path that is not a regular file, or a file over
    ``limit``, is set aside (nothing is read from it)."""
    path = Path(path)
    if not regular_or_set_aside(path, warnings, limit):
        return
    bad = 0
    offset = 0
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            return
        os.set_blocking(fd, True)
        with os.fdopen(fd, "rb", closefd=False) as f:
            for raw in f:
                try:
                    yield offset, len(raw), json.loads(raw)
                except (ValueError, RecursionError):
                    if raw.strip():
                        bad += 1
                offset += len(raw)
    finally:
        os.close(fd)
    if bad:
        warnings.append(f"{path}: {bad} damaged line(s) skipped")


def state_folder(path: Path, warnings: list[str]) -> Path:
    """``path`` as a folder of the app's files, made when missing; anything else found there (a
    file, a FIFO) is set aside first."""
    path = Path(path)
    if os.path.lexists(path) and not path.is_dir():
        set_aside(path, "is not a folder", warnings)
    path.mkdir(parents=True, exist_ok=True)
    return path


class JsonLinesFile:
    """An append-only file of JSON lines kept by the app (``None`` path: memory only, for a
    read-only edits folder), read through the guarded reader (:func:`state_lines`)."""

    def __init__(self, path: Path | None, warnings: list[str]):
        self.path, self.warnings = path, warnings
        self._lock = threading.Lock()
        if path is not None and regular_or_set_aside(path, warnings, MAX_LINES_BYTES) and path.stat().st_size:
            with open(path, "rb+") as f:  # a line torn by a crash is ended, so the next one starts clean
                f.seek(-1, os.SEEK_END)
                if f.read(1) != b"\n":
                    f.write(b"\n")

    def rewrite(self, objects) -> None:
        """The file with these lines only (atomically), e.g. the latest line of each frame."""
        if self.path is None:
            return
        from .atomic import atomic_write_text

        with self._lock:
            atomic_write_text(self.path, "".join(json.dumps(o, separators=(",", ":")) + "\n" for o in objects))

    def lines(self) -> Iterator[tuple[int, int, Any]]:
        """(offset, length, value) of each line that parses (:func:`state_lines`)."""
        if self.path is not None:
            yield from state_lines(self.path, self.warnings)

    def append(self, obj: dict) -> tuple[int, int] | None:
        if self.path is None:
            return None
        data = (json.dumps(obj, separators=(",", ":"), allow_nan=False) + "\n").encode()
        with self._lock:
            with open(self.path, "ab") as f:
                offset = f.seek(0, os.SEEK_END)
                f.write(data)
        return offset, len(data)

    def read(self, offset: int, length: int) -> Any:
        """The line at ``offset`` (from :meth:`append` or :meth:`lines`)."""
        assert self.path is not None  # offsets come from a file
        with self._lock:
            fd = os.open(self.path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
            try:
                if not stat.S_ISREG(os.fstat(fd).st_mode):
                    raise OSError(f"{self.path} is not a regular file")
                return json.loads(os.pread(fd, length, offset))
            finally:
                os.close(fd)
