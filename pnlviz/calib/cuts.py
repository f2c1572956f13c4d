"""Where a broadcast clip cuts from one shot to the next, one rule for every caller (``pnlviz
calibrate --temporal``, :func:`pnlviz.calibrate_clip`, the app and its export):

1. **found** (:func:`find_shots`): where every image change between consecutive frames is known
   (:func:`pnlviz.calib.temporal.image_change`), a large change; otherwise per-frame cameras whose
   centres and views jump (a different camera position), confirmed by the next frame, and the
   image changes that are known. (With the images known, a per-frame camera that jumps is a frame
   with too few keypoints, not a cut.)
2. **by hand** (:class:`CutEdits`, :func:`apply_cuts`): cuts a user added or removed.
3. **by the fit** (:func:`pnlviz.calib.temporal.solve_clip`): a shot whose camera is worse than
   its frames' own cameras on some of them is split where the frames' own centres jump, when that
   makes fewer frames worse (never at a cut removed by hand).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from pnlviz.field.model import pitch_grid
from pnlviz.geometry.camera import Camera

from .shot import TemporalParams

__all__ = ["CutEdits", "apply_cuts", "find_shots", "segment_shots", "view_change"]

_GRID = pitch_grid(5.0)


def view_change(a: Camera, b: Camera) -> float:
    """Median displacement (pixels of ``a``) of the pitch grid points both cameras see (inf when
    they see none in common)."""
    pa = a.project(_GRID)
    pb = b.scaled(a.width, a.height).project(_GRID)
    seen = a.in_image(pa) & np.all(np.isfinite(pb), 1)
    return float(np.median(np.linalg.norm(pa[seen] - pb[seen], axis=1))) if seen.any() else math.inf


def segment_shots(cameras: Sequence[Camera | None], changes: Sequence[float | None] | None = None,
                  params: TemporalParams = TemporalParams()) -> list[range]:
    """Cut a clip into shots: ``range`` objects covering ``0 .. len(cameras) - 1`` in order. A cut
    falls before frame t when ``changes[t - 1]`` (the image change from t - 1 to t) exceeds
    ``cut_image``, or when frame t's per-frame camera is apart from the current shot (its centre
    farther than ``cut_centre_m`` from the median of the shot's last five centres, and its view of
    the pitch moved by more than ``cut_view`` of the image width from the shot's latest camera)
    *and* so is the next calibrated frame (one wrong per-frame camera is an outlier, not a cut).
    Frames without a camera never cut."""
    T = len(cameras)
    if T == 0:
        return []
    calibrated = [t for t in range(T) if cameras[t] is not None]
    cuts: list[int] = []
    centres: list[np.ndarray] = []
    last: Camera | None = None  # the shot's latest camera that was not an outlier

    def apart(a: Camera, b: Camera, ref: np.ndarray) -> bool:
        return (float(np.linalg.norm(a.C - ref)) > params.cut_centre_m
                and view_change(a, b) > params.cut_view * a.width)

    for t in range(T):
        if t > 0 and changes is not None and (change := changes[t - 1]) is not None and change > params.cut_image:
            cuts.append(t)
            centres = []
        cam = cameras[t]
        if cam is None:
            continue
        C = np.asarray(cam.C, float)
        if centres and last is not None:
            ref = np.median(np.array(centres[-5:]), axis=0)
            if apart(cam, last, ref):
                later = next((cameras[u] for u in calibrated if u > t), None)
                confirmed = later is not None and apart(later, last, ref)
                if not confirmed:
                    continue  # an outlier frame: it neither cuts nor moves the reference
                if not cuts or cuts[-1] != t:
                    cuts.append(t)
                centres = []
        centres.append(C)
        last = cam
    bounds = [0, *sorted(set(c for c in cuts if 0 < c < T)), T]
    return [range(a, b) for a, b in zip(bounds[:-1], bounds[1:]) if b > a]


def find_shots(cameras: Sequence[Camera | None], changes: Sequence[float | None] | None = None,
               params: TemporalParams = TemporalParams()) -> list[range]:
    """The shots found in a clip (step 1 of the module docstring): from the image changes alone
    when every one is known, else from the per-frame ``cameras`` and the changes known."""
    T = len(cameras)
    images = changes is not None and len(changes) == T - 1 and all(c is not None for c in changes)
    return segment_shots([None] * T if images else cameras, changes, params)


@dataclass(frozen=True)
class CutEdits:
    """Cuts changed by hand: ``added`` frames start a shot, ``removed`` ones no longer do (a cut
    before frame t is named by t)."""

    added: frozenset[int] = frozenset()
    removed: frozenset[int] = frozenset()

    def with_cut(self, t: int, cut: bool) -> CutEdits:
        """These edits with a cut before frame ``t`` added (``cut``) or removed."""
        t = int(t)
        if cut:
            return CutEdits(self.added | {t}, self.removed - {t})
        return CutEdits(self.added - {t}, self.removed | {t})

    def to_json(self) -> dict:
        return {"added": sorted(self.added), "removed": sorted(self.removed)}

    @classmethod
    def from_json(cls, obj: Mapping | None) -> CutEdits:
        """From :meth:`to_json`'s form (None: no cuts). Anything else is a ValueError saying what
        (a damaged file must not read as "no cuts", nor ``"123"`` as cuts 1, 2 and 3)."""
        if obj is None:
            return cls()
        if not isinstance(obj, Mapping) or set(obj) - {"added", "removed"}:
            raise ValueError(f"cuts: expected {{'added': [...], 'removed': [...]}}, got {str(obj)[:80]!r}")

        def frames(key: str) -> frozenset[int]:
            value = obj.get(key, [])
            if not isinstance(value, list) or not all(type(t) is int and t >= 0 for t in value):
                raise ValueError(f"cuts: {key!r} must be a list of frame numbers, got {str(value)[:80]!r}")
            return frozenset(value)

        return cls(frames("added"), frames("removed"))


def apply_cuts(shots: Sequence[range], cuts: CutEdits, T: int) -> list[range]:
    """The shots of a clip of ``T`` frames after the hand's cuts: the found cuts without the
    removed ones, with the added ones."""
    starts = {s.start for s in shots if 0 < s.start < T}
    starts = (starts - set(cuts.removed)) | {t for t in cuts.added if 0 < t < T}
    bounds = [0, *sorted(starts), T]
    return [range(a, b) for a, b in zip(bounds[:-1], bounds[1:]) if b > a]
