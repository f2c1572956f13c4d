"""What a path is, checked before it is opened: inputs must be regular files (or folders where a
folder is expected), never a FIFO (opening one blocks), a device (``/dev/zero`` never ends) or a
symlink loop; outputs that exist must be what the command writes (a regular file, or a folder), so
that an atomic rename never replaces a device node, a FIFO or a symbolic link.

Every refusal is a one-line :class:`~pnlviz.data.errors.DataError` naming the path and what it is.
"""

from __future__ import annotations

import contextlib
import errno
import functools
import os
import stat
from collections.abc import Iterator

from .errors import DataError

__all__ = ["kind_of", "open_regular", "require_input", "output_problem", "os_error_text", "naming", "names_path"]


def kind_of(mode: int) -> str:
    """``st_mode`` -> "a regular file", "a FIFO (named pipe)", "a character device"..."""
    for test, name in ((stat.S_ISREG, "a regular file"), (stat.S_ISDIR, "a folder"),
                       (stat.S_ISFIFO, "a FIFO (named pipe)"), (stat.S_ISCHR, "a character device"),
                       (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"),
                       (stat.S_ISLNK, "a symbolic link")):
        if test(mode):
            return name
    return "not a regular file"


def os_error_text(e: OSError) -> str:
    """An OSError as a short reason; a symlink loop said as such."""
    if e.errno == errno.ELOOP:
        return "a symbolic link loop (too many levels of symbolic links)"
    return e.strerror or str(e)


def open_regular(path: str | os.PathLike, source: str | None = None) -> int:
    """A read-only file descriptor of ``path``, which must be a regular file. Opened without
    blocking (a FIFO opens at once) and checked with ``fstat`` before anything is read."""
    source = os.fspath(path) if source is None else source
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    except OSError as e:
        raise DataError(source, f"cannot read file: {os_error_text(e)}") from None
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            raise DataError(source, f"is {kind_of(mode)}, not a regular file: not read")
        os.set_blocking(fd, True)
    except BaseException:
        os.close(fd)
        raise
    return fd


def require_input(path: str | os.PathLike, what: str = "", folder: bool | None = None) -> None:
    """Refuse an input path that is not a regular file or a folder (``folder`` True: must be a
    folder; False: must be a file; None: either)."""
    source = f"{what} {os.fspath(path)}".strip()
    try:
        mode = os.stat(path).st_mode
    except OSError as e:
        raise DataError(source, f"cannot read: {os_error_text(e)}") from None
    ok = (stat.S_ISREG(mode) and folder is not True) or (stat.S_ISDIR(mode) and folder is not False)
    if not ok:
        expected = {True: "a folder", False: "a regular file", None: "a regular file or a folder"}[folder]
        raise DataError(source, f"is {kind_of(mode)}, not {expected}: not read")


def output_problem(path: str | os.PathLike, folder: bool = False) -> str | None:
    """Why ``path`` cannot be written as an output (None when it can): it exists and is not a
    regular file (``folder``: not a folder), or its folder is not writable."""
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        st = None
    except OSError as e:
        return f"cannot be checked: {os_error_text(e)}"
    if st is not None:
        if stat.S_ISLNK(st.st_mode) and folder:
            try:
                st = os.stat(path)
            except OSError as e:
                return f"is a symbolic link that cannot be followed ({os_error_text(e)})"
        if folder and not stat.S_ISDIR(st.st_mode):
            return f"exists and is {kind_of(st.st_mode)}, not a folder: not replaced"
        if not folder and not stat.S_ISREG(st.st_mode):
            return f"exists and is {kind_of(st.st_mode)}, not a regular file: not replaced"
    return None


@contextlib.contextmanager
def naming(path: str | os.PathLike) -> Iterator[None]:
    """An OSError inside the block that names no file (a ``write`` on a full disk) names ``path``:
    the one-line error says which output could not be written."""
    try:
        yield
    except OSError as e:
        if e.filename is None and e.errno is not None:
            raise OSError(e.errno, e.strerror or str(e), os.fspath(path)) from None
        raise


def names_path(method):
    """:func:`naming` for a method of an object writing ``self.path``."""
    @functools.wraps(method)
    def wrapper(self, *args, **kwargs):
        with naming(self.path):
            return method(self, *args, **kwargs)
    return wrapper
