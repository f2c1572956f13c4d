"""A video file as a dataset of frames: ``pnlviz detect --video`` and ``pnlviz calibrate --video``.

Frames are decoded by OpenCV when asked for, one at a time (a video of any length opens without
decoding it); reading them in order decodes each frame once, a jump seeks. Frame ``i`` (0-based)
is named ``<video stem>-IMG_<i + 1:05d>``, which :func:`pnlviz.data.layout.clip_key` reads back
as clip ``<video stem>``, frame ``i + 1``: detections of a video calibrate as one clip.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from .dataset import Frame
from .errors import DataError

__all__ = ["VideoDataset"]

class VideoDataset:
    """The frames of one video file, with the part of :class:`pnlviz.data.Dataset`'s interface the
    batch commands use (stems, frames, images, sizes; no annotations)."""

    def __init__(self, path: str | os.PathLike):
        import cv2

        self.path = Path(path)
        if not self.path.is_file():
            raise DataError(str(path), "no such video file")
        cap = cv2.VideoCapture(str(self.path))
        if not cap.isOpened():
            raise DataError(str(path), "OpenCV cannot open this video (unknown format or codec)")
        self.width = int(cap.get(cv2.CAP_PROP_FRAME_WIDTH))
        self.height = int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT))
        self.fps = float(cap.get(cv2.CAP_PROP_FPS) or 0.0)
        count = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
        if count <= 0:  # some containers do not say: count by grabbing (no decoding)
            count = 0
            while cap.grab():
                count += 1
        cap.release()
        if count <= 0 or self.width <= 0 or self.height <= 0:
            raise DataError(str(path), "the video has no frames")
        self.name = self.path.stem
        self._stems = tuple(f"{self.name}-IMG_{i + 1:05d}" for i in range(count))
        self._index = {s: i for i, s in enumerate(self._stems)}
        self._cap = None
        self._next = 0
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

    def image_size(self, stem: str) -> tuple[int, int] | None:
        return (self.width, self.height) if stem in self._index else None

    def image(self, stem: str) -> np.ndarray:
        """Frame ``stem`` as BGR uint8 (DataError when the video ends early or cannot be decoded)."""
        import cv2

        i = self._index[stem]
        if self._cap is None:
            self._cap = cv2.VideoCapture(str(self.path))
            self._next = 0
        if i != self._next:
            self._cap.set(cv2.CAP_PROP_POS_FRAMES, i)
            self._next = i
        ok, img = self._cap.read()
        if not ok or img is None:
            raise DataError(f"{self.path} frame {i + 1}", "cannot be decoded (the video ends early or is damaged)")
        self._next = i + 1
        return img

    def close(self) -> None:
        if self._cap is not None:
            self._cap.release()
            self._cap = None

    def __getstate__(self) -> dict:  # process pools: re-open the capture in the worker
        state = dict(self.__dict__)
        state["_cap"] = None
        state["_next"] = 0
        return state
