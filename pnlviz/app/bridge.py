"""The server's side of the pointer bridge (``bridge.js``, run in the page): the panel element that
loads it and tells it the mode, the checked reading of what it sends, and the URL a page opens.

Pan and zoom happen in the page: the bridge moves the canvas with a CSS transform at display rate
and sends one message at the end of the gesture (:class:`Gesture`: the transform, relative to the
view the page was showing); the server applies it with one camera push and answers with the view
(:mod:`pnlviz.app.pagesync`), and the bridge takes its transform off when that answer arrives.

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
from urllib.parse import parse_qsl, urlencode, urlsplit, urlunsplit

from pnlviz.app.modes import Mode


def _script() -> str:
    """The page's scripts: the pointer bridge, then the frame layer (``pageframes.js``)."""
    files = resources.files("pnlviz.app")
    return "\n".join(files.joinpath(name).read_text(encoding="utf-8") for name in ("bridge.js", "pageframes.js"))


#: The colour around the image in the image view: the page's background there (the bridge paints
#: it; a mesh around the image cost every WebGL frame the pixels it covers)
BACKDROP_RGB = (38, 40, 46)

#: The keys that move the image view: fit, native resolution (:mod:`pnlviz.app.bindings`). In
#: the image view the page sends them as a gesture (:attr:`Gesture.view`: the key's place here
#: plus one), so the view that answers it is known by its number, and a zoom or pan made after
#: the key stays over that view whatever else arrives first
VIEW_KEYS = ("0", "1")
#: :attr:`Gesture.view` of each view key
FIT, NATIVE = 1, 2

#: The label of the text field the bridge writes to: the page finds the field by it (a label no
#: other widget has; the bridge hides its row).
BRIDGE_FIELD = "pnlviz-pointer"


def bridge_html(input_label: str, mode: Mode | str) -> str:
    """The HTML of the panel element that runs the bridge (once per page) and configures it for
    the tab's view (a :class:`pnlviz.app.modes.Mode`, or its value; anything else: ValueError): in
    the image view the page around the frame takes :data:`BACKDROP_RGB`.
    ``input_label``: the label of the text field it writes to (letters, digits, - and _)."""
    mode = Mode(mode)
    code = base64.b64encode(_script().encode("utf-8")).decode("ascii")
    safe_label = "".join(c for c in input_label if c.isalnum() or c in "-_")
    return (f'<div id="pnlviz-bridge" data-input="{safe_label}" data-mode="{mode.value}" '
            f'data-backdrop="rgb{BACKDROP_RGB}" data-view-keys="{"".join(VIEW_KEYS)}" style="display:none"></div>'
            f'<img alt="" src="data:," style="display:none" onerror="eval(atob(\'{code}\'))">')


def page_url(url: str, dpr: float = 1.0) -> str:
    """``url`` with viser's ``fixedDpr`` parameter: the canvas drawn at that device pixel ratio
    instead of one lowered when the machine is slow (the bridge reloads a page once with its own
    ratio when the URL carries another)."""
    parts = urlsplit(url)
    query = [(k, v) for k, v in parse_qsl(parts.query, keep_blank_values=True) if k != "fixedDpr"]
    return urlunsplit(parts._replace(query=urlencode(query + [("fixedDpr", f"{dpr:g}")])))


@dataclass(frozen=True)
class Gesture:
    """A pan and zoom done in the page: ``k`` its sequence number, ``base`` the version of the view
    it was made on (:attr:`pnlviz.app.viewcontrol.ViewControl.version`), and the CSS transform
    it left on the canvas: a canvas point ``p`` (CSS pixels) shows what was at ``(p - t) / s``.
    ``view``: 0, or a view key pressed at its end (:data:`FIT`, :data:`NATIVE`), whose view
    replaces the transform."""

    k: int
    base: int
    s: float
    t: tuple[float, float]
    view: int = 0


@dataclass(frozen=True)
class Box:
    """A rectangle drawn in the page with a ctrl+drag: ``k`` its sequence number, (``x0``, ``y0``)
    - (``x1``, ``y1``) its corners as fractions of the canvas as the server renders it (the page's
    own pan and zoom undone), ``x0 <= x1``, ``y0 <= y1``."""

    k: int
    x0: float
    y0: float
    x1: float
    y1: float


@dataclass(frozen=True)
class PointerMessage:
    """The bridge's state: ``n`` its sequence number, ``log_zoom`` the total log-zoom asked for so
    far, (``x``, ``y``) the pointer as fractions of the canvas, ``nudge`` the total arrow-key
    nudge so far (image pixels, x and y), ``canvas`` the canvas size in CSS pixels (None: unknown),
    ``gesture`` the last pan and zoom done in the page (None: none yet), ``box`` the last
    rectangle drawn (None: none yet)."""

    n: int
    log_zoom: float
    x: float
    y: float
    nudge: tuple[int, int]
    canvas: tuple[int, int] | None = None
    gesture: Gesture | None = None
    box: Box | None = None


def _box(value) -> Box | None:
    """A box field ``[k, x0, y0, x1, y1]``; ValueError when malformed."""
    if value is None:
        return None
    k, x0, y0, x1, y1 = value  # ValueError / TypeError when not five
    b = Box(int(k), float(x0), float(y0), float(x1), float(y1))
    if b.k < 1 or not all(math.isfinite(v) and abs(v) <= 1e4 for v in (b.x0, b.y0, b.x1, b.y1)) \
            or b.x0 > b.x1 or b.y0 > b.y1:
        raise ValueError("box out of range")
    return b


def _gesture(value) -> Gesture | None:
    """A gesture field ``[k, base, s, tx, ty]`` or ``[k, base, s, tx, ty, view]``; ValueError when
    malformed."""
    if value is None:
        return None
    k, base, s, tx, ty, *rest = value  # ValueError / TypeError when fewer than five
    if len(rest) > 1:
        raise ValueError("gesture: five or six fields")
    g = Gesture(int(k), int(base), float(s), (float(tx), float(ty)), int(rest[0]) if rest else 0)
    if g.k < 0 or not all(math.isfinite(v) for v in (g.s, *g.t)) or not 1e-4 <= g.s <= 1e4 \
            or max(abs(g.t[0]), abs(g.t[1])) > 1e7 or g.view not in (0, FIT, NATIVE):
        raise ValueError("gesture out of range")
    return g


def parse_pointer(text: str) -> PointerMessage | None:
    """A bridge message, or None for anything that is not a well-formed one."""
    if not isinstance(text, str) or not text or len(text) > 600:
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
        gesture = _gesture(d.get("view"))
        box = _box(d.get("box"))
    except (KeyError, IndexError, TypeError, ValueError, OverflowError):
        return None
    if canvas is not None and not (1 <= canvas[0] <= 20000 and 1 <= canvas[1] <= 20000):
        canvas = None
    if not all(math.isfinite(v) for v in (log_zoom, x, y)) or abs(log_zoom) > 1e4 or n < 0:
        return None
    if max(abs(nx), abs(ny)) > 10 ** 7:
        return None
    return PointerMessage(n, log_zoom, min(max(x, 0.0), 1.0), min(max(y, 0.0), 1.0), (nx, ny), canvas, gesture, box)
