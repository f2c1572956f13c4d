"""Which frames a tab steps through, and in what order: the filter and the sort as pure functions
over the frames' views and review statuses (:func:`visible_order`), and the tab's place among
them (:class:`FrameOrder`). No GUI here.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence

import numpy as np

from pnlviz.app.modes import Filter, Sort
from pnlviz.app.state import FrameView


def matches(flt: Filter, view: FrameView | None, review: str | None) -> bool:
    """Whether a frame with this view (None: not calibrated yet) and review status is in ``flt``."""
    if flt is Filter.FAILED:
        return view is not None and (view.result is None or not view.result.ok)
    if flt is Filter.UNREVIEWED:
        return review is None
    if flt.review is not None:
        return review == flt.review
    return True


def worst_residual(view: FrameView | None) -> float:
    """A frame's largest keypoint or line residual (px) for the sort: frames without a camera
    first (1e9), those not calibrated yet last (-1)."""
    if view is None:
        return -1.0
    if view.result is None or not view.result.ok:
        return 1e9
    r = list(view.result.point_residuals.values()) + list(view.result.line_residuals.values())
    return max(r) if r else 0.0


def sort_key(sort: Sort, view: FrameView | None) -> float:
    """The key a frame is sorted by (ascending; equal keys keep the dataset's order)."""
    if sort is Sort.JAC5:
        return view.jac.get(5, -1.0) if view is not None else 2.0
    if sort is Sort.RESIDUAL:
        return -worst_residual(view)
    return 0.0


def visible_order(stems: Sequence[str], views: Mapping[str, FrameView], review: Callable[[str], str | None],
                  flt: Filter, sort: Sort) -> list[int]:
    """Dataset indices of the frames in ``flt``, in ``sort``'s order. ``views``: the views
    computed so far, by stem; ``review(stem)``: a frame's review status."""
    idx = [i for i, stem in enumerate(stems) if matches(flt, views.get(stem), review(stem))]
    if sort is not Sort.INDEX:
        idx.sort(key=lambda i: sort_key(sort, views.get(stems[i])))
    return idx


class FrameOrder:
    """A tab's frame (``index``, a dataset index), its filter and sort, and the frames of the
    filter in order (``order``). With no frame in the filter, ``order`` is the frame shown alone
    and ``outside_filter`` says so."""

    def __init__(self, n_frames: int, index: int):
        self.n_frames = n_frames
        self.index = index
        self.filter, self.sort = Filter.ALL, Sort.INDEX
        self.order = list(range(n_frames))
        self.outside_filter = False

    def position(self) -> int:
        """Where the frame is in the order, from 0 (0 when it is not in it)."""
        return self.order.index(self.index) if self.index in self.order else 0

    def clamp(self, index: int) -> int:
        return int(np.clip(index, 0, self.n_frames - 1))

    def refreshed(self, order: list[int]) -> int:
        """A new order (the filter or the sort changed): the frame to show, this one if it is in
        the new order, else its first (with no match this one, outside the filter)."""
        self.outside_filter = not order
        self.order = order or [self.index]
        return self.index if self.index in self.order else self.order[0]

    def stepped(self, delta: int) -> int:
        """The frame ``delta`` places on in the order (stopping at its ends)."""
        return self.order[int(np.clip(self.position() + delta, 0, len(self.order) - 1))]

    def at(self, pos, first: int = 0) -> int:
        """The frame at position ``pos`` of the order, counted from ``first`` (the slider counts
        from 1; anything not a number: the first frame)."""
        try:
            pos = int(pos) - first
        except (TypeError, ValueError, OverflowError):
            pos = 0
        return self.order[int(np.clip(pos, 0, len(self.order) - 1))]

    def after(self, index: int, order: list[int]) -> tuple[int, bool]:
        """Take the new ``order`` (the one after frame ``index`` changed) and give the frame that
        came after ``index`` in the old one and is still in it, and whether there was none (then
        the frame is ``index`` itself if it is still in the order, else the order's first)."""
        old = self.order
        later = old[old.index(index) + 1:] if index in old else []
        self.order = order or [index]
        self.outside_filter = not order
        nxt = next((j for j in later if j in order), None)
        if nxt is None:
            return (index if index in self.order else self.order[0]), True
        return nxt, False


__all__ = ["FrameOrder", "matches", "sort_key", "visible_order", "worst_residual"]
