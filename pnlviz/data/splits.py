"""Datasets as SoccerNet ships them: frames in split folders or split zips.

SoccerNet-Calibration comes as ``sn23/train/``, ``sn23/valid/``, ``sn23/test/``,
``sn23/challenge/`` (each a plain dataset: ``00000.jpg``, ``00000.json``, ...), or as the zips
``train.zip``, ``valid.zip``, ... beside each other, or as one zip holding the split folders.
Any of these opens as one dataset whose frames are named ``<split>/<stem>`` (``valid/00042``), so
every output keeps the split and maps back to its file: a camera zip holds
``valid/camera_00042.json``, a prediction zip ``valid/00042.json``, an edits folder
``frames/valid/00042.json``.

The rule (:func:`find_splits`), for a folder or a zip with no frame at its top level (a single
wrapping folder is looked through, as for a plain dataset):

* every subfolder (but ``cameras/``) and every ``*.zip`` beside them is a split, named by the
  folder or by the zip without ``.zip``; a split without a frame is left out;
* two or more splits (or one zip split in a folder) make a split dataset; one subfolder alone is
  still a plain dataset, with stems as they are;
* two splits of the same name (``valid/`` and ``valid.zip``): the folder is used, the other is
  listed in :attr:`Dataset.rejected`; a split zip that cannot be opened is listed there too.

Splits are not nested: a zip inside a zip is not read (unpack it first).
"""

from __future__ import annotations

import os
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .annotations import Annotation
from .dataset import NO_FRAMES, Dataset, Frame
from .errors import DataError
from .filekind import os_error_text
from .index import CAMERAS_DIR, FolderScan, classify, frame_folder
from .layout import is_junk, join_stem, sort_stems, split_member, split_stem
from .reading import open_zip

__all__ = ["SplitDataset", "SplitPart", "find_splits", "open_dataset"]


@dataclass(frozen=True)
class SplitPart:
    """One split: ``path`` a folder or a zip; ``root`` the member prefix of its frames when the
    splits are folders inside one zip (``"sn23/valid/"``), else None."""

    name: str
    path: Path
    root: str | None = None


def _folder_splits(scan: FolderScan) -> tuple[list[SplitPart], list[DataError]] | None:
    if scan.files:
        return None
    subdirs, zips = [Path(p) for p in scan.subdirs], [Path(p) for p in scan.zips]
    if not zips and len(subdirs) < 2:
        return None
    parts: dict[str, SplitPart] = {}
    rejected = []
    for p in sorted(subdirs) + sorted(zips):
        name = p.name[:-4] if p in zips else p.name
        if name in parts:
            rejected.append(DataError(os.fspath(p), f"another split named {name!r} is used "
                                                    f"({parts[name].path.name}): this one is ignored"))
            continue
        parts[name] = SplitPart(name, p)
    return list(parts.values()), rejected


def _zip_splits(path: Path) -> list[SplitPart] | None:
    with open_zip(path, not_zip="not a folder or a valid .zip archive") as zf:
        names = [n for n in zf.namelist() if not is_junk(n)]
    prefixes = set()
    for n in names:
        prefix, base = split_member(n)
        if classify(base) is None or CAMERAS_DIR in prefix.split("/"):
            continue  # a split's own cameras/ (sn23/valid/cameras/camera_00042.json) is not a split
        if prefix == "":
            return None
        prefixes.add(prefix)
    if len(prefixes) < 2:
        return None
    depth = {p.count("/") for p in prefixes}
    parents = {p.rstrip("/").rpartition("/")[0] for p in prefixes}
    if depth not in ({1}, {2}) or len(parents) != 1:
        return None  # frames at several depths or under several wrappers: not a split layout
    return [SplitPart(p.rstrip("/").rpartition("/")[2], path, p) for p in sorted(prefixes)]


def find_splits(path: str | os.PathLike,
                listing: tuple[Path, FolderScan] | None = None) -> tuple[list[SplitPart], list[DataError]] | None:
    """The splits of a dataset folder or zip (rules in the module docstring), with the splits
    left out and why; None when it is a plain dataset. ``listing``: the folder's
    ``frame_folder(path, stop_at_zips=True)`` when the caller has it already."""
    p = Path(path)
    if p.is_dir():
        return _folder_splits((listing or frame_folder(p, stop_at_zips=True))[1])
    if not p.exists():
        return None
    parts = _zip_splits(p)
    return None if parts is None else (parts, [])


class SplitDataset(Dataset):
    """The frames of several splits as one dataset, stems ``<split>/<stem>``; each split is a
    :class:`Dataset` (``parts[split]``). Same interface as a plain dataset; ``match_info`` is
    per split (``parts[split].match_info``)."""

    def __init__(self, path: str | os.PathLike, parts: dict[str, Dataset], rejected: list[DataError],
                 cache_size: int = 64):
        self.path = Path(path)
        self.cache_size = cache_size
        self.skipped: list[tuple[str, DataError]] = []
        self.parts = parts
        self.splits = tuple(parts)
        self.is_zip = not self.path.is_dir()
        self.rejected = sorted(rejected + [e for d in parts.values() for e in d.rejected], key=str)
        self._stems = tuple(sort_stems(join_stem(s, st) for s, d in parts.items() for st in d.stems))
        self._members = set(self._stems)

    def __getstate__(self) -> dict:
        return self.__dict__.copy()

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)

    def close(self) -> None:
        for d in self.parts.values():
            d.close()

    def __contains__(self, stem: object) -> bool:
        return stem in self._members

    def __repr__(self) -> str:
        return f"SplitDataset({os.fspath(self.path)!r}, splits={list(self.splits)}, frames={len(self)})"

    def _part(self, stem: str) -> tuple[Dataset, str]:
        if stem not in self._members:
            raise KeyError(f"no frame {stem!r} in {os.fspath(self.path)}")
        split, base = split_stem(stem)
        return self.parts[split], base

    def frame(self, stem: str) -> Frame:
        d, base = self._part(stem)
        f = d.frame(base)
        return Frame(stem, f.image_path, f.annotation_path, f.archive)

    def _source(self, name: str) -> str:
        return name

    def annotation(self, stem: str, keep_unknown: bool = False) -> Annotation | None:
        d, base = self._part(stem)
        return d.annotation(base, keep_unknown)

    def _has_annotation(self, stem: str) -> bool:  # for the base class's iter_annotations
        d, base = self._part(stem)
        return d._has_annotation(base)

    def _parse_annotation(self, stem: str, keep_unknown: bool) -> Annotation | None:
        d, base = self._part(stem)
        return d._parse_annotation(base, keep_unknown)

    def image(self, stem: str) -> np.ndarray | None:
        d, base = self._part(stem)
        return d.image(base)

    def image_size(self, stem: str) -> tuple[int, int] | None:
        d, base = self._part(stem)
        return d.image_size(base)

    def camera_stems(self) -> tuple[str, ...]:
        return tuple(sort_stems(join_stem(s, st) for s, d in self.parts.items() for st in d.camera_stems()))

    def camera_source(self, stem: str) -> str:
        split, base = split_stem(stem)
        return self.parts[split].camera_source(base) if split in self.parts else stem

    def camera_dict(self, stem: str) -> dict | None:
        split, base = split_stem(stem)
        return self.parts[split].camera_dict(base) if split in self.parts else None

    @property
    def match_info(self) -> dict | None:
        return None


def _open_part(part: SplitPart, cache_size: int) -> Dataset:
    return Dataset(part.path, cache_size=cache_size, root=part.root)


def open_dataset(path: str | os.PathLike, cache_size: int = 64) -> Dataset:
    """Open a folder or ``.zip`` dataset, plain or in splits (lazy index; see :class:`Dataset` and
    this module's docstring for the split layouts)."""
    p = Path(path)
    # one listing of a folder for both: the splits, else (no zip beside a single subfolder, so the
    # same folder) the plain index
    listing = frame_folder(p, stop_at_zips=True) if p.is_dir() else None
    found = find_splits(p, listing)
    if found is None:
        return Dataset(path, cache_size=cache_size, listing=listing)
    parts, rejected = found
    opened: dict[str, Dataset] = {}
    unread: list[DataError] = []
    for part in parts:
        try:
            d = _open_part(part, cache_size)
        except (DataError, OSError, zipfile.BadZipFile) as e:
            msg = e.problem if isinstance(e, DataError) else os_error_text(e) if isinstance(e, OSError) else str(e)
            unread.append(DataError(os.fspath(part.path), f"split {part.name!r} cannot be read: {msg}"))
            continue
        if len(d):
            opened[part.name] = d
        else:
            d.close()
    if not opened:
        if unread:  # the zips or folders that looked like splits were something else: say what
            raise DataError(os.fspath(p), NO_FRAMES + "; " + "; ".join(str(e) for e in unread[:3]))
        return Dataset(path, cache_size=cache_size)
    rejected += unread
    return SplitDataset(path, {s: opened[s] for s in sorted(opened)}, rejected, cache_size)
