"""A video file as a dataset of frames: ``pnlviz detect --video`` and ``pnlviz calibrate --video``.

Frames are decoded by OpenCV when asked for, one at a time (a video of any length opens without
decoding it); reading them in order decodes each frame once, a jump seeks. Frame ``i`` (0-based)
is named ``<video stem>-IMG_<i + 1:05d>``, which :func:`pnlviz.data.layout.clip_key` reads back
as clip ``<video stem>``, frame ``i + 1``: detections of a video calibrate as one clip.
"""

from __future__ import annotations

import os
import threading
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .dataset import Frame
from . import limits
from .errors import DataError
from .imagesize import check_pixels

if TYPE_CHECKING:  # imported when a frame is read
    import cv2

__all__ = ["VIDEO_SUFFIXES", "VideoDataset", "is_video"]

#: file name endings opened as videos (``pnlviz serve --video``, :func:`is_video`)
VIDEO_SUFFIXES = (".mp4", ".m4v", ".mov", ".avi", ".mkv", ".webm", ".mpg", ".mpeg", ".ts")


def is_video(path: str | os.PathLike) -> bool:
    """A file (not a folder or a zip of frames) whose name ends as a video's."""
    p = Path(path)
    return p.suffix.lower() in VIDEO_SUFFIXES and not p.is_dir()


#: First bytes of still images: a JPEG or PNG named .mp4 is not a clip.
_STILL_IMAGES = {b"\xff\xd8\xff": "a JPEG image", b"\x89PNG": "a PNG image", b"GIF8": "a GIF image",
                 b"BM": "a BMP image"}


def _check_container(path: Path) -> None:
    """A regular file (a FIFO or device is never opened) that is not a still image."""
    from .filekind import open_regular

    with os.fdopen(open_regular(path), "rb") as f:
        head = f.read(16)
    for magic, what in _STILL_IMAGES.items():
        if head.startswith(magic):
            raise DataError(str(path), f"is {what}, not a video")
    if not head:
        raise DataError(str(path), "the video file is empty")


def _backend(cap) -> str:
    try:
        return str(cap.getBackendName()).upper()
    except Exception:  # an OpenCV without getBackendName
        return ""


def _check_decodes(cap, count: int, source: str) -> None:
    """The first and the last frame decode (a damaged or truncated video is refused at once, not
    "calibrated" from its header); releases ``cap``."""
    import cv2

    try:
        ok, img = cap.read()
        if not ok or img is None:
            raise DataError(source, "the video's first frame cannot be decoded (damaged video or unsupported codec)")
        if count > 1:
            cap.set(cv2.CAP_PROP_POS_FRAMES, count - 1)
            ok, img = cap.read()
            if not ok or img is None:
                raise DataError(source, f"the video's last frame ({count}) cannot be decoded (truncated or damaged "
                                        f"video)")
    finally:
        cap.release()

class VideoDataset:
    """The frames of one video file, with the part of :class:`pnlviz.data.Dataset`'s interface the
    batch commands use (stems, frames, images, sizes; no annotations)."""

    splits: tuple[str, ...] = ()  # one video is one split

    def __init__(self, path: str | os.PathLike):
        import cv2

        self.path = Path(path)
        if not self.path.exists():
            raise DataError(str(path), "no such video file")
        _check_container(self.path)
        cap = cv2.VideoCapture(str(self.path))
        if not cap.isOpened() or "IMAGES" in _backend(cap):
            raise DataError(str(path), "OpenCV cannot open this video (unknown format or codec)")
        self.width = int(cap.get(cv2.CAP_PROP_FRAME_WIDTH))
        self.height = int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT))
        self.fps = float(cap.get(cv2.CAP_PROP_FPS) or 0.0)
        count = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
        if count <= 0:  # some containers do not say: count by grabbing (no decoding)
            count = 0
            while cap.grab():
                count += 1
        if count <= 0 or self.width <= 0 or self.height <= 0:
            cap.release()
            raise DataError(str(path), "the video has no frames")
        try:  # a frame is an image: the same cap on its pixels (a 9000x9000 video was served at 1.45 GB)
            check_pixels(self.width, self.height, str(path), limits.MAX_IMAGE_PIXELS)
        except DataError:
            cap.release()
            raise
        _check_decodes(cap, count, str(path))
        self.name = self.path.stem
        self._stems = tuple(f"{self.name}-IMG_{i + 1:05d}" for i in range(count))
        self._index = {s: i for i, s in enumerate(self._stems)}
        self._cap: cv2.VideoCapture | None = None
        self._next = 0
        self._lock = threading.Lock()  # one capture: a seek and its read are one step for a thread
        self.rejected: list = []

    # -- the Dataset surface -------------------------------------------------------------------
    @property
    def stems(self) -> tuple[str, ...]:
        return self._stems

    def __len__(self) -> int:
        return len(self._stems)

    def __iter__(self):
        return iter(self._stems)

    def __contains__(self, stem: object) -> bool:
        return stem in self._index

    def __repr__(self) -> str:
        return f"VideoDataset({str(self.path)!r}, {len(self)} frames, {self.width}x{self.height})"

    def require_frames(self) -> None:
        return None

    def frame(self, stem: str) -> Frame:
        return Frame(stem, f"{self.path}#{self._index[stem]}", None)

    def annotation(self, stem: str, keep_unknown: bool = False):
        return None

    def camera_dict(self, stem: str) -> dict | None:
        return None  # a video has no known cameras

    def image_size(self, stem: str) -> tuple[int, int] | None:
        return (self.width, self.height) if stem in self._index else None

    def image(self, stem: str) -> np.ndarray:
        """Frame ``stem`` as BGR uint8 (DataError when the video ends early or cannot be decoded)."""
        import cv2

        i = self._index[stem]
        with self._lock:
            if self._cap is None:
                self._cap = cv2.VideoCapture(str(self.path))
                self._next = 0
            if i != self._next:
                self._cap.set(cv2.CAP_PROP_POS_FRAMES, i)
                self._next = i
            ok, img = self._cap.read()
            self._next = i + 1 if ok else -1
        if not ok or img is None:
            raise DataError(f"{self.path} frame {i + 1}", "cannot be decoded (the video ends early or is damaged)")
        return img

    def close(self) -> None:
        with self._lock:
            if self._cap is not None:
                self._cap.release()
                self._cap = None

    def __getstate__(self) -> dict:  # process pools: re-open the capture in the worker
        state = dict(self.__dict__)
        state["_cap"] = None
        state["_next"] = 0
        del state["_lock"]
        return state

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._lock = threading.Lock()
