"""The points you grab in the image view, of one kind (observed keypoints, ghosts of the missing
ones, points of annotated lines): where they are and their colours (the page draws them as flat
discs with a black rim: :attr:`pnlviz.app.workspace.Workspace.marks`), an invisible batched mesh
in the scene that takes the pointer (:class:`PointNodes`), and the drag of one of them, whether
the browser's pick found the mesh or only the image under it."""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterable

import numpy as np

from pnlviz.app.handles import update_changed
from pnlviz.app.modes import DragEvent, DragPhase, PointKind, Selection, WorkspaceEvents
from pnlviz.app.overlay import Markers
from pnlviz.app.view2d import PLANE_Z, ImagePlane, placed

#: screen pixels: the radius of a point's disc, of its black rim, and of the area that grabs it
DISC_PX, RIM_PX, GRAB_PX = 4.5, 6.0, 8.0
#: seconds a replaced grab mesh still takes presses (see :class:`PointNodes`)
GRACE_S = 3.0
#: the grab mesh is not made anew for points that all moved less than this (screen px): a press
#: takes the point nearest the pointer, so a disc half a pixel off takes the same presses, and
#: another tab's redraw after a shot's re-solve (its points a fraction of a pixel off) sends no
#: new mesh to the page (measured from the mesh as it was made, so small moves do not add up)
GRAB_SLACK_PX = 0.5
#: scene units a replaced grab mesh sinks towards the image (0.0005 -> 0.0002 in front of it: five
#: float32 steps behind the grab mesh in use at z 1000, where the browser compares depths; of hits
#: at one depth, its pick takes the mesh made first)
SINK = 0.0003


def _disc(n: int = 20) -> tuple[np.ndarray, np.ndarray]:
    """A unit disc in the xy plane (a fan of ``n`` triangles), facing both ways."""
    a = np.linspace(0.0, 2 * math.pi, n, endpoint=False)
    vertices = np.vstack([[0.0, 0.0, 0.0], np.stack([np.cos(a), np.sin(a), np.zeros(n)], 1)])
    faces = np.array([[0, 1 + i, 1 + (i + 1) % n] for i in range(n)])
    return vertices, faces


class PointNodes:
    """The points of one kind (the page draws them from ``uv`` and :attr:`shaded`), over an
    invisible batched mesh that takes the pointer, so every point of a frame is grabbed directly;
    ``keys[i]`` says what instance ``i`` is; ``moved()`` is called when a dragged point moves.

    The browser finds what the pointer hits on a batched mesh where its instances were when it
    was made: once they are moved or resized in place, a press on a point reports no instance
    and no position, and viser then sends no drag update until the release (the point would not
    follow the hand on any frame but the first). So the grab mesh is made anew, under a new name,
    whenever its instances change, except while one of its points is dragged: then it is left as
    it is (the drag follows the pointer on a plane, not by hitting the mesh; changed in place,
    it would pick no better, and each change is a scene message, which the page holds for its
    next animation frame with every message after it: the dragged disc and the live preview) and
    made anew after the release; it holds a few spare instances (parked out of sight) so that a
    point more or less does not re-create it under the hand. A replaced grab mesh stays
    (invisible, as every grab mesh) for :data:`GRACE_S` seconds, and after that until the next
    one is made: a press the browser took on it before the server's redraw reached the page
    (another tab's edit, under load) is still a press on the points (removed at once, such a
    press was lost: no drag, no pan). A
    press on any grab mesh takes the point nearest the pointer; with none within reach, the
    press is the image's (a click, a pan). A kept mesh sinks behind the one in use
    (:data:`SINK`, in the message batch that makes the new one), so the browser picks the new one
    once it has it: a kept one takes only the presses that come before that, and is not under
    the pointer when it goes. One case remains: a press on the very point just
    dropped, even on a mesh made anew, reports no instance in Chromium (cause not found); that
    drag lands by the pointer's screen position, as before, but without the live preview."""

    def __init__(self, scene, path: str, kind: PointKind, opacity: float = 1.0,
                 events: WorkspaceEvents | None = None):
        self.scene, self.path, self.kind, self.opacity = scene, path, kind, opacity
        self.events = events
        self.keys: list = []
        self.uv = np.zeros((0, 2))
        self.colors = np.zeros((0, 3), np.uint8)
        self.plane: ImagePlane | None = None
        self.world_per_px = 0.01
        self.grab = None
        self.moved: Callable[[], None] | None = None
        self.dragging = False  # one of these points is being dragged: the grab mesh stays
        self._grab_made: tuple[np.ndarray, np.ndarray] | None = None  # its instances as made
        self._grabs_made = 0
        self._retired: list = []  # grab meshes replaced during a drag, kept until its release
        self._stale: list = []  # (grab mesh replaced, when): removed after the grace period
        self._grabbed: dict = {}  # the drag in progress: key, where it was grabbed, the point's pixel then

    def place(self, markers: Markers, plane: ImagePlane, world_per_px: float) -> None:
        """The points are these now (what the page draws, what a press takes); the grab mesh
        follows at :meth:`sync_grab`."""
        self.keys, self.plane, self.world_per_px = list(markers.keys), plane, world_per_px
        self.uv = np.asarray(markers.uv, float).reshape(-1, 2).copy()
        self.colors = np.asarray(markers.colors, np.uint8).reshape(-1, 3)

    def sync_grab(self) -> None:
        """The grab mesh where the points are (made anew, or left: see the class docstring)."""
        if not self.keys and self.grab is None:
            return
        capacity = max(8, 1 << max(0, len(self.keys) - 1).bit_length())
        self._set_grab(*self._grab_layout(capacity))

    def _set_grab(self, pos: np.ndarray, scales: np.ndarray) -> None:
        """The grab mesh's instances: made anew when they changed (see the class docstring), left
        as they are while a point is dragged and the capacity holds."""
        made = self._grab_made  # None once its points moved during a drag: made anew after it
        if made is not None and made[0].shape == pos.shape and np.array_equal(made[1], scales) \
                and np.max(np.abs(made[0] - pos), initial=0.0) <= GRAB_SLACK_PX * self.world_per_px:
            return  # where the points are (self.uv) decides what a press takes; the discs are close enough
        if self.grab is not None and self.dragging and len(self.grab.batched_positions) == len(pos):
            self._grab_made = None  # the drag lives on it as it is
            return
        if self.grab is not None and self.dragging:
            self._retired.append(self.grab)  # the drag lives on it until its release
        elif self.grab is not None:
            self._retire([self.grab])
        self._grabs_made += 1
        vertices, faces = _disc()
        self.grab = self.scene.add_batched_meshes_simple(
            f"{self.path}/grab{self._grabs_made}", vertices, faces, np.tile([1.0, 0.0, 0.0, 0.0], (len(pos), 1)),
            pos, batched_scales=scales, batched_colors=(255, 255, 255), opacity=0.0, side="double",
            cast_shadow=False, receive_shadow=False, lod="off")
        self._grab_made = (pos.copy(), scales.copy())
        assert self.events is not None  # the workspace's, given when there are points to grab
        self._bind(self.grab, self.events)

    def _retire(self, meshes: list) -> None:
        """``meshes`` replaced now: they sink behind the mesh in use and take presses for the
        grace period; those replaced longer ago go."""
        for m in meshes:
            sunk = np.array(m.batched_positions, float)
            sunk[:, 2] += SINK
            update_changed(m, batched_positions=sunk)
        now = time.monotonic()
        keep = []
        for m, t in self._stale:
            if now - t < GRACE_S:
                keep.append((m, t))
            else:
                m.remove()
        self._stale = keep + [(m, now) for m in meshes]

    @property
    def shaded(self) -> np.ndarray:
        """The points' colours at this kind's opacity (ghosts: mixed with grey)."""
        if self.opacity >= 1.0:
            return self.colors
        return (self.opacity * self.colors + (1 - self.opacity) * 90).astype(np.uint8)

    def _grab_layout(self, capacity: int) -> tuple[np.ndarray, np.ndarray]:
        """Positions and scales of the grab mesh's instances: the points, then the spares."""
        n = len(self.keys)
        pos = np.zeros((capacity, 3))
        pos[:, 2] = PLANE_Z + 5.0  # spares: behind the image, tiny (a zero scale has no inverse)
        scales = np.full(capacity, 1e-6)
        if n:
            pos[:n] = placed(self.plane).world(self.uv, "grab")
            scales[:n] = GRAB_PX * self.world_per_px
        return pos, scales

    def rescale(self, world_per_px: float) -> None:
        self.world_per_px = world_per_px
        if self.grab is not None and self.keys:
            self.sync_grab()

    def move(self, index: int, uv) -> None:
        """Put point ``index`` at pixel ``uv`` (while it is dragged)."""
        if not 0 <= index < len(self.keys):
            return
        self.uv[index] = uv
        if self.grab is not None:
            self.sync_grab()
        if self.moved is not None:
            self.moved()

    def _instance(self, index: int | None, at_uv) -> int | None:
        """The point an event is about: the point nearest where the pointer hit, within reach;
        the instance viser reports only when it gives no hit position. (The browser picks among
        the instances it drew: when another tab's edit reorders the points, instance ``i`` there
        can be another point here; where two points' grab discs overlap, it names either one,
        and a press on one point's centre grabbed its neighbour. viser also reports no instance
        at times for a mesh whose instances moved.)"""
        if at_uv is None or not np.all(np.isfinite(at_uv)):
            return index if index is not None and 0 <= index < len(self.keys) else None
        if not self.keys:
            return None
        reach = 1.5 * GRAB_PX * self.world_per_px / placed(self.plane).scale  # image pixels
        d = np.hypot(*(self.uv - at_uv).T)
        i = int(np.argmin(d))
        return i if d[i] <= reach else None

    def _bind(self, node, events: WorkspaceEvents) -> None:
        def hit(event):
            """(the point clicked or None, the pixel the click's ray meets the image at)."""
            o = np.asarray(event.ray_origin, float)
            at = placed(self.plane).pixel_on_ray(o, o + np.asarray(event.ray_direction))
            return self._instance(event.instance_index, at), at

        @node.on_click
        async def _(event) -> None:
            i, at = hit(event)
            if i is not None:
                events.pick(Selection(self.kind, self.keys[i]))
            elif at is not None and np.all(np.isfinite(at)):  # no point there now: the frame's
                events.click(np.asarray(at, float))

        @node.on_click(modifier="cmd/ctrl")
        async def _(event) -> None:  # Ctrl+click: the point joins the selection (or leaves it)
            i = hit(event)[0]
            if i is not None:
                events.pick_more(Selection(self.kind, self.keys[i]))

        # Shift+click on a point places, as on the frame: on a ghost, that keypoint where the camera
        # puts it (the ghost becomes a keypoint); on another point, the chosen id there
        @node.on_click(modifier="shift")
        async def _(event) -> None:
            i, at = hit(event)
            if i is not None and self.kind is PointKind.GHOSTS:
                events.place(self.uv[i].copy(), self.keys[i])
            elif at is not None and np.all(np.isfinite(at)):
                events.place(np.asarray(at, float))

        route = DragRoute(lambda: (self,), events.pan)

        @node.on_drag
        async def _(event) -> None:
            route(event)

    def drag(self, event) -> bool:
        """A drag event of viser's on one of these points (on the grab mesh; or on the image
        under it, ``event.instance_index`` None, when the browser's pick missed the mesh: one made
        anew that it has not mounted yet). At its start, the point is the instance hit, else the
        one nearest the press within reach; False when there is none (the press is not for these
        points)."""
        grabbed, events = self._grabbed, self.events
        assert events is not None  # the workspace's, given when there are points to grab
        phase = DragPhase(event.phase)
        if phase is DragPhase.START:
            grabbed.clear()
            at = placed(self.plane).pixel(event.start_position) if self.plane is not None else np.full(2, np.nan)
            exact = bool(np.all(np.isfinite(at)))
            if not exact:  # viser lost the instance it hit: where the pointer is, on screen
                at = events.screen_to_pixel(np.asarray(event.end_screen_pos, float))
            i = self._instance(event.instance_index, at)
            if i is None:
                return False
            grabbed.update(key=self.keys[i], index=i, at=at, uv=self.uv[i].copy(), exact=exact)
            self.dragging = True
        if "key" not in grabbed:
            return False
        # the point follows the pointer by as many image pixels as the pointer moved
        pointer = (placed(self.plane).pixel(event.end_position) if grabbed["exact"]
                   else events.screen_to_pixel(np.asarray(event.end_screen_pos, float)))
        now = grabbed["uv"] + pointer - grabbed["at"]
        if phase is not DragPhase.START and self.keys[grabbed["index"]:grabbed["index"] + 1] == [grabbed["key"]]:
            self.move(grabbed["index"], now)
        key = grabbed["key"]
        if phase is DragPhase.END:  # before the release is handled: it makes the grab mesh anew
            grabbed.clear()
            self.dragging = False
            self._retire(self._retired)
            self._retired = []
        events.drag(DragEvent(self.kind, key, phase, now))
        return True


class DragRoute:
    """One gesture at a time on a node that points lie on (the image, its backdrop, a grab mesh):
    it drags the first of ``candidates()`` with a point within reach of the press, else it pans
    the view (``pan(phase, start, now)``, screen fractions of the canvas)."""

    def __init__(self, candidates: Callable[[], Iterable[PointNodes]],
                 pan: Callable[[DragPhase, np.ndarray, np.ndarray], None]) -> None:
        self.candidates, self.pan = candidates, pan
        self.points: PointNodes | None = None
        self.at: np.ndarray | None = None  # where the gesture started, when it pans

    def __call__(self, event) -> None:
        phase = DragPhase(event.phase)
        if phase is DragPhase.START:
            self.points = next((p for p in self.candidates() if p.keys and p.drag(event)), None)
            self.at = None if self.points is not None else np.array(event.start_screen_pos, float)
        elif self.points is not None:
            self.points.drag(event)
        if self.at is not None:
            self.pan(phase, self.at, np.array(event.end_screen_pos, float))
