"""Reading input files and zip members: every failure is one :class:`DataError` line.

Sizes are checked against :mod:`pnlviz.data.limits` before anything is read or decompressed, and
reads are bounded (a member whose header lies about its size is still read at most up to the
limit). A zip member that cannot be read for any reason (corrupt deflate stream, bad CRC,
truncated archive, unsupported compression method, encryption, missing member) raises
``DataError("<zip>:<member>", "cannot read zip member: ...")``.
"""

from __future__ import annotations

import contextlib
import os
import zipfile
import zlib
from collections.abc import Callable, Iterator
from typing import IO

from .errors import DataError
from .filekind import open_regular, require_input
from .layout import is_junk, split_member
from .limits import MAX_DATASET_JSON_BYTES, MAX_IMAGE_BYTES, MAX_JSON_BYTES, format_bytes

__all__ = [
    "frame_files",
    "ZIP_MEMBER_ERRORS", "open_zip", "zip_member", "read_zip_member", "open_file", "read_file",
    "limit_for", "is_utf8", "bad_name_error",
]

#: What :mod:`zipfile` raises for a member it cannot read.
ZIP_MEMBER_ERRORS = (zlib.error, zipfile.BadZipFile, EOFError, OSError, NotImplementedError, RuntimeError, KeyError)
_IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png")


def limit_for(name: str) -> int:
    """The byte cap of a dataset's file by its extension: images :data:`MAX_IMAGE_BYTES`, else an
    annotation's (:data:`MAX_DATASET_JSON_BYTES`)."""
    return MAX_IMAGE_BYTES if name.lower().endswith(_IMAGE_SUFFIXES) else MAX_DATASET_JSON_BYTES


def _too_large(source: str, size: int, limit: int) -> DataError:
    return DataError(source, f"file too large: {format_bytes(size)} (the limit for this kind of file is "
                             f"{format_bytes(limit)})")


def is_utf8(name: str) -> bool:
    """False for a name that cannot be written as UTF-8 (``os.scandir`` gives such names, not valid
    UTF-8 on disk, with surrogate escapes)."""
    try:
        name.encode("utf-8")
    except UnicodeEncodeError:
        return False
    return True


def bad_name_error(source: str) -> DataError:
    """The error of a file whose name is not valid UTF-8 (it is skipped, never becomes a stem)."""
    return DataError(source, "file name is not valid UTF-8: skipped (rename the file)")


def _reason(e: BaseException) -> str:
    text = e.args[0] if isinstance(e, KeyError) and e.args else str(e)
    if isinstance(e, RuntimeError) and "encrypted" in str(text):
        return "the member is encrypted (not supported)"
    return str(text) or type(e).__name__


def open_zip(path: str | os.PathLike, not_zip: str = "not a valid .zip archive") -> zipfile.ZipFile:
    """Open a zip archive for reading; any failure is a DataError naming ``path``."""
    source = os.fspath(path)
    require_input(path, folder=False)
    try:
        return zipfile.ZipFile(path)
    except zipfile.BadZipFile:
        raise DataError(source, not_zip) from None
    except OSError as e:
        raise DataError(source, f"cannot open zip archive: {e.strerror or e}") from None
    except UnicodeDecodeError:
        raise DataError(source, "cannot open zip archive: a member name flagged UTF-8 is not valid UTF-8") from None
    except (EOFError, ValueError, NotImplementedError, RuntimeError) as e:
        raise DataError(source, f"cannot open zip archive: {_reason(e)}") from None


@contextlib.contextmanager
def zip_member(zf: zipfile.ZipFile, member: str, source: str, limit: int) -> Iterator[IO[bytes]]:
    """The open member, after its declared size was checked against ``limit``. A read failure
    inside the ``with`` block becomes ``DataError(source, "cannot read zip member: ...")``."""
    try:
        info = zf.getinfo(member)
        if info.file_size > limit:
            raise _too_large(source, info.file_size, limit)
        with zf.open(info) as f:
            yield f
    except ZIP_MEMBER_ERRORS as e:
        raise DataError(source, f"cannot read zip member: {_reason(e)}") from None


def read_zip_member(zf: zipfile.ZipFile, member: str, source: str, limit: int = MAX_JSON_BYTES) -> bytes:
    """The bytes of a zip member (at most ``limit``); any failure is a DataError naming ``source``."""
    with zip_member(zf, member, source, limit) as f:
        data = f.read(limit + 1)
    if len(data) > limit:
        raise _too_large(source, len(data), limit)
    return data


@contextlib.contextmanager
def open_file(path: str | os.PathLike, limit: int, source: str | None = None) -> Iterator[IO[bytes]]:
    """A file open for reading, after its size was checked against ``limit``; OSError inside the
    ``with`` block becomes ``DataError(source, "cannot read file: ...")``."""
    source = os.fspath(path) if source is None else source
    fd = open_regular(path, source)  # never blocks on a FIFO, never reads a device
    try:
        with os.fdopen(fd, "rb") as f:
            size = os.fstat(f.fileno()).st_size
            if size > limit:
                raise _too_large(source, size, limit)
            yield f
    except OSError as e:
        raise DataError(source, f"cannot read file: {e.strerror or e}") from None


def read_file(path: str | os.PathLike, limit: int = MAX_JSON_BYTES, source: str | None = None) -> bytes:
    """The bytes of a file (at most ``limit``, also for a file that grows or a device)."""
    source = os.fspath(path) if source is None else source
    with open_file(path, limit, source) as f:
        data = f.read(limit + 1)
    if len(data) > limit:
        raise _too_large(source, len(data), limit)
    return data


def frame_files(path: str | os.PathLike, zf: zipfile.ZipFile | None, stem_of: Callable[[str], str | None],
                rejected: Callable[[DataError], None]) -> dict[str, list[tuple[str, str]]]:
    """The per-frame files of an output zip (``zf``) or folder (``path``), grouped by folder:
    ``{prefix: [(stem, member name or file path)]}`` for the names ``stem_of`` gives a stem
    (prefixes ``""``, ``"a/"``, ``"a/b/"``: three levels at most). Junk names are skipped; a
    folder's file whose name is not valid UTF-8 goes to ``rejected``. For
    :func:`pnlviz.data.layout.keyed_members`."""
    found: dict[str, list[tuple[str, str]]] = {}

    def add(prefix: str, base: str, name: str) -> None:
        stem = stem_of(base)
        if stem is not None:
            found.setdefault(prefix, []).append((stem, name))

    if zf is not None:
        for name in zf.namelist():
            prefix, base = split_member(name)
            if not is_junk(name) and prefix.count("/") <= 2:
                add(prefix, base, name)
        return found

    def walk(folder: str, prefix: str) -> None:
        with os.scandir(folder) as it:
            entries = sorted(it, key=lambda e: e.name)
        for e in entries:
            if is_junk(e.name):
                continue
            if not is_utf8(e.name):
                if stem_of(e.name) is not None:
                    rejected(bad_name_error(e.path))
            elif e.is_dir():
                if prefix.count("/") < 2:
                    walk(e.path, f"{prefix}{e.name}/")
            elif e.is_file():
                add(prefix, e.name, e.path)

    walk(os.fspath(path), "")
    return found
