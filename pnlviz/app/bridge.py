"""The server's side of the pointer bridge (``bridge.js``, run in the page): the panel element that
loads it and tells it the mode, and the checked reading of what it sends.

viser has no wheel event and no hotkey for + and -; the bridge takes them in the page and writes a
small JSON message into a text field of the panel (hidden), which viser delivers like any typed
value. Such a value comes from the browser, so :func:`parse_pointer` trusts nothing in it: it is
read here, once, into a :class:`PointerMessage`, and nothing past this module sees the text.

Why a text field: viser 1.1.1 has no channel from the page to the server for a message of the
app's own. What a page sends it are the messages of its own widgets and scene (a value typed or
chosen, a button pressed or held, a command, a click or drag on a node, a transform control
moved, a click or rectangle on the scene, the camera, a file upload, a form submitted or
changed) and answers to the server's requests (a render, a ``localStorage`` item: only the
server can ask for those). Of these, a widget's value is the one a script in the page can send
unasked, with text of its own; so the transport stays a hidden text field.
"""

from __future__ import annotations

import base64
import json
import math
from dataclasses import dataclass
from importlib import resources

from pnlviz.app.modes import Mode


def _script() -> str:
    return resources.files("pnlviz.app").joinpath("bridge.js").read_text(encoding="utf-8")


def bridge_html(input_uuid: str, mode: Mode | str) -> str:
    """The HTML of the panel element that runs the bridge (once per page) and configures it for
    the tab's view (a :class:`pnlviz.app.modes.Mode`, or its value; anything else: ValueError)."""
    mode = Mode(mode)
    code = base64.b64encode(_script().encode("utf-8")).decode("ascii")
    safe_uuid = "".join(c for c in input_uuid if c.isalnum() or c in "-_")
    return (f'<div id="pnlviz-bridge" data-input="{safe_uuid}" data-mode="{mode.value}" style="display:none"></div>'
            f'<img alt="" src="data:," style="display:none" onerror="eval(atob(\'{code}\'))">')


@dataclass(frozen=True)
class PointerMessage:
    """The bridge's state: ``n`` its sequence number, ``log_zoom`` the total log-zoom asked for so
    far, (``x``, ``y``) the pointer as fractions of the canvas, ``nudge`` the total arrow-key
    nudge so far (image pixels, x and y), ``canvas`` the canvas size in CSS pixels (None: unknown)."""

    n: int
    log_zoom: float
    x: float
    y: float
    nudge: tuple[int, int]
    canvas: tuple[int, int] | None = None


def parse_pointer(text: str) -> PointerMessage | None:
    """A bridge message, or None for anything that is not a well-formed one."""
    if not isinstance(text, str) or not text or len(text) > 400:
        return None
    try:
        d = json.loads(text)
    except ValueError:
        return None
    if not isinstance(d, dict) or d.get("kind") != "pointer":
        return None
    try:
        n, log_zoom, x, y = int(d["n"]), float(d["log_zoom"]), float(d["x"]), float(d["y"])
        nx, ny = (int(v) for v in d.get("nudge", (0, 0)))
        canvas = d.get("canvas")
        canvas = (int(canvas[0]), int(canvas[1])) if canvas is not None else None
    except (KeyError, IndexError, TypeError, ValueError, OverflowError):
        return None
    if canvas is not None and not (1 <= canvas[0] <= 20000 and 1 <= canvas[1] <= 20000):
        canvas = None
    if not all(math.isfinite(v) for v in (log_zoom, x, y)) or abs(log_zoom) > 1e4 or n < 0:
        return None
    if max(abs(nx), abs(ny)) > 10 ** 7:
        return None
    return PointerMessage(n, log_zoom, min(max(x, 0.0), 1.0), min(max(y, 0.0), 1.0), (nx, ny), canvas)
