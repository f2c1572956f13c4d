"""A frame's computed view: its inputs read (:class:`pnlviz.pipeline.reader.FrameReader`), the
engine's one path per frame (:func:`pnlviz.calib.frame.calibrate_frame`), and the camera's score
against the frame's annotation (JaC@5/10/20). What the app shows of a frame and what export writes.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import cast

import numpy as np

from pnlviz.calib.calibrate import CalibrationResult
from pnlviz.calib.frame import calibrate_frame
from pnlviz.calib.observations import Observations
from pnlviz.conventions import EVAL_SIZE
from pnlviz.data.predictions import Predictions
from pnlviz.field.model import FieldModel
from pnlviz.geometry.camera import Camera
from pnlviz.pipeline.reader import FrameReader, Settings

__all__ = ["FrameView", "frame_view"]


@dataclass
class FrameView:
    """Everything the app shows for one frame under one setting."""

    stem: str
    index: int
    has_image: bool  # the pixels are not kept here (23k cached views must fit in memory): AppState.image()
    size: tuple[int, int]  # (W, H) of the image or of the --size fallback
    annotation: Mapping[str, np.ndarray] | None
    observations: Observations | None
    result: CalibrationResult | None
    #: JaC@5/10/20 against the annotation once measured (:attr:`jac`); None: not yet
    measured_jac: dict[int, float] | None = None
    error: str | None = None  # a problem reading the frame
    ms: float = 0.0
    reference_camera: Camera | None = None  # a known camera (e.g. synthetic ground truth), scaled to the frame
    detections: Predictions | None = None  # the frame's PnLCalib detections, if any
    origin: str | None = None  # where the observations came from: annotation, detections, both or edits
    settings: Settings = Settings()
    #: a clip frame: which camera it shows (its shot's or its own) and why, one line
    shot_note: str | None = None

    @property
    def camera(self) -> Camera | None:
        """The camera to show the frame with: the calibration's, else the known one."""
        if self.result is not None and self.result.ok:
            return self.result.camera
        return self.reference_camera

    @property
    def jac(self) -> dict[int, float]:
        """JaC@5/10/20 of the calibration's camera against the frame's annotation ({} without
        either), measured when first asked: a preview drawn while a point is dragged never asks
        (it was a tenth of the preview's time), the view kept when that point is let go does."""
        if self.measured_jac is None:
            from pnlviz.metrics.soccernet import evaluate_frame

            camera = self.result.camera if self.result is not None else None
            jac: dict[int, float] = {}
            if camera is not None and self.annotation:
                fr = evaluate_frame(camera.scaled(*EVAL_SIZE), self.annotation)
                jac = {t: fr.accuracy(t) for t in (5, 10, 20)}
            self.measured_jac = jac
        return self.measured_jac


def frame_view(reader: FrameReader, stem: str, settings: Settings, model: FieldModel | None = None,
               keypoint_edits: Mapping | None = None) -> FrameView:
    """The frame ``stem`` (one the reader's dataset has) read and calibrated under ``settings``
    (scored when its :attr:`FrameView.jac` is first asked); with ``keypoint_edits``, as it would
    be with these instead of its saved ones. Never raises on bad data."""
    idx = reader.index_of(stem)
    read = reader.read(stem, keypoint_edits)
    if read.inputs is None:
        return FrameView(stem, idx, False, reader.size, None, None, None, error=read.error, settings=settings)
    fc = calibrate_frame(read.inputs, reader.frame_settings(settings), model)
    # nothing to calibrate from is not an error of the frame: the card asks for keypoints
    engine_error = fc.failure.message if fc.failure is not None and fc.failure.code == "internal" else None
    return FrameView(stem, idx, read.has_image, read.inputs.size, read.inputs.annotation, fc.observations, fc.result,
                     error=read.image_error or engine_error, ms=fc.ms, reference_camera=read.reference_camera,
                     # the engine's inputs hold them untyped (calib does not import data)
                     detections=cast("Predictions | None", read.inputs.detections), origin=fc.origin, settings=settings)
