"""A SoccerNet-style dataset: a folder or a .zip of ``<stem>.jpg|png`` + ``<stem>.json``.

Layout (folder or zip, or a zip holding one folder with it)::

    00001.jpg  00001.json  00002.jpg  ...   frames: image and/or annotation (either may be missing)
    match_info.json                         optional, not a frame
    cameras/camera_00001.json ...           optional ground-truth cameras (``pnlviz synth``)

Opening only lists names (``os.scandir`` / the zip's central directory); annotations, images and
cameras are read when asked for, so a 23k-frame folder opens in a blink. Annotations are cached
in a small LRU. A :class:`Dataset` pickles (a zip is reopened in the worker process).

Files that are not used are listed in :attr:`Dataset.rejected`, one :class:`DataError` each:

* a name that is not valid UTF-8 (it never becomes a stem);
* a second file for the same frame. The rule: for the annotation, the ``.json`` name in lower
  case wins (``00001.json`` over ``00001.JSON``), else the first name in sorted order; for the
  image, the extension earliest in :data:`IMAGE_EXTENSIONS` wins (``.jpg`` over ``.png``), then
  a lower-case extension, then the first name in sorted order;
* a member name that appears twice in a zip (the last copy is the one a zip reader sees).

Sizes are capped before reading (:mod:`pnlviz.data.limits`): a file over its byte limit, or an
image over the pixel limit (read from its header, :mod:`pnlviz.data.imagesize`), is a DataError.
"""

from __future__ import annotations

import copy
import io
import os
import threading
import zipfile
from collections import OrderedDict
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .annotations import Annotation, parse_annotation_bytes
from .cameras import camera_member_name, camera_stem, parse_camera_bytes
from .errors import DataError, member_source
from .imagesize import header_size
from .jsonio import describe, parse_json_bytes
from .index import CAMERAS_DIR, IMAGE_EXTENSIONS, MATCH_INFO, FolderScan, index_folder, index_zip
from .layout import sort_stems
from .reading import bad_name_error, is_utf8, limit_for, open_file, open_zip, read_file, read_zip_member, zip_member

__all__ = ["Frame", "Dataset", "IMAGE_EXTENSIONS"]

#: The message of a folder or zip of cameras opened as a dataset.
CAMERAS_NOT_FRAMES = (
    "holds cameras (camera_<stem>.json, as `pnlviz calibrate` writes them), not frames: give --data the dataset's "
    "folder or zip; cameras are read by `pnlviz evaluate --pred`, `render --cameras` and `sheet --cameras`")

#: The message of a dataset without a single frame.
NO_FRAMES = (
    "no frames (expected <stem>.jpg/.png/.json at the top level, inside one folder, or in split folders or zips)")


@dataclass(frozen=True)
class Frame:
    """Where the files of one frame are.

    ``image_path`` / ``annotation_path`` are file paths for a folder dataset, member names for a
    zip dataset (then ``archive`` is the zip's path), or None when the frame lacks that file.
    """

    stem: str
    image_path: str | None
    annotation_path: str | None
    archive: str | None = None

    @property
    def has_image(self) -> bool:
        return self.image_path is not None

    @property
    def has_annotation(self) -> bool:
        return self.annotation_path is not None

    def source(self, name: str) -> str:
        """The ``<file>`` part of an error message for ``name`` (a path or a zip member)."""
        return member_source(self.archive, name) if self.archive else name


class Dataset:
    """Lazily indexed frames of a folder or zip; see the module docstring.

    Use :func:`pnlviz.data.open_dataset` to create one (``root``: for a zip, the member prefix
    of its frames, found when None; ``listing``: a folder's listing the caller has already made). ``len(ds)``, ``ds.stems`` (natural order),
    ``ds.frame(stem)``, ``ds.annotation(stem)``, ``ds.image(stem)``, ``ds.image_size(stem)``,
    ``ds.camera_dict(stem)``, ``ds.camera_stems()``, ``ds.match_info``,
    ``ds.iter_annotations(on_error=...)``, ``ds.rejected`` (files not used, one DataError each),
    ``ds.require_frames()``. Unknown stems raise KeyError; problems with file contents raise
    :class:`DataError`.
    """

    #: The splits of a dataset in split folders or zips (:class:`pnlviz.data.splits.SplitDataset`);
    #: ``()`` for a plain one.
    splits: tuple[str, ...] = ()

    def __init__(self, path: str | os.PathLike, cache_size: int = 64, root: str | None = None,
                 listing: tuple[Path, FolderScan] | None = None):
        self.path = Path(path)
        self.cache_size = cache_size
        #: ``(stem, DataError)`` of the frames the last :meth:`iter_annotations` skipped.
        self.skipped: list[tuple[str, DataError]] = []
        #: Files that are not used (bad names, duplicates; see the module docstring), one line each.
        self.rejected: list[DataError]
        self._lock = threading.RLock()
        self._zf: zipfile.ZipFile | None = None
        self._cache: OrderedDict[tuple[str, bool], Annotation] = OrderedDict()
        self._sizes: dict[str, tuple[int, int]] = {}
        self._match_info: Any = ...
        self._camera_stems: tuple[str, ...] | None = None
        if not self.path.exists():
            raise DataError(os.fspath(self.path), "no such file or folder")
        self.is_zip = not self.path.is_dir()
        if self.is_zip:
            self._zf = open_zip(self.path, not_zip="not a folder or a valid .zip archive")
            self._index = index_zip(self.path, self._zf, root)
        else:
            self._index = index_folder(self.path, listing)
        self.rejected = self._index.rejected
        self._images, self._annotations = self._index.images, self._index.annotations
        self._stems = tuple(sort_stems(set(self._images) | set(self._annotations)))
        bases = (name.replace("\\", "/").rsplit("/", 1)[-1] for name in self._annotations.values())
        if self._annotations and not self._images and all(camera_stem(b) is not None for b in bases):
            raise DataError(os.fspath(self.path), CAMERAS_NOT_FRAMES)  # calibrate's output, not a dataset

    # ------------------------------------------------------------- pickling
    def __getstate__(self) -> dict:
        state = self.__dict__.copy()
        state["_zf"] = None
        state["_lock"] = None
        state["_cache"] = OrderedDict()
        return state

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._lock = threading.RLock()

    def close(self) -> None:
        """Close the zip archive (reopened if the dataset is used again)."""
        with self._lock:
            if self._zf is not None:
                self._zf.close()
                self._zf = None

    def __enter__(self) -> Dataset:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # ----------------------------------------------------------- basic access
    def __len__(self) -> int:
        return len(self._stems)

    def __iter__(self) -> Iterator[str]:
        return iter(self._stems)

    def __contains__(self, stem: object) -> bool:
        return stem in self._images or stem in self._annotations

    def __repr__(self) -> str:
        return f"Dataset({os.fspath(self.path)!r}, frames={len(self)})"

    @property
    def stems(self) -> tuple[str, ...]:
        """Frame stems in natural order (numeric when all digits)."""
        return self._stems

    def frame(self, stem: str) -> Frame:
        """The :class:`Frame` of ``stem`` (KeyError if the dataset has no such frame)."""
        if stem not in self:
            raise KeyError(f"no frame {stem!r} in {os.fspath(self.path)}")
        return Frame(
            stem=stem,
            image_path=self._images.get(stem),
            annotation_path=self._annotations.get(stem),
            archive=os.fspath(self.path) if self.is_zip else None,
        )

    def _source(self, name: str) -> str:
        return self._index.source(name)

    def require_frames(self) -> None:
        """DataError when the dataset has no frame at all (batch commands have nothing to do)."""
        if not self._stems:
            raise DataError(os.fspath(self.path), NO_FRAMES)

    def _zip(self) -> zipfile.ZipFile:
        if self._zf is None:
            self._zf = open_zip(self.path)
        return self._zf

    def _read(self, name: str) -> bytes:
        """Bytes of a file (folder) or member (zip), capped by :func:`~pnlviz.data.reading.limit_for`;
        DataError when unreadable or too large."""
        if not self.is_zip:
            return read_file(name, limit_for(name))
        with self._lock:
            return read_zip_member(self._zip(), name, self._source(name), limit_for(name))

    # ------------------------------------------------------------ annotations
    def _has_annotation(self, stem: str) -> bool:
        return stem in self._annotations

    def _parse_annotation(self, stem: str, keep_unknown: bool) -> Annotation | None:
        name = self.frame(stem).annotation_path
        if name is None:
            return None
        return parse_annotation_bytes(self._read(name), self._source(name), keep_unknown=keep_unknown)

    def annotation(self, stem: str, keep_unknown: bool = False) -> Annotation | None:
        """The validated annotation of ``stem`` (``{class: (N, 2) normalised}``), None if it has none.

        Results are cached (small LRU); the caller gets its own copy and may modify it.
        """
        key = (stem, keep_unknown)
        with self._lock:
            hit = self._cache.get(key)
            if hit is not None:
                self._cache.move_to_end(key)
                return {k: v.copy() for k, v in hit.items()}
        ann = self._parse_annotation(stem, keep_unknown)
        if ann is None:
            return None
        with self._lock:
            self._cache[key] = ann
            while len(self._cache) > max(self.cache_size, 0):
                self._cache.popitem(last=False)
        return {k: v.copy() for k, v in ann.items()}

    def iter_annotations(
        self,
        on_error: Callable[[str, DataError], Any] | None = None,
        keep_unknown: bool = False,
    ) -> Iterator[tuple[str, Annotation]]:
        """Yield ``(stem, annotation)`` for every annotated frame, going on past bad ones.

        A frame whose annotation raises :class:`DataError` is skipped: ``on_error(stem, err)``
        is called if given, and ``(stem, err)`` is appended to ``self.skipped`` (cleared when
        the iteration starts). Bypasses the LRU cache.
        """
        self.skipped = []
        for stem in self._stems:
            if not self._has_annotation(stem):
                continue
            try:
                ann = self._parse_annotation(stem, keep_unknown)
            except DataError as err:
                self.skipped.append((stem, err))
                if on_error is not None:
                    on_error(stem, err)
                continue
            assert ann is not None  # the frame has an annotation file
            yield stem, ann

    # ------------------------------------------------------------------ images
    def image(self, stem: str) -> np.ndarray | None:
        """The image of ``stem`` as BGR uint8 ``(H, W, 3)``, pixels as stored (EXIF orientation
        ignored); None if the frame has no image. Corrupt data, or an image over the size caps,
        raises DataError (checked from the header, before decoding)."""
        name = self.frame(stem).image_path
        if name is None:
            return None
        img = decode_image(self._read(name), self._source(name))
        with self._lock:
            self._sizes[stem] = (img.shape[1], img.shape[0])
        return img

    def image_size(self, stem: str) -> tuple[int, int] | None:
        """``(width, height)`` of the image of ``stem``, from its header (never decoded); None if
        the frame has no image. A corrupt header or an image over the size caps raises DataError."""
        with self._lock:
            if stem in self._sizes:
                return self._sizes[stem]
        name = self.frame(stem).image_path
        if name is None:
            return None
        size = self._header_size(name)
        with self._lock:
            self._sizes[stem] = size
        return size

    def _header_size(self, name: str) -> tuple[int, int]:
        source = self._source(name)
        if not self.is_zip:
            with open_file(name, limit_for(name)) as f:
                return header_size(f.read, source)
        with self._lock, zip_member(self._zip(), name, source, limit_for(name)) as f:
            return header_size(f.read, source)

    # ------------------------------------------------------- cameras, match info
    def camera_stems(self) -> tuple[str, ...]:
        """Stems of the cameras in ``cameras/`` (``camera_<stem>.json``), natural order, whether or
        not the dataset has that frame. A name that is not valid UTF-8 goes to :attr:`rejected`."""
        if self._camera_stems is None:
            if self.is_zip:
                names = self._index.camera_members or set()  # a zip's index has them
            else:
                folder = self._index.path(CAMERAS_DIR)
                names = set(os.listdir(folder)) if os.path.isdir(folder) else set()
            stems = set()
            for base in names:
                stem = camera_stem(base)
                if stem is None:
                    continue
                if is_utf8(stem):
                    stems.add(stem)
                else:
                    self.rejected.append(bad_name_error(self._source(self._camera_path(base))))
            self._camera_stems = tuple(sort_stems(stems))
        return self._camera_stems

    def _camera_path(self, base: str) -> str:
        return self._index.path(CAMERAS_DIR, base)

    def camera_source(self, stem: str) -> str:
        """The ``<file>`` part of a message about the camera of ``stem``."""
        return self._source(self._camera_path(camera_member_name(stem)))

    def camera_dict(self, stem: str) -> dict | None:
        """The ground-truth camera ``cameras/camera_<stem>.json`` (raw dict, validated), or None."""
        base = camera_member_name(stem)
        name = self._camera_path(base)
        present = base in (self._index.camera_members or ()) if self.is_zip else os.path.isfile(name)
        if not present:
            return None
        return parse_camera_bytes(self._read(name), self._source(name))

    @property
    def match_info(self) -> dict | None:
        """The content of ``match_info.json`` (a dict), or None when the dataset has none."""
        if self._match_info is ...:
            name = self._index.path(MATCH_INFO)
            present = name in (self._index.members or ()) if self.is_zip else os.path.isfile(name)
            info = None
            if present:
                source = self._source(name)
                info = parse_json_bytes(self._read(name), source)
                if not isinstance(info, dict):
                    raise DataError(source, f"match info must be a JSON object, got {describe(info)}")
            self._match_info = info
        return copy.deepcopy(self._match_info)


def decode_image(data: bytes, source: str) -> np.ndarray:
    """Decode image file bytes to BGR uint8 with OpenCV; DataError when corrupt, not PNG/JPEG, or
    over the pixel cap (read from the header first)."""
    import cv2

    header_size(io.BytesIO(data).read, source)
    try:
        img = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_COLOR | cv2.IMREAD_IGNORE_ORIENTATION)
    except cv2.error as e:
        raise DataError(source, f"corrupt image: OpenCV cannot decode it ({str(e).strip()})") from None
    if img is None or img.size == 0:
        raise DataError(source, "corrupt image: OpenCV cannot decode it (corrupt or unsupported format)")
    return img
