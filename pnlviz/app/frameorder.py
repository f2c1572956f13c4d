"""Which frames a tab steps through, and in what order: the filter and the sort as pure functions
over the frames' views and review statuses (:func:`visible_order`), and the tab's place among
them (:class:`FrameOrder`). No GUI here.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence

import numpy as np

from pnlviz.app.modes import Filter, Sort
from pnlviz.app.triage import FrameSummary
from pnlviz.data.layout import split_stem


def matches(flt: Filter, summary: FrameSummary | None, review: str | None) -> bool:
    """Whether a frame with this summary (None: not calibrated yet) and review status is in ``flt``."""
    if flt is Filter.FAILED:
        return summary is not None and not summary.ok
    if flt is Filter.SUSPECTS:
        return summary is not None and summary.suspect is not None and summary.suspect >= 1.0
    if flt is Filter.UNREVIEWED:
        return review is None
    if flt.review is not None:
        return review == flt.review
    return True


def worst_residual(summary: FrameSummary | None) -> float:
    """A frame's largest keypoint or line residual (px) for the sort: frames without a camera
    first (1e9), those not calibrated yet last (-1)."""
    if summary is None:
        return -1.0
    if not summary.ok:
        return 1e9
    return summary.worst


def sort_key(sort: Sort, summary: FrameSummary | None) -> float:
    """The key a frame is sorted by (ascending; equal keys keep the dataset's order)."""
    if sort is Sort.JAC5:
        if summary is None:
            return 2.0
        return summary.jac5 if summary.ok and summary.jac5 is not None else -1.0
    if sort is Sort.RESIDUAL:
        return -worst_residual(summary)
    if sort is Sort.SUSPECT:  # most suspect first; not judged (no annotation) after, not calibrated yet last
        if summary is None:
            return 1.0
        return -summary.suspect if summary.suspect is not None else 0.5
    return 0.0


def sort_key_text(sort: Sort, summary: FrameSummary | None) -> str | None:
    """What the tab's sort sees of a frame, for the panel (None when the sort is the dataset's order)."""
    if sort is Sort.INDEX:
        return None
    if summary is None:
        return f"{sort.value}: not calibrated yet"
    if not summary.ok:
        return f"{sort.value}: no camera"
    if sort is Sort.JAC5:
        return f"JaC@5 {summary.jac5:.3f}" if summary.jac5 is not None else "JaC@5: no annotation to score against"
    if sort is Sort.SUSPECT:
        if summary.suspect is None:
            return "suspect score: not judged (no annotation, or edited since)"
        return f"suspect score {summary.suspect:.2f}" + (f": {summary.suspect_note}" if summary.suspect_note else "")
    return f"worst residual {summary.worst:,.1f} px"


def visible_order(stems: Sequence[str], summaries: Mapping[str, FrameSummary], review: Callable[[str], str | None],
                  flt: Filter, sort: Sort, split: str = "") -> list[int]:
    """Dataset indices of the frames in ``flt`` (and in ``split``, of a dataset in splits; ``""``:
    every split), in ``sort``'s order. ``summaries``: the frames' summaries known so far, by stem;
    ``review(stem)``: a frame's review status."""
    idx = [i for i, stem in enumerate(stems) if (not split or split_stem(stem)[0] == split)
           and matches(flt, summaries.get(stem), review(stem))]
    if sort is not Sort.INDEX:
        idx.sort(key=lambda i: sort_key(sort, summaries.get(stems[i])))
    return idx


class FrameOrder:
    """A tab's frame (``index``, a dataset index), its filter and sort, and the frames of the
    filter in order (``order``). With no frame in the filter, ``order`` is the frame shown alone
    and ``outside_filter`` says so."""

    def __init__(self, n_frames: int, index: int):
        self.n_frames = n_frames
        self.index = index
        self.filter, self.sort = Filter.ALL, Sort.INDEX
        self.split = ""  # a dataset in splits: the one split stepped through ("": all)
        self.order = list(range(n_frames))
        self.outside_filter = False

    def filter_label(self) -> str:
        """The filter as the panel names it (``"unreviewed"``, ``"split valid"``, ``"unreviewed in valid"``)."""
        if not self.split:
            return self.filter.value
        return f"split {self.split}" if self.filter is Filter.ALL else f"{self.filter.value} in {self.split}"

    def position(self) -> int:
        """Where the frame is in the order, from 0 (0 when it is not in it)."""
        return self.order.index(self.index) if self.index in self.order else 0

    def clamp(self, index: int) -> int:
        return int(np.clip(index, 0, self.n_frames - 1))

    def refreshed(self, order: list[int], first: bool = False) -> int:
        """A new order (the filter or the sort changed): the frame to show, this one if it is in
        the new order (unless ``first``: a new sort), else its first (with no match this one,
        outside the filter)."""
        self.outside_filter = not order
        self.order = order or [self.index]
        return self.index if self.index in self.order and not first else self.order[0]

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


__all__ = ["FrameOrder", "matches", "sort_key", "sort_key_text", "visible_order", "worst_residual"]
