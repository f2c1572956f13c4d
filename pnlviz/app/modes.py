"""The app's modes and pointer events as types: which view a tab shows, its filter and sort, what
a drag moves, which kind of point is selected or dragged, and a drag's phase. Values from the
browser (a dropdown's text, viser's phase names) become these once, where they come in; the
value of each dropdown option is the text the user sees in it.
"""

from __future__ import annotations

import enum
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np


class Mode(enum.Enum):
    """The view a tab shows: the frame as an image, or the pitch and the camera in 3D."""

    IMAGE = "image"
    THREE_D = "3d"

    @property
    def other(self) -> Mode:
        return Mode.THREE_D if self is Mode.IMAGE else Mode.IMAGE


class Filter(enum.Enum):
    """Which frames a tab steps through (the values are the options of the "filter" dropdown)."""

    ALL = "all"
    FAILED = "failed"  # calibrated, with no camera
    UNREVIEWED = "unreviewed"
    ACCEPTED = "accepted"
    CORRECTED = "corrected"
    REJECTED = "rejected"
    SUSPECTS = "suspects"  # an annotation the label-error finder flags (pnlviz.calib.qa: score >= 1)

    @property
    def review(self) -> str | None:
        """The review status this filter keeps (None: it is not a filter by status)."""
        return self.value if self in (Filter.ACCEPTED, Filter.CORRECTED, Filter.REJECTED) else None


class Sort(enum.Enum):
    """The order a tab steps through its frames in (the values are the "sort" dropdown's options)."""

    INDEX = "index"
    JAC5 = "JaC@5 (worst first)"
    RESIDUAL = "residual (worst first)"
    SUSPECT = "suspect score (worst first)"


class DragMode(enum.Enum):
    """What a drag on the image moves (the values are the "drag" dropdown's options)."""

    KEYPOINTS = "keypoints"
    LINE_POINTS = "line points"


class PointKind(enum.StrEnum):
    """The points drawn on the image: observed keypoints, ghosts of the missing ones, points of
    annotated lines. (A string enum: it names the point nodes and overlay layers.)"""

    KEYPOINTS = "keypoints"
    GHOSTS = "ghosts"
    LINE_POINTS = "line_points"


class DragPhase(enum.Enum):
    """viser's drag phases: the press, the moves, the release (or a cancel)."""

    START = "start"
    UPDATE = "update"
    END = "end"


#: what a point is: a keypoint (or ghost) id, or a line point's (class name, index)
PointKey = int | tuple[str, int]


@dataclass(frozen=True)
class Selection:
    """A selected point: a keypoint or ghost id, or for a line point (class name, index)."""

    kind: PointKind
    key: PointKey

    @property
    def kid(self) -> int:
        """The id of a keypoint or ghost."""
        assert not isinstance(self.key, tuple), "a line point has no keypoint id"
        return int(self.key)

    @property
    def line_point(self) -> tuple[str, int]:
        """(class name, index) of a line point."""
        assert isinstance(self.key, tuple), "a keypoint is not a line point"
        return self.key

    @property
    def is_keypoint(self) -> bool:
        """A keypoint or a ghost: it has a keypoint id."""
        return self.kind in (PointKind.KEYPOINTS, PointKind.GHOSTS)


@dataclass(frozen=True, eq=False)
class DragEvent:
    """A point dragged: which one, the phase, and the image pixel it is dragged to."""

    kind: PointKind
    key: PointKey
    phase: DragPhase
    uv: np.ndarray

    @property
    def point(self) -> Selection:
        return Selection(self.kind, self.key)


def labels(options: type[enum.Enum]) -> tuple[str, ...]:
    """The texts of a dropdown whose options are ``options``' values, in their order."""
    return tuple(member.value for member in options)


__all__ = ["DragEvent", "DragMode", "DragPhase", "Filter", "Mode", "PointKind", "Selection", "Sort", "WorkspaceEvents",
           "labels"]


@dataclass
class WorkspaceEvents:
    """What the workspace reports, in image pixels of the frame it showed."""

    place: Callable[..., None]  # shift+click on the frame: place(uv); on a ghost: place(uv, its id)
    click: Callable[[np.ndarray], None]  # a plain click on the frame (not on a point)
    pan: Callable[[DragPhase, np.ndarray, np.ndarray], None]  # (phase, start, now): screen fractions of the canvas
    pick: Callable[[Selection], None]  # a click on a point
    pick_more: Callable[[Selection], None]  # Ctrl+click on a point: in or out of the selection
    drag: Callable[[DragEvent], None]  # a point dragged (to the pixel in the event)
    screen_to_pixel: Callable[[np.ndarray], np.ndarray]  # screen fractions of the canvas -> image pixel
