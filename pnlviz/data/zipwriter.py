"""Streaming batch outputs: each result goes into a temporary file beside the output as soon as it
is computed; :meth:`close` renames that file over the output, so the output is complete and valid
whenever it exists under its name, and an interrupted batch keeps what it computed.

:class:`ZipStream` writes a zip (deflated members, as :meth:`zipfile.ZipFile.writestr` does) and
:class:`LineStream` a text file of one line per result. With a sort ``key``, results that came
out of order are put in order when the file is closed (the zip is rewritten member by member
with the same timestamps), so the bytes do not depend on the order of arrival; members carry a fixed timestamp
(:data:`MEMBER_DATE`), so the same results make the same bytes, run here, resumed or on a cluster.

Resuming: with ``journal=True`` each member is also appended, as one JSON line, to a journal
beside the output (``.<name>.partial``), flushed at once, and the journal is removed when the
zip is in place. A run killed outright (no chance to close) leaves the journal; a run stopped by
Ctrl+C closes its zip. Either way :func:`resume_members` gives back what was done (the members of
the output zip, then those of the journal), for a command's ``--resume`` to skip.
"""

from __future__ import annotations

import base64
import contextlib
import json
import os
import tempfile
import zipfile
from collections.abc import Callable
from pathlib import Path
from typing import IO, Any

from .atomic import refuse_non_regular
from .filekind import names_path, naming
from .errors import DataError, member_source
from .reading import is_utf8

__all__ = ["MEMBER_DATE", "ZipStream", "LineStream", "journal_path", "member_info", "resume_members"]

#: every member's timestamp: the same results give the same bytes, whatever ran them and when
MEMBER_DATE = (1980, 1, 1, 0, 0, 0)


def member_info(name: str) -> zipfile.ZipInfo:
    """The header of a member pnlviz writes: deflated, mode 0644, dated :data:`MEMBER_DATE`."""
    info = zipfile.ZipInfo(name, date_time=MEMBER_DATE)
    info.compress_type, info.external_attr = zipfile.ZIP_DEFLATED, 0o644 << 16
    return info


def journal_path(path: str | os.PathLike) -> Path:
    """Where a :class:`ZipStream` with ``journal=True`` records its members as they are written."""
    p = Path(path)
    return p.with_name(f".{p.name}.partial")


def resume_members(path: str | os.PathLike) -> dict[str, str | bytes]:
    """What an earlier run of a batch writing ``path`` completed: the members of the zip at
    ``path`` (when it is one), then those of its journal (a torn last line, from a kill in the
    middle of a write, is ignored). ``{}`` when there is neither."""
    done: dict[str, str | bytes] = {}
    p = Path(path)
    if p.is_file():
        try:
            with zipfile.ZipFile(p) as z:
                for info in z.infolist():
                    data = z.read(info)
                    try:
                        done[info.filename] = data.decode("utf-8")
                    except UnicodeDecodeError:
                        done[info.filename] = data
        except (zipfile.BadZipFile, OSError) as exc:
            raise DataError(os.fspath(p), f"cannot resume from it: not a readable zip ({exc})") from None
    j = journal_path(p)
    if j.is_file():
        with open(j, encoding="utf-8", errors="replace") as f:
            for line in f:
                try:
                    rec = json.loads(line)
                    name = rec["name"]
                    data = rec["text"] if "text" in rec else base64.b64decode(rec["bytes"])
                except (ValueError, KeyError, TypeError):
                    continue  # the line a kill cut short
                done[name] = data
    return done


class _TempOutput:
    """A temporary file beside ``path`` that :meth:`_commit` renames over it."""

    def __init__(self, path: str | os.PathLike, keep_partial: bool):
        self.path = Path(path)
        self.keep_partial = keep_partial
        if self.path.is_dir():
            raise DataError(os.fspath(self.path), "is a folder: expected a file name for the output")
        refuse_non_regular(self.path)
        with naming(self.path):
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._tmp = self._new_temp()
        self.closed = False

    def _new_temp(self) -> str:
        fd, tmp = tempfile.mkstemp(prefix=f".{self.path.name}.", suffix=".tmp", dir=self.path.parent)
        os.close(fd)
        return tmp

    def _commit(self) -> None:
        with open(self._tmp, "rb+") as f:
            os.fsync(f.fileno())
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(self._tmp, 0o666 & ~umask)  # mkstemp gives 0600; the output gets the usual mode
        refuse_non_regular(self.path)
        os.replace(self._tmp, self.path)
        self.closed = True

    def _remove_temp(self) -> None:
        with contextlib.suppress(OSError):
            os.unlink(self._tmp)

    @names_path
    def close(self) -> Path:
        raise NotImplementedError

    def discard(self) -> None:
        raise NotImplementedError

    def __len__(self) -> int:
        raise NotImplementedError

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        """Close (keep) on success; on an exception close too when ``keep_partial`` and something
        was written, else discard (a run that failed before its first result leaves ``path`` as
        it was, not an empty output that looks like a finished one)."""
        if self.closed:
            return
        if exc_type is not None and (not self.keep_partial or len(self) == 0):
            self.discard()
            return
        try:
            self.close()
        except BaseException:
            self.discard()
            if exc_type is None:
                raise


class ZipStream(_TempOutput):
    """A zip written member by member; see the module docstring.

    ``key(name)`` orders the members at :meth:`close` (None: order of :meth:`add`).
    ``keep_partial``: an exception inside ``with ZipStream(...)`` still closes and keeps the zip
    (the default; for batches) instead of discarding it.
    """

    def __init__(self, path: str | os.PathLike, key: Callable[[str], Any] | None = None, keep_partial: bool = True,
                 journal: bool = False):
        super().__init__(path, keep_partial)
        self.key = key
        self.names: list[str] = []
        self._seen: set[str] = set()
        self._zip = zipfile.ZipFile(self._tmp, "w", compression=zipfile.ZIP_DEFLATED)
        self._journal: IO[str] | None = None
        if journal:  # a fresh record: a resumed run adds the members it takes over again
            self._journal = open(journal_path(self.path), "w", encoding="utf-8")

    def __len__(self) -> int:
        return len(self.names)

    @names_path
    def add(self, name: str, data: str | bytes) -> None:
        """Write one member now. A name that cannot be stored (not UTF-8, already written) raises
        DataError and writes nothing; the zip stays usable."""
        source = member_source(self.path, name)
        if not is_utf8(name):
            raise DataError(source, "member name is not valid UTF-8: not written")
        if name in self._seen:
            raise DataError(source, "written twice: the second copy is dropped")
        self._zip.writestr(member_info(name), data)
        self.names.append(name)
        self._seen.add(name)
        if self._journal is not None:
            rec = {"name": name, "text": data} if isinstance(data, str) else \
                {"name": name, "bytes": base64.b64encode(data).decode("ascii")}
            self._journal.write(json.dumps(rec) + "\n")
            self._journal.flush()

    def _end_journal(self) -> None:
        if self._journal is not None:
            self._journal.close()
            self._journal = None
            with contextlib.suppress(OSError):
                os.unlink(journal_path(self.path))

    @names_path
    def close(self) -> Path:
        """Finish the zip, put its members in ``key`` order, and move it over ``path``."""
        self._zip.close()
        if self.key is not None and self.names != sorted(self.names, key=self.key):
            self._reorder()
        self._commit()
        self._end_journal()  # only once the zip holds everything it recorded
        return self.path

    def _reorder(self) -> None:
        key = self.key
        assert key is not None  # close reorders only with a key
        tmp = self._new_temp()
        try:
            with zipfile.ZipFile(self._tmp) as src, zipfile.ZipFile(tmp, "w", compression=zipfile.ZIP_DEFLATED) as dst:
                for info in sorted(src.infolist(), key=lambda i: key(i.filename)):
                    copy = zipfile.ZipInfo(info.filename, date_time=info.date_time)
                    copy.compress_type, copy.external_attr = info.compress_type, info.external_attr
                    dst.writestr(copy, src.read(info))
            os.replace(tmp, self._tmp)
        except BaseException:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
            raise

    def discard(self) -> None:
        """Drop everything written; ``path`` is left as it was (and the journal, if any, kept
        for ``--resume`` when it records something)."""
        with contextlib.suppress(Exception):
            self._zip.close()
        if self._journal is not None:
            self._journal.close()
            self._journal = None
            if not self.names:
                with contextlib.suppress(OSError):
                    os.unlink(journal_path(self.path))
        self._remove_temp()
        self.closed = True


class LineStream(_TempOutput):
    """A text file of one line per result, written as they come (UTF-8).

    The ``key`` given to each :meth:`add` orders the lines at :meth:`close` (a stable sort:
    lines with equal keys keep their order).
    """

    def __init__(self, path: str | os.PathLike, keep_partial: bool = True):
        super().__init__(path, keep_partial)
        self._file: IO[str] = open(self._tmp, "w", encoding="utf-8", newline="")
        self._keys: list[Any] = []

    def __len__(self) -> int:
        return len(self._keys)

    @names_path
    def add(self, line: str, key: Any = 0) -> None:
        """Write ``line`` (a newline is added; it must not hold one)."""
        if "\n" in line or "\r" in line:
            raise ValueError("LineStream.add: one line at a time")
        self._file.write(line + "\n")
        self._file.flush()
        self._keys.append(key)

    @names_path
    def close(self) -> Path:
        """Finish the file, put its lines in key order, and move it over ``path``."""
        self._file.close()
        order = sorted(range(len(self._keys)), key=self._keys.__getitem__)
        if order != list(range(len(self._keys))):
            with open(self._tmp, encoding="utf-8", newline="") as f:
                lines = f.readlines()
            with open(self._tmp, "w", encoding="utf-8", newline="") as f:
                f.writelines(lines[i] for i in order)
        self._commit()
        return self.path

    def discard(self) -> None:
        """Drop everything written; ``path`` is left as it was."""
        with contextlib.suppress(Exception):
            self._file.close()
        self._remove_temp()
        self.closed = True
