"""The frames' pixels the page holds (pnlviz.app.pageframes): what is sent, once, into which slot,
and what the page is told to show."""

import base64
import re

import cv2
import numpy as np
import pytest

from pnlviz.app.pageframes import FRAME_CLASS, FrameSlots, frame_html
from pnlviz.app.view2d import ImagePlane


class Panel:
    """A panel that keeps the HTML elements added to it (viser's ``add_html`` handles)."""

    def __init__(self):
        self.elements = []

    def add_html(self, content):
        element = type("Html", (), {})()
        element.content = content
        self.elements.append(element)
        return element


def image(value: int, w: int = 64, h: int = 48) -> np.ndarray:
    out = np.zeros((h, w, 3), np.uint8)
    out[..., 0] = value  # blue (the frame reader's BGR order)
    return out


def decoded(html: str) -> np.ndarray:
    """The BGR pixels of a slot's data URL."""
    url = re.search(r'data-src="data:image/jpeg;base64,([^"]+)"', html).group(1)
    return cv2.imdecode(np.frombuffer(base64.b64decode(url), np.uint8), cv2.IMREAD_COLOR)


def test_a_frame_goes_to_the_page_once_and_a_frame_sent_ahead_is_shown_with_nothing_sent():
    panel = Panel()
    slots = FrameSlots(panel)
    assert slots.page_state() == "" and slots.shown_key is None
    plane = slots.show("a", image(200))
    assert plane == ImagePlane(64, 48) and slots.sent == 1 and len(panel.elements) == 1
    html = panel.elements[0].content
    assert f'class="{FRAME_CLASS}"' in html and 'data-slot="0"' in html and 'data-size="64,48"' in html
    assert np.abs(decoded(html).astype(int) - image(200)).max() <= 3  # the frame's own pixels, in order
    assert slots.page_state() == "0,1" and slots.shown_key == "a"

    slots.preload("b", lambda: image(100, 32, 24))
    slots.preload("b", lambda: pytest.fail("read again"))  # held: not read, not sent
    assert slots.sent == 2 and slots.holds("b") and slots.page_state() == "0,1"  # still showing a
    assert slots.show("b", lambda: pytest.fail("read again")) == ImagePlane(32, 24)
    assert slots.sent == 2 and slots.page_state() == "1,2"  # the slot and version sent ahead
    assert slots.show("a", image(0)) == ImagePlane(64, 48) and slots.sent == 2  # back: nothing sent


def test_a_fourth_frame_takes_the_slot_shown_longest_ago_never_the_one_shown():
    panel = Panel()
    slots = FrameSlots(panel)
    for key in "abc":
        slots.show(key, image(10))
    slots.show("a", image(10))  # shown order now: b, c, a (a shown)
    slots.preload("d", lambda: image(250))
    assert not slots.holds("b") and all(slots.holds(k) for k in "acd")
    assert slots.page_state() == "0,1"  # a still shown, untouched
    assert len(panel.elements) == 3 and 'data-slot="1"' in panel.elements[1].content
    assert np.abs(decoded(panel.elements[1].content).astype(int) - image(250)).max() <= 3
    slots.show("d", lambda: pytest.fail("read again"))
    assert slots.page_state() == "1,4"
    slots.preload("e", lambda: image(5))  # d shown: c, shown longest ago, goes
    assert not slots.holds("c") and slots.holds("d") and slots.page_state() == "1,4"


def test_a_tab_without_a_browser_keeps_the_bookkeeping_and_sends_nothing():
    slots = FrameSlots(None)
    assert slots.show("a", image(1)) == ImagePlane(64, 48)
    slots.preload("b", lambda: image(2))
    assert slots.holds("a") and slots.holds("b") and slots.sent == 0 and slots.page_state() == "0,1"


def test_pixels_that_are_not_an_rgb_frame_are_refused_and_nothing_is_sent():
    panel = Panel()
    slots = FrameSlots(panel)
    for bad, what in ((np.zeros((4, 4), np.uint8), r"\(4, 4\)"), (np.zeros((4, 4, 3), np.float32), "float32"),
                      (np.zeros((4, 4, 4), np.uint8), r"\(4, 4, 4\)")):
        with pytest.raises(ValueError, match=what):
            frame_html(0, 1, bad)
        with pytest.raises(ValueError, match="H x W x 3 uint8"):
            slots.show("x", bad)
    assert panel.elements == [] and slots.sent == 0
