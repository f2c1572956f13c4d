"""One frame's path through the engine: its inputs (annotation, detections, keypoint edits, image
size, settings) -> observations -> calibration -> evidence, in :func:`calibrate_frame`.

Every caller goes through here: ``pnlviz calibrate``, the app and its export, the benchmarks.
Nothing here reads files: the caller hands over what it read (and says what it could not read
in its own words). Pure, and safe to call from several threads.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass, field, replace

import numpy as np

from pnlviz.calib.calibrate import CalibParams, CalibrationResult, calibrate
from pnlviz.calib.inputs import Detections, annotation_observations, observations_from_predictions
from pnlviz.calib.observations import Observations
from pnlviz.calib.sources import KeypointEdit, apply_keypoint_edits, merge_observations
from pnlviz.conventions import DEFAULT_ALPHA
from pnlviz.conventions import SOURCES as _SOURCES
from pnlviz.field.model import FieldModel, load_field_model
from pnlviz.geometry.camera import Camera

#: which observations a frame is calibrated from: "both" merges annotation and detections
SOURCES = _SOURCES


@dataclass(frozen=True)
class FrameInputs:
    """What is known of one frame. ``size``: (W, H) pixels of the frame (its image, else the
    size it is calibrated at); ``annotation``: SoccerNet line annotation (normalised);
    ``detections``: PnLCalib-format detections (:class:`pnlviz.data.Predictions`);
    ``keypoint_edits``: ``{"id": [x, y] | None}`` in pixels (None: not visible)."""

    size: tuple[int, int]
    annotation: Mapping[str, np.ndarray] | None = None
    detections: Detections | None = None
    keypoint_edits: Mapping[str, KeypointEdit] | None = None

    def __post_init__(self):
        W, H = self.size
        if not (int(W) == W and int(H) == H and W >= 2 and H >= 2):
            raise ValueError(f"a frame size is two whole numbers >= 2 (W, H), got {self.size!r}")


@dataclass(frozen=True)
class FrameSettings:
    """How a frame is calibrated. ``source``: one of :data:`SOURCES` (a frame without an
    annotation uses its detections whatever the source); ``detection_settings``: the
    :class:`CalibParams` fields a detector states for its detections (applied to frames
    calibrated from detections alone, e.g. the light model's "no k1"); ``overrides``: fields set
    by the user, applied last."""

    pnl: bool = True
    alpha: float = DEFAULT_ALPHA
    source: str = "annotation"
    detection_settings: Mapping[str, object] = field(default_factory=dict)
    overrides: Mapping[str, object] = field(default_factory=dict)

    def __post_init__(self):
        if self.source not in SOURCES:
            raise ValueError(f"keypoint source must be one of {SOURCES}, got {self.source!r}")


@dataclass(frozen=True)
class Failure:
    """Why a frame has no camera: a stable ``code`` (for counting and filtering) and a message."""

    code: str
    message: str


@dataclass
class FrameCalibration:
    """A frame's calibration and the evidence for it. ``origin``: where the observations came
    from ("annotation", "detections", "both", "edits" when only edited keypoints exist, or None)."""

    observations: Observations | None
    origin: str | None
    params: CalibParams | None
    result: CalibrationResult | None
    failure: Failure | None = None
    ms: float = 0.0

    @property
    def ok(self) -> bool:
        return self.result is not None and self.result.ok

    @property
    def camera(self) -> Camera | None:
        """The frame's camera, None without one."""
        return self.result.camera if self.result is not None else None


def observations_for(inputs: FrameInputs, source: str, model: FieldModel) -> tuple[Observations | None, str | None]:
    """The observations of a frame and where they came from (see :class:`FrameCalibration`)."""
    W, H = inputs.size
    ann = inputs.annotation if source in ("annotation", "both") else None  # the ones used
    det = inputs.detections if source in ("detections", "both") or ann is None else None
    obs: Observations | None = None
    origin: str | None = None
    if ann is not None and det is not None:
        obs, origin = merge_observations(annotation_observations(ann, W, H, model),
                                         observations_from_predictions(det, W, H, model=model), model), "both"
    elif ann is not None:
        obs, origin = annotation_observations(ann, W, H, model), "annotation"
    elif det is not None:
        obs, origin = observations_from_predictions(det, W, H, model=model), "detections"
    if inputs.keypoint_edits:
        if obs is None:
            obs, origin = Observations(W, H), "edits"
        obs = apply_keypoint_edits(obs, inputs.keypoint_edits, model)
    return obs, origin


def detection_settings_apply(origin: str | None, settings: FrameSettings) -> Mapping[str, object]:
    """The detector's settings when they apply: observations from detections alone, PnL on
    (without PnL there is nothing they change)."""
    return settings.detection_settings if origin == "detections" and settings.pnl else {}


def calib_params(settings: FrameSettings, origin: str | None) -> CalibParams:
    """The calibration parameters for observations from ``origin``: the defaults, the detector's
    settings where they apply, the user's overrides; without PnL no refinement at all."""
    params = CalibParams(alpha=settings.alpha).updated(detection_settings_apply(origin, settings))
    params = params.updated(settings.overrides)
    if not settings.pnl:
        params = replace(params, pnl=False, refine_focal=False, refine_k1=False)
    return params


def calibrate_frame(inputs: FrameInputs, settings: FrameSettings = FrameSettings(),
                    model: FieldModel | None = None) -> FrameCalibration:
    """Calibrate one frame. Never raises on bad geometry or a failing solver: a frame without a
    camera comes back with a :class:`Failure`."""
    model = model or load_field_model()
    t0 = time.perf_counter()
    obs, origin = observations_for(inputs, settings.source, model)
    if obs is None:
        return FrameCalibration(None, None, None, None, Failure("no_input", "nothing to calibrate from"))
    params = calib_params(settings, origin)
    try:
        result = calibrate(obs, params, model)
    except Exception as exc:  # noqa: BLE001 - a bug must not end a batch: the frame says what happened
        return FrameCalibration(obs, origin, params, None, Failure("internal", f"internal error: {type(exc).__name__}: {exc}"),
                                1e3 * (time.perf_counter() - t0))
    failure = None if result.ok else Failure(result.failure_code or "failed", result.failure or "not calibrated")
    return FrameCalibration(obs, origin, params, result, failure, 1e3 * (time.perf_counter() - t0))
