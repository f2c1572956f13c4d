"""Which dataset an edits folder belongs to, and what a command may take as one.

An edit record labels the pictures of one dataset: read against another dataset whose frames
have the same names (``00000``, ``00001``, ...) it would label other pictures. So every record
written carries its frame's identity (:func:`frame_identity`: the image size, and a digest of
the frame's annotation file and of the head of its image file), and ``<edits>/dataset.json``
names the dataset the folder was made for. When a folder is opened, its records are checked
against the dataset's frames (:func:`check_identity`): records of frames the dataset does not
have, or whose frame is another picture, make the folder refused, with the mismatches listed,
unless the user adopts it (``--force-edits``). Records written before identities were kept
carry none and cannot be checked (a command that reads the folder says how many in one warning;
the app gives them the identity of their frame when it writes them again).

Commands that only read an edits folder (``export``, ``qa``, ``calibrate``) take ``--edits`` only
when it is one (:func:`require_edits_folder`): a typo, a file, a FIFO or ``/dev/zero`` is an
error, never "no edits".
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import time
import zipfile
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from pnlviz.data.edits_layout import EditsLayout
from pnlviz.data.errors import DataError

__all__ = ["IDENTITY_FILE", "check_identity", "frame_identity", "identity_problem", "require_edits_folder",
           "write_dataset_file"]

#: the file naming the dataset an edits folder was made for
IDENTITY_FILE = EditsLayout(Path(".")).identity.name  #: the dataset file's name
#: bytes of an image file read into its frame's digest (its header and the first of its data)
IMAGE_HEAD = 16384
#: records checked when a folder is opened (an export checks every one it writes)
CHECKED_AT_OPEN = 400


class _Files:
    """Reads the heads of the files of a dataset's frames (zips opened once)."""

    def __init__(self) -> None:
        self.zips: dict[str, zipfile.ZipFile] = {}

    def head(self, name: str, archive: str | None, n: int | None) -> bytes:
        if archive is None:
            with open(name, "rb") as f:
                return f.read(n if n is not None else -1)
        zf = self.zips.get(archive)
        if zf is None:
            zf = self.zips[archive] = zipfile.ZipFile(archive)
        with zf.open(name) as f:
            return f.read(n if n is not None else -1)

    def close(self) -> None:
        for zf in self.zips.values():
            zf.close()


def frame_identity(ds, stem: str, files: _Files | None = None) -> dict:
    """``{"size": [W, H] | None, "digest": hex}`` of frame ``stem`` of dataset ``ds``: its image
    size, and a SHA-1 of its annotation file and of the first :data:`IMAGE_HEAD` bytes of its
    image file (of the video file and the frame's index for a video's frame). A file that cannot
    be read counts as absent."""
    own = files is None
    files = files or _Files()
    try:
        frame = ds.frame(stem)
        h = hashlib.sha1()
        for name, n in ((frame.annotation_path, None), (frame.image_path, IMAGE_HEAD)):
            h.update(b"\x00")
            if name is None:
                continue
            path, sep, index = str(name).rpartition("#")
            if sep and frame.archive is None and not os.path.exists(name):  # a video's frame: <video>#<index>
                name, tail = path, f"#{index}".encode()
            else:
                tail = b""
            with contextlib.suppress(OSError, KeyError, zipfile.BadZipFile, RuntimeError):
                h.update(files.head(name, frame.archive, n) + tail)
        try:
            size = ds.image_size(stem)
        except DataError:
            size = None
        return {"size": None if size is None else [int(size[0]), int(size[1])], "digest": h.hexdigest()}
    finally:
        if own:
            files.close()


def identity_problem(recorded: Any, current: Mapping) -> str | None:
    """Why a record's frame identity is not the frame's now (None: it is)."""
    if not isinstance(recorded, Mapping):
        return None
    if recorded.get("size") != current.get("size"):
        return f"image size {recorded.get('size')} when edited, {current.get('size')} now"
    if recorded.get("digest") != current.get("digest"):
        return "another picture or annotation than the one edited"
    return None


def check_identity(store, ds, *, force: bool = False, stems: Iterable[str] | None = None,
                   limit: int | None = CHECKED_AT_OPEN) -> list[str]:
    """The records of the edits folder ``store`` (an :class:`pnlviz.data.edits.EditsStore`)
    checked against dataset ``ds``: those of ``stems`` (default: every record, at most ``limit``
    of them, spread over the folder). Returns the mismatches, one line each; raises
    :class:`pnlviz.data.edits.EditsFolderError` listing them unless ``force`` (then the store
    gets a warning). Records without an identity are counted in a warning."""
    from pnlviz.data.edits import EditsFolderError

    names = list(store.stems() if stems is None else stems)
    if limit is not None and len(names) > limit:
        names = names[:: max(1, len(names) // limit)][:limit]
    known = set(ds.stems)
    problems: list[str] = []
    unchecked = 0
    files = _Files()
    try:
        for stem in names:
            rec = store.get(stem)
            if not rec:
                continue
            if stem not in known:
                problems.append(f"{stem}: has an edit record but is not a frame of {os.fspath(ds.path)}")
                continue
            if "frame" not in rec:
                unchecked += 1
                continue
            why = identity_problem(rec["frame"], frame_identity(ds, stem, files))
            if why:
                problems.append(f"{stem}: {why}")
    finally:
        files.close()
    if unchecked and not store.writable:  # the app stamps them as it writes them again
        store.warnings[:] = [w for w in store.warnings if "carry no frame identity" not in w]
        store.warnings.append(f"{store.root}: {unchecked} edit record(s) carry no frame identity (written before "
                              "it was kept): they cannot be checked against the dataset")
    if problems and not force:
        made_for = _made_for(store.root)
        listed = "; ".join(problems[:5]) + (f"; and {len(problems) - 5} more" if len(problems) > 5 else "")
        raise EditsFolderError(f"{store.root} holds edits of another dataset{made_for} than {os.fspath(ds.path)} "
                               f"({len(problems)} of {len(names)} records checked do not match: {listed}); "
                               f"give the right --edits, or adopt this folder with --force-edits")
    if problems:
        store.warnings[:] = [w for w in store.warnings if "adopted with --force-edits" not in w]
        store.warnings.append(f"{store.root}: adopted with --force-edits although {len(problems)} record(s) "
                              f"do not match {os.fspath(ds.path)}")
    return problems


def _made_for(root: Path) -> str:
    try:
        return f" (made for {json.loads(EditsLayout(root).identity.read_text())['dataset']})"
    except (OSError, ValueError, KeyError, TypeError):
        return ""


def write_dataset_file(root: Path, ds) -> None:
    """``<edits>/dataset.json``: the dataset the folder is made for (written once, when missing)."""
    from pnlviz.data.atomic import atomic_write_text

    path = EditsLayout(root).identity
    if path.exists():
        return
    with contextlib.suppress(OSError):
        atomic_write_text(path, json.dumps({"dataset": os.fspath(Path(ds.path).resolve()), "frames": len(ds.stems),
                                            "created": time.strftime("%Y-%m-%dT%H:%M:%S")}))


def require_edits_folder(path, what: str = "--edits") -> Path:
    """``path`` as an existing edits folder (one holding ``frames/``, ``lock`` or
    ``dataset.json``); a DataError saying what it is otherwise (missing, a file, a FIFO or device,
    a folder without edits)."""
    p = Path(path)
    source = f"{what} {os.fspath(p)}"
    if not p.exists():
        raise DataError(source, "does not exist (an edits folder is made by pnlviz serve)")
    if not p.is_dir():
        raise DataError(source, "is not a folder (an edits folder holds frames/ with one record per frame)")
    if not EditsLayout(p).is_edits_folder():
        raise DataError(source, "is not an edits folder (it holds no frames/, lock or dataset.json)")
    return p
