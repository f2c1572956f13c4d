"""Temporal calibration of broadcast clips: shots, and one broadcast camera per shot.

Per-frame calibration ignores that a broadcast camera stands on a tripod head (within a shot its
centre and lens do not move, and pan, tilt, roll and zoom change smoothly), so its cameras jitter
with the detection noise and fail on frames with too few keypoints. A clip, in time order, is cut
into shots (:func:`pnlviz.calib.cuts.segment_shots`: large image changes, or per-frame cameras
that jump to another position), and each shot that has at least one per-frame camera gets one
broadcast camera (:func:`pnlviz.calib.shot_fit.fit_shot`, the model in :mod:`pnlviz.calib.shot`),
which gives every frame a camera. This module is the clip's driver, and measures the image
changes that mark cuts.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from pnlviz.field.model import FieldModel, load_field_model
from pnlviz.geometry.camera import Camera

from .cuts import segment_shots
from .observations import Observations
from .shot import TemporalParams
from .shot_fit import ShotFit, fit_shot

if TYPE_CHECKING:  # imported when called (frame imports this module's neighbours)
    from .frame import FrameInputs, FrameSettings

__all__ = ["ClipCalibration", "ClipResult", "calibrate_clip", "calibrate_clip_frames", "image_change",
           "image_changes"]


def image_change(a: np.ndarray, b: np.ndarray) -> float:
    """How different two consecutive frames look, 0 (same) .. 1: the mean absolute difference of
    their 32x18 grey thumbnails, in units of full scale. Within a shot the thumbnails barely move
    (grass is uniform, a pan shifts them by a fraction of a thumbnail pixel): 0.002-0.007 on
    synthetic clips; a cut replaces them: 0.04-0.11 there."""
    import cv2

    def thumb(img: np.ndarray) -> np.ndarray:
        grey = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY) if img.ndim == 3 else img
        return cv2.resize(grey, (32, 18), interpolation=cv2.INTER_AREA).astype(np.float32)

    return float(np.mean(np.abs(thumb(a) - thumb(b))) / 255.0)


@dataclass
class ClipResult:
    #: per frame: the shot's camera, or None (a shot without any per-frame camera to start from)
    cameras: list[Camera | None]
    #: per frame: index of its shot
    shot_of: list[int]
    shots: list[range]
    fits: list[ShotFit | None]


def calibrate_clip(observations: Sequence[Observations | None], cameras: Sequence[Camera | None],
                   size: tuple[float, float], params: TemporalParams = TemporalParams(),
                   changes: Sequence[float | None] | None = None, model: FieldModel | None = None) -> ClipResult:
    """A clip in time order: its shots (:func:`segment_shots`), and in each shot that has at least
    one per-frame camera the broadcast camera (:func:`fit_shot`) of every frame that has
    observations (frames with none keep no camera)."""
    model = model or load_field_model()
    T = len(observations)
    shots = segment_shots(cameras, changes, params)
    out: list[Camera | None] = [None] * T
    shot_of = [0] * T
    fits: list[ShotFit | None] = []
    for k, shot in enumerate(shots):
        for t in shot:
            shot_of[t] = k
        if all(cameras[t] is None for t in shot):
            fits.append(None)
            continue
        fit = fit_shot([observations[t] for t in shot], [cameras[t] for t in shot], size, params, model)
        fits.append(fit)
        for t, cam in zip(shot, fit.cameras):
            if observations[t] is not None:
                out[t] = cam
    return ClipResult(out, shot_of, shots, fits)


def image_changes(images: Iterable[np.ndarray | None]) -> list[float | None]:
    """:func:`image_change` from each frame to the next (one value fewer than frames; None where
    either frame is missing), the ``changes`` of :func:`calibrate_clip`. ``images`` may be a
    generator: two frames are held at a time."""
    out: list[float | None] = []
    prev, first = None, True
    for img in images:
        if not first:
            out.append(image_change(prev, img) if prev is not None and img is not None else None)
        prev, first = img, False
    return out


@dataclass
class ClipCalibration:
    #: per frame: its own camera (None without one), its observations (None without input)
    per_frame: list[Camera | None]
    observations: list[Observations | None]
    result: ClipResult


def calibrate_clip_frames(inputs: Sequence[FrameInputs | None], settings: FrameSettings, *,
                          cameras: Sequence[Camera | None] | None = None,
                          changes: Sequence[float | None] | None = None,
                          model: FieldModel | None = None) -> ClipCalibration:
    """A clip as ``pnlviz calibrate --temporal`` calibrates it: ``inputs`` are the frames'
    :class:`pnlviz.calib.frame.FrameInputs` in time order (None: unreadable), all of one size, and
    ``settings`` their :class:`~pnlviz.calib.frame.FrameSettings`. The per-frame cameras (computed
    with :func:`~pnlviz.calib.frame.calibrate_frame` unless given), the frames' observations, and
    :func:`calibrate_clip` with the shot's lens fitted the way the frames' calibration fits it (no
    k1 for detections whose detector says ``refine_k1: false``)."""
    from .frame import calib_params, calibrate_frame, observations_for

    model = model or load_field_model()
    sizes = {(i.size[0], i.size[1]) for i in inputs if i is not None}
    if len(sizes) != 1:
        raise ValueError("the frames of a clip must have one size")
    if cameras is None:
        cameras = [calibrate_frame(i, settings, model).camera if i is not None else None for i in inputs]
    found = [observations_for(i, settings.source, model) if i is not None else (None, None) for i in inputs]
    origin = next((g for _, g in found if g is not None), None)
    params = TemporalParams(fit_k1=calib_params(settings, origin).refine_k1)
    obs = [o for o, _ in found]
    result = calibrate_clip(obs, list(cameras), sizes.pop(), params, changes=changes, model=model)
    return ClipCalibration(list(cameras), obs, result)
