"""Which camera each frame of a shot keeps: the shot's or its own.

The shot's camera of a frame is judged against that frame's own observations, item by item, with
the frame pipeline's distances (:func:`pnlviz.calib.shot_fit.distances`): an item is a keypoint,
a line class or a circle class, and its distance is that of its farthest point. The frame's noise
is measured from its own camera: ``sigma = sqrt(rss / (n - p))`` over its ``n`` residual scalars
and the camera's ``p`` parameters (8; 7 without k1), no less than the detection noise
(``TemporalParams.noise_px``); with ``n <= p`` its own camera merely interpolates its few points
and cannot vouch for itself (``sigma`` infinite). An item **prefers** one camera when the other
puts it farther than ``3 sigma`` and than twice the first camera's distance, while the first puts
it within ``3 sigma``. The shot's camera is **worse** than the frame's own when at least
:data:`WORSE_BY` more items prefer the frame's camera than prefer the shot's (one wrong detection
that the frame's own camera bends to is not enough). Noise cannot tip it (a camera fitted to the frame alone
is closer on every item, but within its noise), and a frame with too few observations for a
reliable camera of its own is carried by the shot.
The frame then keeps its own camera, but for a frame alone in that (:func:`alone_kept_by_shot`): a
broadcast camera moves smoothly, so a shot's camera that is wrong on one frame is wrong on its
neighbours too; a frame whose items prefer its own camera while its neighbours' do not is a frame
whose observations are off (a detector's bad frame: its own camera follows them), and it keeps the
shot's camera, reported so.

The shot's camera is also held to the frame's verdict (``CalibParams.max_rms``: the RMS of the
keypoints it keeps), and a shot whose solve did not converge gives no frame its camera.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Literal

import numpy as np

from pnlviz.geometry.camera import Camera

from .calibrate import CalibParams
from .problem import FrameData
from .shot import FrameDistances, TemporalParams
from .shot_fit import distances

__all__ = ["MIN_RUN", "CameraChoice", "Use", "alone_kept_by_shot", "frame_noise", "judge_frame", "second_look_choice"]

#: which camera a clip frame uses: its shot's, its own (per-frame calibration), or none
Use = Literal["shot", "own", "none"]
#: the shot's camera is worse when this many more of the frame's items prefer its own camera
WORSE_BY = 2
#: ... on at least this many consecutive frames (or the whole shot, when shorter)
MIN_RUN = 3
#: how a reason ends for a frame that has no camera of its own to keep
NONE_OF_ITS_OWN = ", and the frame has none of its own"


@dataclass(frozen=True)
class CameraChoice:
    """The camera a clip frame uses and why (one line a user reads)."""

    use: Use
    reason: str
    #: items (keypoints, line and circle classes) that prefer the frame's own camera / the shot's
    worse: tuple[str, ...] = ()
    better: tuple[str, ...] = ()
    #: the frame's own camera was kept because items prefer it (not by the verdict or the solve)
    by_items: bool = False

    def to_json(self) -> dict:
        return {"use": self.use, "reason": self.reason, "worse": list(self.worse), "better": list(self.better)}


def _names(data: FrameData, classes: Sequence[str], at: np.ndarray) -> tuple[str, ...]:
    """The names of items ``at`` (indices into :meth:`FrameDistances.values` with ``classes``)."""
    n = data.obs.n_keypoints
    return tuple(f"keypoint {int(data.obs.kp_ids[i])}" if i < n else classes[i - n] for i in at.tolist())


def _check_length(d: FrameDistances, data: FrameData) -> None:
    if len(d.keypoints) != data.obs.n_keypoints:
        raise ValueError(f"distances of {len(d.keypoints)} keypoints for a frame of {data.obs.n_keypoints}")


def _prefers(a: np.ndarray, b: np.ndarray, tol: float) -> np.ndarray:
    """Items ``a`` px from one camera and ``b`` px from the other that prefer the first."""
    return (a <= tol) & (tol < b) & (b > 2 * a)


def frame_noise(d: FrameDistances, floor: float, n_params: int) -> float:
    """The noise (px) of a frame's observations measured from a camera fitted to them (``d``), no
    less than ``floor``; infinite when the camera has no more residuals than parameters."""
    if d.n <= n_params:
        return math.inf
    return max(floor, math.sqrt(d.rss / (d.n - n_params)))


def judge_frame(data: FrameData | None, shot: Camera | None, own: Camera | None, params: TemporalParams,
                calib: CalibParams = CalibParams(), converged: bool = True, *,
                shot_distances: FrameDistances | None = None, own_distances: FrameDistances | None = None
                ) -> CameraChoice:
    """The camera frame ``data`` uses: its shot's ``shot`` or its own ``own`` (either None when
    there is none). See the module docstring. ``shot_distances`` / ``own_distances``: the
    cameras' :class:`FrameDistances` on the frame when the caller has them."""
    if data is None:
        return CameraChoice("none", "nothing observed on this frame")
    if shot is None or not converged:
        why = "the shot has no camera" if shot is None else "the shot's solve did not converge"
        if own is None:
            return CameraChoice("none", f"{why}{NONE_OF_ITS_OWN}")
        return CameraChoice("own", f"{why}: the frame keeps its own camera")
    W = float(shot.width)
    d_shot = shot_distances or distances(data, shot)
    _check_length(d_shot, data)
    fail = _verdict(data, d_shot, calib, W)
    if own is None:
        if fail:
            return CameraChoice("none", f"the shot's camera fails the frame's verdict ({fail}){NONE_OF_ITS_OWN}")
        return CameraChoice("shot", "the frame has no camera of its own: the shot carries it")
    d_own = own_distances or distances(data, own)
    _check_length(d_own, data)
    classes = list(d_shot.classes)
    a, b = d_shot.values(classes), d_own.values(classes)
    tol = 3 * frame_noise(d_own, params.noise_px * W / 960.0, 8 if calib.refine_k1 else 7)
    worse_at, better_at = np.flatnonzero(_prefers(b, a, tol)), np.flatnonzero(_prefers(a, b, tol))
    worse, better = _names(data, classes, worse_at), _names(data, classes, better_at)
    if fail:
        return CameraChoice("own", f"the shot's camera fails the frame's verdict ({fail})", worse, better)
    if len(worse) - len(better) >= WORSE_BY:
        far = ", ".join(f"{k} ({a[i]:.0f} px, own {b[i]:.1f})" if math.isfinite(a[i]) else f"{k} (behind)"
                        for k, i in zip(worse, worse_at[:3]))
        more = f" and {len(worse) - 3} more" if len(worse) > 3 else ""
        return CameraChoice("own", f"the shot's camera misses {far}{more}, which the frame's own camera fits",
                            worse, better, by_items=True)
    if better:
        return CameraChoice("shot", f"the shot's camera fits {len(better)} item(s) the frame's own camera misses",
                            worse, better)
    return CameraChoice("shot", "the shot's camera fits the frame as well as its own", worse, better)


def second_look_choice(choice: CameraChoice) -> CameraChoice:
    """``choice`` (judged without a camera of its own) of a frame whose own camera rests on a
    second look at its detections, which a shot does not fit (:func:`pnlviz.calib.looks.for_shot`):
    its reason says so."""
    why = ("its own camera rests on detections under the detector's thresholds (a second look), "
           "which a shot does not fit")
    if choice.use == "shot":
        return replace(choice, reason=f"{why}: the shot carries it")
    return replace(choice, reason=f"{choice.reason.removesuffix(NONE_OF_ITS_OWN)}; {why}")


def _verdict(data: FrameData, d: FrameDistances, calib: CalibParams, width: float) -> str | None:
    """Why a camera fails the frame pipeline's verdict (no keypoint within the point gate, or
    their RMS above ``max_rms``), None when it passes (a frame of lines alone: nothing to judge)."""
    if not data.obs.n_keypoints:
        return None
    gate = calib.px(calib.point_gate_px, width)
    kept = d.keypoints[(d.keypoints <= gate) | data.obs.pins]
    if not len(kept):
        return f"no keypoint within {gate:.0f} px"
    rms = float(np.sqrt(np.mean(np.square(kept))))
    limit = calib.px(calib.max_rms, width)
    return None if rms <= limit else f"keypoint RMS {rms:.1f} px > {limit:.1f}"


def alone_kept_by_shot(choices: list[CameraChoice]) -> list[CameraChoice]:
    """The choices of a shot's frames (in order) with each run of frames that keep their own
    camera by their items (``by_items``) shorter than :data:`MIN_RUN` frames (and than the shot)
    given back to the shot's camera: see the module docstring. A run that touches a frame keeping
    its own camera for another reason (the shot's camera fails its verdict) is not alone: the shot's
    camera is wrong there too, and the run keeps its own."""
    out = list(choices)
    need = min(MIN_RUN, len(choices))
    i = 0
    while i < len(out):
        if out[i].use != "own":
            i += 1
            continue
        j = i
        while j < len(out) and out[j].use == "own":
            j += 1
        if j - i < need and all(out[k].by_items for k in range(i, j)):
            for k in range(i, j):
                c = out[k]
                out[k] = CameraChoice("shot", c.reason.replace("the shot's camera misses", "its observations disagree "
                                                               "with its neighbours': the shot's camera misses", 1)
                                      .replace(", which the frame's own camera fits", ", which only the frame's own "
                                               "camera fits (suspect observations)"), c.worse, c.better)
        i = j
    return out
