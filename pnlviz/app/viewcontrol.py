"""The browser camera of one tab: in the image view a 2D camera over the frame (pan, zoom around
the pointer, fit, native resolution, the canvas resized), kept straight at the image whatever
viser's own controls do; in the 3D view a viewpoint behind the estimated camera. The page's
pointer bridge (:mod:`pnlviz.app.bridge`) reports the wheel, + and -, the arrows and the canvas
size here.

The view itself is pure (:class:`pnlviz.app.view2d.View2D`); this part holds the tab's current
one, clamps what it is asked for, and sends the camera (without a browser, nothing is sent).

Pan and zoom are done in the page at display rate (``bridge.js`` moves the canvas with a CSS
transform) and arrive here once per gesture (:meth:`ViewControl.gesture`): no camera is pushed
while the hand moves. Each push gets a new :attr:`ViewControl.version` and is announced to the
page with it (``on_push``, in the same atomic message batch as the camera), which is how the page
knows when the real render replaces its transform.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import numpy as np

from pnlviz.app.bridge import FIT, NATIVE, Gesture, parse_pointer
from pnlviz.app.modes import DragPhase, Mode
from pnlviz.app.view2d import FOV_Y, PLANE_Z, View2D

#: the canvas assumed until the browser reports its own (and for a session without a browser)
DEFAULT_CANVAS = (1280, 860)
FOV_3D = math.radians(50.0)
#: seconds after the server moved the camera during which the browser's camera reports are its echoes
ECHO_S = 0.5


class ViewControl:
    """The camera of one tab. ``workspace``: what holds the frame's plane (``plane``) and keeps
    its points a constant size on screen (``set_zoom``); ``client``: the tab's viser client (None
    without a browser); ``on_zoom(view)``: the zoom changed; ``nudge(dx, dy)``: the arrow keys
    moved the selected point; ``enqueue``: the tab's queue, for the camera's reports."""

    def __init__(self, workspace, client, on_zoom: Callable[[View2D], None], nudge: Callable[[int, int], None],
                 enqueue: Callable[[Callable[[], object]], None], clock: Callable[[], float] = time.monotonic):
        self.workspace, self.client = workspace, client
        self.on_zoom, self.nudge, self.enqueue, self.clock = on_zoom, nudge, enqueue, clock
        self.mode = Mode.IMAGE
        self.view2d: View2D | None = None
        #: the canvas in screen (CSS) pixels, as the page's bridge reports it (until then, viser's
        #: drawing-buffer size, which is the same at a device pixel ratio of 1)
        self.canvas = DEFAULT_CANVAS
        self.css_canvas: tuple[int, int] | None = None
        self.relative: tuple[float, float, float] | None = None  # carried to frames of another size
        self.bridge_seen = (-1, 0.0, (0, 0))  # (n, log_zoom, nudge) of the last bridge message
        self._pushed_at = -math.inf
        self._pan_from: View2D | None = None
        #: the view's version (one more on every camera push), how many pushes were sent, the last
        #: page gesture handled, and who announces a push to the page: ``on_push(answer, applied)``
        self.version = self.pushes = 0
        self.gesture_seen = -1
        self.on_push: Callable[[int | None, bool], None] | None = None
        #: a box drawn in the page (ctrl+drag): ``on_box(lo, hi)``, its corners in image pixels
        self.on_box: Callable[[np.ndarray, np.ndarray], None] | None = None
        self.box_seen = 0

    @property
    def in_image(self) -> bool:
        """In the image view, with a frame on its plane."""
        return self.mode is Mode.IMAGE and self.view2d is not None

    # ------------------------------------------------------------------ what the user asks for
    def pan(self, phase: DragPhase, start, now) -> None:
        """A drag on the image that viser reported (screen fractions ``start`` -> ``now``): the
        page pans by itself, so this comes only when its bridge took the press for one on a point
        (or is not loaded); the image moves once, at the release, by what the hand moved."""
        if not self.in_image:
            return
        if phase is DragPhase.START or self._pan_from is None:
            self._pan_from = self.view2d
        if phase is not DragPhase.END:
            return
        base, self._pan_from = self._pan_from, None
        assert base is not None  # in the image view, set at the press or here
        d = (np.asarray(now, float) - np.asarray(start, float)) * self.canvas
        self.push(base.panned(d[0] / base.zoom, d[1] / base.zoom))

    def gesture(self, g: Gesture) -> None:
        """A pan and zoom the page did (a CSS transform on the view of version ``g.base``): the
        camera goes where the page showed, in one push, and the page is answered either way. With
        a view key (``g.view``) the key's view instead (native resolution around the centre of
        what the page showed), made whatever view the page was on."""
        if g.k <= self.gesture_seen:
            return
        self.gesture_seen = g.k
        made_here = g.base == self.version
        plane = self.workspace.plane
        if not self.in_image or plane is None or not (made_here or g.view):  # a view key: on any view
            if self.on_push is not None:  # not applied: the page takes its transform off
                self.on_push(g.k, False)
            return
        v, canvas = self.view2d, np.asarray(self.canvas, float)
        assert v is not None  # in the image view
        centre = np.array([v.cu, v.cv])
        if made_here:  # where the page showed
            centre = centre + ((1.0 - g.s) * canvas / 2 - np.asarray(g.t)) / (g.s * v.zoom)
        if g.view == FIT:
            self.fit(answer=g.k)
        elif g.view == NATIVE:  # around the centre of what the page showed
            self.native((float(centre[0]), float(centre[1])), answer=g.k)
        else:
            self.push(View2D(float(centre[0]), float(centre[1]), v.zoom * g.s), answer=g.k)

    def zoom_by(self, factor: float, at_screen=None) -> None:
        """Zoom by ``factor`` around a canvas point (pixels; default: the centre)."""
        v = self.view2d
        if not self.in_image or v is None:  # in_image: there is a view
            return
        at = v.to_pixel(at_screen, self.canvas) if at_screen is not None else None
        self.push(v.zoomed(factor, at))

    def fit(self, answer: int | None = None) -> None:
        """The whole frame in the canvas; ``answer``: the page gesture it answers (a view key)."""
        if self.mode is Mode.IMAGE and self.workspace.plane is not None:
            self.push(View2D.fit(self.workspace.plane, self.canvas), answer=answer)

    def native(self, centre: tuple[float, float] | None = None, answer: int | None = None) -> None:
        """One image pixel per screen pixel, around ``centre`` (image pixels; default: the centre
        of the view); ``answer``: the page gesture it answers (a view key)."""
        v = self.view2d
        if self.in_image and v is not None:  # in_image: there is a view
            cu, cv = centre if centre is not None else (v.cu, v.cv)
            self.push(View2D(cu, cv, 1.0), answer=answer)

    def to_pixel(self, fractions) -> np.ndarray:
        """The image pixel under a canvas point given as fractions of the canvas."""
        view = self.view2d or View2D(0.0, 0.0, 1.0)
        return view.to_pixel(np.asarray(fractions, float) * self.canvas, self.canvas)

    def bridge_message(self, text) -> None:
        """What the page's pointer bridge sent (read by :func:`pnlviz.app.bridge.parse_pointer`:
        anything else is ignored): the canvas size, a zoom around the pointer, a nudge. Its
        totals are compared with the last message's, so a message lost or repeated changes
        nothing twice."""
        msg = parse_pointer(text)
        n, log_zoom, nudge = self.bridge_seen
        if msg is None or msg.n <= n:
            return
        self.bridge_seen = (msg.n, msg.log_zoom, msg.nudge)
        if msg.canvas is not None and msg.canvas != self.css_canvas:
            self.css_canvas = msg.canvas
            self.resized(msg.canvas)
        if msg.gesture is not None:
            self.gesture(msg.gesture)
        if msg.box is not None and msg.box.k > self.box_seen:
            self.box_seen = msg.box.k
            if self.in_image and self.on_box is not None:
                b = msg.box
                self.on_box(self.to_pixel((b.x0, b.y0)), self.to_pixel((b.x1, b.y1)))
        if msg.log_zoom != log_zoom:
            self.zoom_by(math.exp(float(np.clip(msg.log_zoom - log_zoom, -3.0, 3.0))),
                         (msg.x * self.canvas[0], msg.y * self.canvas[1]))
        dx, dy = msg.nudge[0] - nudge[0], msg.nudge[1] - nudge[1]
        if (dx or dy) and self.mode is Mode.IMAGE:
            self.nudge(int(np.clip(dx, -100, 100)), int(np.clip(dy, -100, 100)))

    # ------------------------------------------------------------------ frames and modes
    def frame_placed(self, plane_before) -> None:
        """A frame was put on the image plane: on the first frame, or one of another size, the
        view is the same part of the frame as before (the whole frame at first)."""
        plane = self.workspace.plane
        if plane == plane_before and self.view2d is not None:
            return
        view = View2D.fit(plane, self.canvas)
        if self.relative:
            view = View2D.from_relative(self.relative, plane, self.canvas)
        if self.mode is Mode.IMAGE:
            self.push(view)
        else:
            self.view2d = view.clamped(plane, self.canvas)

    def restore(self) -> None:
        """Back in the image view: the view it had."""
        if self.relative is not None and self.workspace.plane is not None:
            self.push(View2D.from_relative(self.relative, self.workspace.plane, self.canvas))

    def look_3d(self, pose: dict) -> None:
        """The 3D view's camera at ``pose`` (position, look_at, up)."""
        if self.client is None:
            return
        with self.client.atomic():
            cam = self.client.camera
            cam.near, cam.far, cam.fov = 0.05, 1000.0, FOV_3D
            cam.up_direction = pose["up"]
            cam.position = pose["position"]
            cam.look_at = pose["look_at"]

    # ------------------------------------------------------------------ the browser camera
    def push(self, view: View2D, answer: int | None = None) -> None:
        """Put the browser camera on ``view`` (clamped to what the image view allows); ``answer``:
        the page gesture it applies, announced with the new version in the same message batch."""
        plane = self.workspace.plane
        if plane is None:
            return
        view = view.clamped(plane, self.canvas)
        self._keep(view)
        if self.client is None:
            return
        position, look_at = view.camera(plane, self.canvas[1])
        d = PLANE_Z - position[2]
        self._pushed_at = self.clock()
        cam = self.client.camera
        with self.client.atomic():
            cam.fov = FOV_Y
            cam.up_direction = (0.0, -1.0, 0.0)
            cam.position = position
            cam.look_at = look_at
            cam.near, cam.far = 0.25 * d, 2.0 * d + 1.0
            self.version += 1
            self.pushes += 1
            if self.on_push is not None:
                self.on_push(answer, answer is not None)

    def _keep(self, view: View2D) -> None:
        """``view`` is what the tab shows now."""
        plane = self.workspace.plane
        self.view2d = view
        self.relative = view.relative(plane, self.canvas)
        self.workspace.set_zoom(plane.scale / view.zoom)
        self.on_zoom(view)

    async def on_camera(self, camera) -> None:
        """The browser's camera moved (viser's own controls, or an echo of ours): checked on the
        tab's queue."""
        if self.mode is not Mode.IMAGE:
            return
        try:
            state = (np.array(camera.position), np.array(camera.wxyz), np.array(camera.look_at),
                     (int(camera.image_width), int(camera.image_height)))
        except AssertionError:  # no camera message yet
            return
        self.enqueue(lambda: self.camera_moved(*state))

    def camera_moved(self, position, wxyz, look_at, canvas: tuple[int, int]) -> None:
        """Keep the image view an image view: looking straight at the frame, within the zoom
        limits. In the image view the page's bridge takes viser's own pans and zooms (right drag,
        W A S D Q E) as its own gestures; whatever else moves the camera (a touch gesture) may pan
        and zoom; anything else (an orbit, a dolly through the image) is put back."""
        plane = self.workspace.plane
        if self.mode is not Mode.IMAGE or plane is None or min(canvas) <= 0 or self.view2d is None:
            return
        if self.css_canvas is None and canvas != self.canvas:
            self.resized(canvas)
            return
        if self.clock() - self._pushed_at < ECHO_S:
            return  # an echo of a view we set (or of the 3D view we left): ours is newer
        d = PLANE_Z - position[2]
        straight = (d > 0 and abs(abs(wxyz[0]) - 1.0) < 1e-4 and abs(look_at[2] - PLANE_Z) < 1e-3 * d
                    and np.hypot(*(look_at[:2] - position[:2])) < 1e-3 * d)
        if not straight:
            self.push(self.view2d)
            return
        # the canvas height in the camera's own pixels gives the zoom it shows; in screen pixels:
        view = View2D.from_camera(plane, position, canvas[1])
        view = View2D(view.cu, view.cv, view.zoom * self.canvas[1] / canvas[1])
        clamped = view.clamped(plane, self.canvas)
        moved = abs(clamped.cu - view.cu) + abs(clamped.cv - view.cv)
        if abs(math.log(clamped.zoom / view.zoom)) > 1e-3 or moved > 0.5:
            self.push(clamped)
            return
        self._keep(view)
        if self.on_push is not None:  # viser's own controls moved it: the page's bridge is told
            self.on_push(None, False)

    def resized(self, canvas: tuple[int, int]) -> None:
        """The canvas changed size: the same part of the frame stays in view."""
        self.canvas = canvas
        plane = self.workspace.plane
        if plane is not None and self.relative is not None and self.mode is Mode.IMAGE:
            self.push(View2D.from_relative(self.relative, plane, canvas))


__all__ = ["DEFAULT_CANVAS", "ECHO_S", "FOV_3D", "ViewControl"]
