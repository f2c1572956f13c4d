"""What the page's pointer bridge (``bridge.js``) is told of a tab's image view, so that it can pan
and zoom the canvas by itself at display rate and tell a pan from a point drag on the press.

A hidden element of the tab's panel, ``#pnlviz-view``, carries in its data attributes:

* ``data-v``: the view's version (:attr:`pnlviz.app.viewcontrol.ViewControl.version`, one more
  on every camera push); ``data-answer``: the last page gesture handled, ``data-applied``: 1 if
  the camera went where the page showed, 0 if it was refused (the page takes its transform off);
* ``data-view``: the image pixel at the canvas centre and the zoom (CSS px per image px);
  ``data-canvas``: the canvas in CSS px the server computes with; ``data-limits``: the zoom
  limits and the frame size (the page keeps its transform within what the server would allow);
* ``data-reach``: the screen radius (CSS px) within which a press grabs a point, and
  ``data-points``: every grabbable point, image pixels ``x,y,x,y,...`` (a press within reach of
  one is left to viser: a point drag; any other plain left press on the canvas is a pan);
* ``data-frame``: the frame to draw behind the canvas, ``slot,version`` (its pixels are in the
  slot's panel element: :mod:`pnlviz.app.pageframes`), so that the page places and swaps it with
  the view and the overlays it belongs to;
* ``data-ids``: the keypoint ids the page writes over the canvas, ``text,u,v;...`` (image
  pixels), most important first: the page hides an id closer than ``data-id-gap`` CSS px
  (:data:`pnlviz.app.workspace.LABEL_MIN_GAP_PX`) on screen to one before it, at every zoom;
* ``data-draw``: the overlays, points, pin boxes and selection rings the page draws over the
  frame (:attr:`pnlviz.app.workspace.Workspace.marks`, written by
  :func:`pnlviz.app.pagedraw.draw_text`).

A push announces itself inside the camera's atomic message batch
(:meth:`pnlviz.app.viewcontrol.ViewControl.push`), so the page gets the new version with the
new camera. Only what changed is sent.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from pnlviz.app.view2d import MAX_ZOOM, MIN_ZOOM_OF_FIT, View2D
from pnlviz.app.points import GRAB_PX
from pnlviz.app.workspace import LABEL_MIN_GAP_PX


def page_data(version: int, answer: int, applied: bool, view: View2D | None, canvas: tuple[int, int],
              plane, reach: float, points: np.ndarray, frame: str = "",
              ids: Sequence[tuple[str, float, float]] = (), id_gap: float = 0.0, draw: str = "") -> str:
    """The ``#pnlviz-view`` element for these values (``plane``: the frame's
    :class:`pnlviz.app.view2d.ImagePlane`, None before the first frame; ``frame``: the slot shown,
    :meth:`pnlviz.app.pageframes.FrameSlots.page_state`; ``ids``: ``(text, u, v)`` per id label,
    most important first, :attr:`pnlviz.app.workspace.Workspace.id_labels`; ``id_gap``: the least
    distance between two ids shown, CSS px; ``draw``: the marks the page draws over the frame,
    :func:`pnlviz.app.pagedraw.draw_text`)."""
    attrs = {"v": str(int(version)), "answer": str(int(answer)), "applied": "1" if applied else "0",
             "canvas": f"{int(canvas[0])},{int(canvas[1])}", "frame": frame,
             "ids": ";".join(f"{_id_text(t)},{u:.1f},{v:.1f}" for t, u, v in ids
                             if np.isfinite(u) and np.isfinite(v)),
             "id-gap": f"{float(id_gap):g}", "draw": draw}
    if view is not None and plane is not None:
        fit = View2D.fit(plane, canvas).zoom
        attrs["view"] = f"{view.cu:.4f},{view.cv:.4f},{view.zoom:.6g}"
        attrs["limits"] = f"{MIN_ZOOM_OF_FIT * fit:.6g},{max(MAX_ZOOM, fit):.6g},{plane.W},{plane.H}"
        attrs["reach"] = f"{reach:.2f}"
        pts = np.asarray(points, float).reshape(-1, 2)
        pts = pts[np.all(np.isfinite(pts), axis=1)]
        attrs["points"] = ",".join(f"{v:.1f}" for v in pts.ravel())
    body = " ".join(f'data-{k}="{v}"' for k, v in attrs.items())
    return f'<div id="pnlviz-view" style="display:none" {body}></div>'


def _id_text(text: str) -> str:
    """An id label's text as ``data-ids`` carries it: what separates its fields, and what HTML
    would read, left out (ids are digits, with "?" or parentheses)."""
    return "".join(c for c in str(text) if c not in ',;"<>&')


class PageSync:
    """The ``#pnlviz-view`` element of one tab (``gui``: the tab's panel), kept up to date with its
    ``workspace`` (the points) and its ``control`` (:class:`pnlviz.app.viewcontrol.ViewControl`)."""

    def __init__(self, gui, workspace, control):
        self.workspace, self.control = workspace, control
        self.answer, self.applied = -1, False
        self._content = ""
        self.updates = 0  # times the element was sent
        self.handle = gui.add_html(self._data())
        control.on_push = self.pushed

    def pushed(self, answer: int | None, applied: bool) -> None:
        """The camera was pushed (or a gesture refused): the page is told, in the same batch."""
        if answer is not None:
            self.answer, self.applied = answer, applied
        self.sync()

    def sync(self) -> None:
        """Send the element if anything in it changed (the view, the points)."""
        content = self._data()
        if content != self._content:
            self._content = content
            self.handle.content = content
            self.updates += 1

    def _data(self) -> str:
        ws, control = self.workspace, self.control
        view = control.view2d
        plane = ws.plane
        reach = GRAB_PX * ws.world_per_px / plane.scale * view.zoom if view is not None and plane is not None else 0.0
        nodes = [n for n in ws.points.values() if n.keys and len(n.uv)]
        points = np.concatenate([n.uv for n in nodes]) if nodes else np.zeros((0, 2))
        return page_data(control.version, self.answer, self.applied, view, control.canvas, plane, reach, points,
                         ws.frames.page_state(), ws.id_labels, LABEL_MIN_GAP_PX, ws.marks_text)


__all__ = ["PageSync", "page_data"]
