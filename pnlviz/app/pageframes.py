"""The frame's pixels as the page draws them: an ``<img>`` behind the transparent WebGL canvas
(``pageframes.js``), not a textured plane of the scene.

Why: in software WebGL (a machine without a GPU, as most annotation VMs are) the image plane was
the largest cost of every frame the browser drew, 37-40 ms of about 87 at 1276x900, whatever its
pixels (the cost is filling its area in the scene's transparent, multisampled pass). The page
composites an ``<img>`` for a fraction of that, and every latency of the image view (a drag's
release, the next frame, a pan) waits for two or three such frames.

How: each of :data:`FRAME_SLOTS` hidden panel elements carries one frame's JPEG as a data URL
(``data-src``), with its size and a version that changes with its pixels. The page decodes each
slot once; the slot to show, and its version, come with the view in ``#pnlviz-view``
(:mod:`pnlviz.app.pagesync`), in the message batch of the overlays drawn over it, so the page
places it from the same numbers as the camera and swaps it in the animation frame that draws
those overlays (viser applies a batch in one frame and draws it in the next). A frame sent ahead
(hidden) is shown with no pixels sent. Measured: a frame of the image view 79 -> 46 ms
(``benchmarks/bench_frame_cost.py``; docs/app.md, "What a frame costs"). The scene keeps an
invisible surface where the image is, which takes the clicks
(:class:`pnlviz.app.workspace.Workspace`).

A tab without a browser (tests, the command line) keeps the bookkeeping and sends nothing.
"""

from __future__ import annotations

import base64
from collections.abc import Callable, Hashable

import cv2
import numpy as np

from pnlviz.app.view2d import ImagePlane

FRAME_SLOTS = 3  #: frames whose pixels are kept in the page: the one shown and two sent ahead
JPEG_QUALITY = 90
FRAME_CLASS = "pnlviz-frame"  #: the class of the slots' panel elements (the page finds them by it)


def frame_pixels(image_bgr) -> np.ndarray:
    """``image_bgr`` as an array, checked: H x W x 3 uint8 (else ValueError)."""
    image = np.asarray(image_bgr)
    if image.ndim != 3 or image.shape[2] != 3 or image.dtype != np.uint8:
        raise ValueError(f"a frame's pixels are H x W x 3 uint8, not {image.shape} {image.dtype}")
    return image


def frame_html(slot: int, version: int, image_bgr: np.ndarray, quality: int = JPEG_QUALITY) -> str:
    """The hidden panel element carrying ``image_bgr`` (H x W x 3, BGR as the frame reader gives
    it, uint8) in slot ``slot`` at ``version``."""
    image = frame_pixels(image_bgr)
    ok, jpeg = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise ValueError("the frame could not be encoded as JPEG")
    url = "data:image/jpeg;base64," + base64.b64encode(jpeg.tobytes()).decode("ascii")
    H, W = image.shape[:2]
    return (f'<div class="{FRAME_CLASS}" data-slot="{int(slot)}" data-n="{int(version)}" '
            f'data-size="{W},{H}" data-src="{url}" style="display:none"></div>')


class FrameSlots:
    """Which frames' pixels the page holds, and which one it shows. ``gui``: the tab's panel (its
    ``add_html``), or None for a tab without a browser."""

    def __init__(self, gui=None, slots: int = FRAME_SLOTS):
        self._gui = gui
        self._handles: list = []  # panel elements, one per slot, made on first use
        self._slots: list[dict] = []  # key, plane, version, used (a clock), per slot
        self._clock = 0
        self._versions = 0
        self.capacity = slots
        self.shown: int | None = None  # the slot shown
        self.sent = 0  # frames' pixels sent to the page

    @property
    def shown_key(self) -> Hashable | None:
        return None if self.shown is None else self._slots[self.shown]["key"]

    @property
    def shown_plane(self) -> ImagePlane | None:
        """The plane of the frame shown, None before the first."""
        return None if self.shown is None else self._slots[self.shown]["plane"]

    def page_state(self) -> str:
        """What ``#pnlviz-view`` tells the page to show: ``"slot,version"`` ("" before a frame)."""
        if self.shown is None:
            return ""
        return f"{self.shown},{self._slots[self.shown]['version']}"

    def holds(self, key: Hashable) -> bool:
        """Whether frame ``key``'s pixels are in the page already (shown or sent ahead)."""
        return any(sl["key"] == key for sl in self._slots)

    def show(self, key: Hashable, image_bgr: np.ndarray | Callable[[], np.ndarray]) -> ImagePlane:
        """Show frame ``key`` (its pixels, or a function that reads them when the page does not hold
        them yet); its plane."""
        i = next((i for i, sl in enumerate(self._slots) if sl["key"] == key), None)
        if i is None:
            i = self._load(key, image_bgr() if callable(image_bgr) else image_bgr)
        self._clock += 1
        self._slots[i]["used"] = self._clock
        self.shown = i
        return self._slots[i]["plane"]

    def preload(self, key: Hashable, image_bgr: Callable[[], np.ndarray]) -> None:
        """Send frame ``key``'s pixels ahead, hidden, so that showing it sends nothing."""
        if not self.holds(key):
            self._load(key, image_bgr())

    def _load(self, key: Hashable, image_bgr: np.ndarray) -> int:
        """Pixels into a slot: a new one while there are fewer than ``capacity``, else the one
        shown longest ago (never the one shown). Pixels that are not a frame are refused before
        anything changes."""
        image = frame_pixels(image_bgr)
        if len(self._slots) >= self.capacity:
            i = min((j for j in range(len(self._slots)) if j != self.shown), key=lambda j: self._slots[j]["used"])
        else:
            i = len(self._slots)
        html = frame_html(i, self._versions + 1, image) if self._gui is not None else None
        self._versions += 1
        entry = {"key": key, "plane": ImagePlane(int(image.shape[1]), int(image.shape[0])),
                 "version": self._versions, "used": 0}
        if i < len(self._slots):
            self._slots[i] = entry
        else:
            self._slots.append(entry)
        if html is not None:
            if i < len(self._handles):
                self._handles[i].content = html
            else:
                self._handles.append(self._gui.add_html(html))
            self.sent += 1
        return i


__all__ = ["FRAME_CLASS", "FRAME_SLOTS", "FrameSlots", "frame_html", "frame_pixels"]
