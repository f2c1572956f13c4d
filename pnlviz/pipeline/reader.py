"""One way to read a frame's inputs, for every caller: ``pnlviz calibrate``, the app and export.

A :class:`FrameReader` holds where a dataset's frames come from (the dataset, its detections, its
edits folder, the size of frames without an image) and reads one frame at a time into a
:class:`FrameRead`: the engine's :class:`pnlviz.calib.frame.FrameInputs` (the frame's size, its
annotation with its edit applied, its detections, its keypoint edits) and what is known beside
(the image's problem, a reference camera). Which of these observations calibrate the frame is the
source's choice (:class:`Settings`, :func:`pnlviz.calib.frame.observations_for`), never the
reader's.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from typing import Any, Protocol
from dataclasses import dataclass
from pathlib import Path

from pnlviz.calib.calibrate import CalibParams
from pnlviz.calib.frame import SOURCES, FrameInputs, FrameSettings
from pnlviz.conventions import DEFAULT_ALPHA, EVAL_SIZE
from pnlviz.data import DataError, open_dataset, predictions_info_path, read_predictions, read_predictions_info
from pnlviz.data.annotations import parse_annotation
from pnlviz.pipeline.settings import check_settings
from pnlviz.data.edits import EditsStore, default_edits_dir
from pnlviz.data.edits_folder import check_identity, frame_identity, write_dataset_file
from pnlviz.geometry.camera import Camera

__all__ = ["FrameRead", "FrameReader", "Settings"]


@dataclass(frozen=True)
class Settings:
    """How a frame is calibrated: PnL on or off, its line weight, and the keypoint source (what a
    tab of the app chooses; the detector's own settings join them in :meth:`FrameReader.frame_settings`)."""

    pnl: bool = True
    alpha: float = DEFAULT_ALPHA
    source: str = "annotation"

    def __post_init__(self):
        if self.source not in SOURCES:
            raise ValueError(f"keypoint source must be one of {SOURCES}, got {self.source!r}")
        if not (isinstance(self.alpha, (int, float)) and math.isfinite(self.alpha) and 0.0 <= self.alpha <= 1.0):
            raise ValueError(f"alpha must be a number in [0, 1], got {self.alpha!r}")
        object.__setattr__(self, "alpha", round(float(self.alpha), 4))
        object.__setattr__(self, "pnl", bool(self.pnl))


@dataclass(frozen=True)
class FrameRead:
    """One frame as read. ``inputs``: what the engine calibrates it from (None when the frame
    cannot be read: ``error`` says why); ``has_image``: it has an image that can be used;
    ``image_error``: why its image cannot be used (the frame is then read at the fallback size);
    ``reference_camera``: a known camera (e.g. synthetic ground truth), scaled to the frame."""

    stem: str
    inputs: FrameInputs | None
    has_image: bool = False
    image_error: str | None = None
    reference_camera: Camera | None = None
    error: str | None = None


class DetectionStore(Protocol):
    """Detections by stem as the reader looks them up: a dict, or the app's store on disk
    (:class:`pnlviz.app.triage.DetectionCache`)."""

    def __contains__(self, stem: object, /) -> bool: ...

    def get(self, stem: str, default: Any = None, /) -> Any: ...

    def __setitem__(self, stem: str, pred: Any, /) -> None: ...

    def __len__(self) -> int: ...


class FrameReader:
    """Where a dataset's frames come from, read one frame at a time (:meth:`read`).

    ``ds``: the dataset (or anything with its interface: a video, or no frame at all);
    ``predictions``: PnLCalib detections by stem (None: no detections); ``edits``: an edits
    folder whose annotation and keypoint corrections apply (None: none); ``size``: (W, H) of
    frames without an image; ``detection_settings``: the calibration settings the detector
    states for its detections. ``annotations`` / ``reference_cameras`` off: those files are not
    read (a batch calibrating from detections alone needs neither).
    """

    def __init__(self, ds, *, predictions: Mapping | None = None, edits: EditsStore | None = None,
                 size: tuple[int, int] = EVAL_SIZE, detection_settings: Mapping | None = None,
                 annotations: bool = True, reference_cameras: bool = True, data: Path | None = None):
        self.ds = ds
        self.data = Path(data if data is not None else getattr(ds, "path", "."))
        self.predictions = predictions
        #: detections made since the predictions were read (the app's detector), looked up after them
        self.detected: DetectionStore = {}
        self.edits = edits
        w, h = size
        self.size = (w, h)
        self.detection_settings = dict(detection_settings or {})
        self.annotations, self.reference_cameras = annotations, reference_cameras
        self.stems = list(ds.stems)
        self._index = {s: i for i, s in enumerate(self.stems)}

    @classmethod
    def open(cls, data: Path, *, detections: Path | None = None, edits: Path | None = None,
             size: tuple[int, int] = EVAL_SIZE, writable: bool = False,
             detector_settings: Mapping | None = None, force_edits: bool = False,
             settings_file: Path | None = None) -> FrameReader:
        """The frames of the dataset at ``data`` with the prediction zip ``detections`` (the
        calibration settings of the detector's settings file ``settings_file``, else of the one
        beside the zip, else ``detector_settings``) and the edits folder ``edits``
        (default: :func:`pnlviz.data.edits.default_edits_dir`), opened read-only unless
        ``writable``. The edits folder's records must be of this dataset's pictures
        (:func:`pnlviz.data.edits_folder.check_identity`: an EditsFolderError lists the mismatches)
        unless ``force_edits`` adopts it; a writable reader keeps each frame's identity in the records
        it writes. DataError for a dataset without frames or a bad file; ValueError for an
        unknown calibration setting. A video file (:func:`pnlviz.data.video.is_video`) is read as
        a dataset of its frames, decoded when asked for (one clip: ``<video>-IMG_<n>``)."""
        from pnlviz.data.video import VideoDataset, is_video

        ds = VideoDataset(data) if is_video(data) else open_dataset(data)
        if not len(ds):
            ds.require_frames()
        predictions = read_predictions(detections, splits=ds.splits) if detections else None
        recorded = read_predictions_info(detections, settings_file).get("calibration")
        source = (str(settings_file) if settings_file is not None else str(predictions_info_path(detections))
                  if recorded and detections else "detector settings")
        settings = check_settings(recorded or detector_settings or {}, source)  # fails here, not on a frame
        CalibParams().updated(settings)
        root = edits or default_edits_dir(data)
        if writable and os.path.isdir(root):  # checked read-only first: a refused folder is left as it was
            check_identity(EditsStore(root, writable=False), ds, force=force_edits)
        store = EditsStore(root, writable=writable)
        if not writable:
            check_identity(store, ds, force=force_edits)  # the folder's records are of these pictures
        else:
            check_identity(store, ds, force=True)  # the warnings of an adopted folder, on the store kept
        if writable:
            write_dataset_file(store.root, ds)
            store.identity = lambda stem: frame_identity(ds, stem)
        return cls(ds, predictions=predictions, edits=store, size=size, detection_settings=settings, data=data)

    @property
    def edits_folder(self) -> EditsStore:
        """The edits folder, for what needs one (a reader from :meth:`open` always has one)."""
        assert self.edits is not None, "this reader has no edits folder"
        return self.edits

    def close(self) -> None:
        """Release the edits folder and the dataset's files."""
        if self.edits is not None:
            self.edits.close()
        close = getattr(self.ds, "close", None)
        if close is not None:
            close()

    def __enter__(self) -> FrameReader:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # ------------------------------------------------------------------ one frame
    def index_of(self, stem: str) -> int:
        """The frame's place in the dataset (KeyError for a stem it does not have)."""
        return self._index[stem]

    def default_settings(self) -> Settings:
        """The settings frames are calibrated with unless told: the annotation, with the
        detections too once there are some."""
        return Settings(source="annotation" if self.predictions is None else "both")

    def frame_settings(self, settings: Settings) -> FrameSettings:
        """``settings`` with the detector's own, as the engine takes them."""
        return FrameSettings(pnl=settings.pnl, alpha=settings.alpha, source=settings.source,
                             detection_settings=self.detection_settings)

    def image_size(self, stem: str) -> tuple[tuple[int, int] | None, str | None]:
        """(W, H) of the frame's image from its header (None without one) and why it cannot be
        used (None when it can)."""
        if stem not in self.ds:
            return None, None
        try:
            return (self.ds.image_size(stem) if self.ds.frame(stem).has_image else None), None
        except DataError as exc:
            return None, str(exc)

    def frame_size(self, stem: str) -> tuple[int, int]:
        """(W, H) of the frame's image, else (no image, or one that cannot be read) :attr:`size`."""
        return self.image_size(stem)[0] or self.size

    def detections(self, stem: str):
        """The frame's detections: from the predictions, else from :attr:`detected`; None without
        predictions."""
        if self.predictions is None:
            return None
        return self.predictions.get(stem) or self.detected.get(stem)

    def annotation(self, stem: str, record: Mapping | None = None) -> dict | None:
        """The frame's annotation: its edit if it has one (in ``record``, default: the edits
        folder's), else the dataset's. DataError when it cannot be read."""
        if record is None:
            record = self.edits.get(stem) if self.edits is not None else {}
        edit = record.get("annotation")
        if edit is not None:
            assert self.edits is not None  # an edited annotation comes from the edits folder
            return parse_annotation(edit, f"{self.edits.frames / stem}.json")
        return self.ds.annotation(stem) if stem in self.ds else None

    def read(self, stem: str, keypoint_edits: Mapping | None = None) -> FrameRead:
        """The frame's inputs, with its keypoint edits (``keypoint_edits``: these instead of the
        edits folder's). Never raises on bad data: an unreadable frame comes back with ``error``."""
        record = self.edits.get(stem) if self.edits is not None else {}
        size, image_error = self.image_size(stem)
        has_image = stem in self.ds and self.ds.frame(stem).has_image and image_error is None
        size = size or self.size
        try:
            ann = self.annotation(stem, record) if self.annotations else None
            ref = None
            if self.reference_cameras and stem in self.ds:
                ref = self.ds.camera_dict(stem)
                ref = Camera.from_soccernet(ref).scaled(*size) if ref is not None else None
        except DataError as exc:
            return FrameRead(stem, None, error=str(exc))
        if keypoint_edits is None:
            keypoint_edits = record.get("keypoints")
        return FrameRead(stem, FrameInputs(size, ann, self.detections(stem), keypoint_edits), has_image,
                         image_error, ref)
