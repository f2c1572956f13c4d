"""Which files of a dataset folder or zip are frames: the names are listed once (``os.scandir``
/ the zip's central directory, nothing read), sorted into one image and one annotation per frame
stem, and the files that are not used are listed with the reason (rules in
:mod:`pnlviz.data.dataset`).
"""

from __future__ import annotations

import os
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

from .errors import DataError, member_source
from .filekind import os_error_text
from .layout import find_root, is_junk, split_member
from .reading import bad_name_error, is_utf8

#: Image file extensions recognised as frames, in order of preference for a stem with several.
IMAGE_EXTENSIONS: tuple[str, ...] = (".jpg", ".jpeg", ".png")
MATCH_INFO = "match_info.json"
CAMERAS_DIR = "cameras"

__all__ = ["CAMERAS_DIR", "IMAGE_EXTENSIONS", "MATCH_INFO", "DatasetIndex", "index_folder", "index_zip"]


def classify(base: str) -> tuple[str, str] | None:
    """``("image"|"annotation", stem)`` for a frame file name, else None."""
    lower = base.lower()
    if lower == MATCH_INFO or base.startswith("."):
        return None
    stem, dot, ext = base.rpartition(".")
    if not dot or not stem:
        return None
    ext = "." + ext.lower()
    if ext == ".json":
        return ("annotation", stem)
    if ext in IMAGE_EXTENSIONS:
        return ("image", stem)
    return None


def _preference(what: str, base: str) -> tuple:
    """Sort key of the files of one frame: the first one is used (rule in the dataset docstring)."""
    ext = "." + base.rpartition(".")[2]
    if what == "annotation":
        return (ext != ".json", base)
    return (IMAGE_EXTENSIONS.index(ext.lower()), ext != ext.lower(), base)


@dataclass
class DatasetIndex:
    """The frame files of a dataset. Names are file paths (a folder) or member names (a zip,
    ``archive`` its path). ``root``: the folder holding the frames (a path, or a member prefix
    such as ``""`` or ``"dir/"`` in a zip); ``members``: every member name of a zip (None for a
    folder, whose other files are looked up on disk when asked for)."""

    archive: Path | None
    root: str
    images: dict[str, str] = field(default_factory=dict)
    annotations: dict[str, str] = field(default_factory=dict)
    rejected: list[DataError] = field(default_factory=list)
    members: set[str] | None = None
    camera_members: set[str] | None = None

    def source(self, name: str) -> str:
        """The ``<file>`` part of an error message for ``name``."""
        return member_source(self.archive, name) if self.archive is not None else name

    def path(self, *parts: str) -> str:
        """The name of a file under the root (``path("cameras", "camera_1.json")``)."""
        if self.archive is not None:
            return self.root + "/".join(parts)
        return os.fspath(Path(self.root, *parts))

    def _sort(self, files: list[tuple[str, str]]) -> None:
        """One file per frame and kind (the preferred one); the others go to :attr:`rejected`."""
        by_frame: dict[tuple[str, str], list[tuple[str, str]]] = {}
        for base, name in files:
            kind = classify(base)
            if kind is None:
                continue
            if not is_utf8(kind[1]):
                self.rejected.append(bad_name_error(self.source(name)))
                continue
            by_frame.setdefault(kind, []).append((base, name))
        for (what, stem), candidates in by_frame.items():
            candidates.sort(key=lambda f: _preference(what, f[0]))
            (self.annotations if what == "annotation" else self.images)[stem] = candidates[0][1]
            for _, name in candidates[1:]:
                self.rejected.append(DataError(self.source(name), f"another {what} of frame {stem!r} is used "
                                                                  f"({candidates[0][0]}): this file is ignored"))
        self.rejected.sort(key=str)


@dataclass
class FolderScan:
    """One listing of a folder (hidden names left out): ``files`` the frame files ``(name,
    path)``, ``subdirs`` its folders but ``cameras/``, ``zips`` its ``*.zip`` files (split zips,
    :mod:`pnlviz.data.splits`), ``broken`` the entries that cannot be read (a symlink loop)."""

    files: list[tuple[str, str]] = field(default_factory=list)
    subdirs: list[str] = field(default_factory=list)
    zips: list[str] = field(default_factory=list)
    broken: list[DataError] = field(default_factory=list)


def scan_folder(root: Path) -> FolderScan:
    scan = FolderScan()
    with os.scandir(root) as it:
        for entry in it:
            if entry.name.startswith("."):
                continue
            try:
                is_dir = entry.is_dir()  # follows a symlink: a loop raises ELOOP
            except OSError as e:
                scan.broken.append(DataError(entry.path, f"cannot read: {os_error_text(e)}: skipped"))
                continue
            if is_dir:
                if entry.name != CAMERAS_DIR:
                    scan.subdirs.append(entry.path)
            elif classify(entry.name) is not None:
                scan.files.append((entry.name, entry.path))
            elif entry.name.lower().endswith(".zip") and len(entry.name) > 4:
                scan.zips.append(entry.path)
    return scan


def frame_folder(path: str | os.PathLike, *, stop_at_zips: bool = False) -> tuple[Path, FolderScan]:
    """The folder holding a dataset's frames and its listing: ``path`` itself, or its single
    subfolder when it has no frame file (nor, with ``stop_at_zips``, a zip)."""
    root = Path(path)
    scan = scan_folder(root)
    if not scan.files and len(scan.subdirs) == 1 and not (stop_at_zips and scan.zips):
        root = Path(scan.subdirs[0])
        scan = scan_folder(root)
    return root, scan


def index_folder(path: Path, listing: tuple[Path, FolderScan] | None = None) -> DatasetIndex:
    """The frames of a folder: at its top level, or inside its single subfolder (``listing``:
    :func:`frame_folder`'s result when the caller has it already)."""
    root, scan = listing or frame_folder(path)
    files, broken = scan.files, scan.broken
    index = DatasetIndex(None, os.fspath(root))
    index._sort(files)
    index.rejected = sorted(index.rejected + broken, key=str)
    return index


def index_zip(path: Path, zf: zipfile.ZipFile, root: str | None = None) -> DatasetIndex:
    """The frames of an open zip: at its top level, or inside its single top-level folder; or,
    with ``root`` (a member prefix such as ``"valid/"``), the frames in that folder (one split of
    a zip holding several, :mod:`pnlviz.data.splits`)."""
    index = DatasetIndex(Path(path), "")
    names, seen = [], set()
    for n in zf.namelist():
        if is_junk(n):
            continue
        if n in seen:
            index.rejected.append(DataError(index.source(n), "appears twice in the archive: the last copy is used"))
            continue
        seen.add(n)
        names.append(n)
    candidates = [n for n in names if n.split("/", 1)[0] != CAMERAS_DIR]
    index.root = find_root(candidates, lambda b: classify(b) is not None) if root is None else root
    index.members, index.camera_members = set(names), set()
    cam_prefix = index.root + CAMERAS_DIR + "/"
    files = []
    for n in names:
        prefix, base = split_member(n)
        if prefix == index.root:
            files.append((base, n))
        elif prefix == cam_prefix:
            index.camera_members.add(base)
    index._sort(files)
    return index
