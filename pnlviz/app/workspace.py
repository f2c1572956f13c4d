"""The image view's scene nodes for one tab: the frame on its plane (sent once per frame), the
overlays as line segments over it, and the points you grab (observed keypoints, ghosts of the
missing ones, points of annotated lines) as batched discs with their ids. Every node is created
once and then updated in place, so an edit sends only what changed and a drag in progress is
never cut short by a redraw.

Pointer events come back as image pixels through :class:`WorkspaceEvents`; what they mean (pan,
select, move, place) is the tab's business (:mod:`pnlviz.app.viewcontrol`,
:mod:`pnlviz.app.editing`). Nothing here computes a calibration.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Hashable
from typing import Any

import numpy as np

from pnlviz.app.handles import update_changed
from pnlviz.app.modes import DragEvent, DragPhase, PointKind, Selection, WorkspaceEvents
from pnlviz.app.overlay import FLAGGED_RGB, PIN_RGB, Markers, Overlay, Segments
from pnlviz.app.view2d import PLANE_Z, ImagePlane, declutter, placed
from pnlviz.viz import ring

#: screen pixels: the radius of a point's disc, of its black rim, of the area that grabs it, and
#: of the selection ring
DISC_PX, RIM_PX, GRAB_PX, RING_PX = 4.5, 6.0, 8.0, 11.0
PIN_BOX_PX = 8.5  #: screen pixels: half the side of the box around a pinned keypoint
#: screen thickness of each layer's lines
THICKNESS = {"refined_pitch": 2.0, "refined_pitch_casing": 4.5, "initial_pitch": 1.5, "reference_pitch": 1.5, "annotation": 2.0,
             "detected_lines": 2.0, "residuals": 1.5, "finding_annotated": 5.0, "finding_expected": 2.0}
BACKDROP_RGB = (38, 40, 46)
BACKDROP_MARGIN = 6.0  # the dark frame around the image: this many image widths (heights) each side
FRAME_SLOTS = 3  # frames whose pixels are kept in the browser: the one shown and two sent ahead
SELECTED_RGB = (255, 255, 255)
LABEL_MIN_GAP_PX = 16.0  # ids closer than this on screen: only the first one shows


def _disc(n: int = 20) -> tuple[np.ndarray, np.ndarray]:
    """A unit disc in the xy plane (a fan of ``n`` triangles), facing both ways."""
    a = np.linspace(0.0, 2 * math.pi, n, endpoint=False)
    vertices = np.vstack([[0.0, 0.0, 0.0], np.stack([np.cos(a), np.sin(a), np.zeros(n)], 1)])
    faces = np.array([[0, 1 + i, 1 + (i + 1) % n] for i in range(n)])
    return vertices, faces


class _PointNodes:
    """The points of one kind, drawn as flat discs with a black rim (two point clouds: unlit, so
    the colours are the legend's) over an invisible batched mesh that takes the pointer, so every
    point of a frame is grabbed directly; ``keys[i]`` says what instance ``i`` is.

    The browser finds what the pointer hits on a batched mesh where its instances were when it
    was made: once they are moved or resized in place, a press on a point reports no instance
    and no position, and viser then sends no drag update until the release (the point would not
    follow the hand on any frame but the first). So the grab mesh is made anew, under a new name,
    whenever its instances change, except while one of its points is dragged: then it is
    changed in place (the drag follows the pointer on a plane, not by hitting the mesh), and it
    holds a few spare instances (parked out of sight) so that a point more or less does not
    re-create it under the hand. One case remains: a press on the very point just dropped, even
    on a mesh made anew, reports no instance in Chromium (cause not found); that drag lands by
    the pointer's screen position, as before, but without the live preview."""

    def __init__(self, scene, path: str, kind: PointKind, layer: str, opacity: float = 1.0,
                 events: WorkspaceEvents | None = None):
        self.scene, self.path, self.kind, self.layer, self.opacity = scene, path, kind, layer, opacity
        self.events = events
        self.keys: list = []
        self.uv = np.zeros((0, 2))
        self.colors = np.zeros((0, 3), np.uint8)
        self.plane: ImagePlane | None = None
        self.world_per_px = 0.01
        self.disc = self.rim = self.grab = None
        self.dragging = False  # one of these points is being dragged: the grab mesh stays
        self._grab_made: tuple[np.ndarray, np.ndarray] | None = None  # its instances as made
        self._grabs_made = 0
        self._retired: list = []  # grab meshes replaced during a drag, removed at its release

    def show(self, markers: Markers, plane: ImagePlane, world_per_px: float) -> None:
        self.keys, self.plane, self.world_per_px = list(markers.keys), plane, world_per_px
        self.uv = np.asarray(markers.uv, float).reshape(-1, 2).copy()
        self.colors = np.asarray(markers.colors, np.uint8).reshape(-1, 3)
        if not self.keys and self.grab is None:
            return
        self._draw()
        capacity = max(8, 1 << max(0, len(self.keys) - 1).bit_length())
        self._set_grab(*self._grab_layout(capacity))

    def _set_grab(self, pos: np.ndarray, scales: np.ndarray) -> None:
        """The grab mesh's instances: made anew when they changed (see the class docstring), in
        place while a point is dragged and the capacity holds."""
        made = self._grab_made  # None once changed in place: the browser's picking is stale
        if made is not None and made[0].shape == pos.shape and np.array_equal(made[0], pos) \
                and np.array_equal(made[1], scales):
            return
        if self.grab is not None and self.dragging and len(self.grab.batched_positions) == len(pos):
            update_changed(self.grab, batched_positions=pos, batched_scales=scales)
            self._grab_made = None
            return
        if self.grab is not None and self.dragging:
            self._retired.append(self.grab)  # the drag lives on it until its release
        elif self.grab is not None:
            self.grab.remove()
        self._grabs_made += 1
        vertices, faces = _disc()
        self.grab = self.scene.add_batched_meshes_simple(
            f"{self.path}/grab{self._grabs_made}", vertices, faces, np.tile([1.0, 0.0, 0.0, 0.0], (len(pos), 1)),
            pos, batched_scales=scales, batched_colors=(255, 255, 255), opacity=0.0, side="double",
            cast_shadow=False, receive_shadow=False, lod="off")
        self._grab_made = (pos.copy(), scales.copy())
        assert self.events is not None  # the workspace's, given when there are points to grab
        self._bind(self.grab, self.events)

    def _draw(self) -> None:
        """The visible discs and rims, where ``uv`` says (none: hidden)."""
        if not self.keys:
            for node in (self.disc, self.rim):
                if node is not None:
                    update_changed(node, visible=False)
            return
        pos = placed(self.plane).world(self.uv, self.layer).astype(np.float32)
        rim_pos = pos + np.array([0.0, 0.0, 0.0002], np.float32)
        if self.disc is None:
            common = {"point_shape": "circle", "point_shading": "flat", "precision": "float32"}
            self.rim = self.scene.add_point_cloud(f"{self.path}/rim", rim_pos, np.zeros_like(self.colors),
                                                  point_size=RIM_PX * self.world_per_px, **common)
            self.disc = self.scene.add_point_cloud(f"{self.path}/disc", pos, self._shade(self.colors),
                                                   point_size=DISC_PX * self.world_per_px, **common)
            return
        update_changed(self.rim, points=rim_pos, colors=np.zeros_like(self.colors), visible=True)
        update_changed(self.disc, points=pos, colors=self._shade(self.colors), visible=True)

    def _shade(self, colors: np.ndarray) -> np.ndarray:
        """Colours at this kind's opacity (ghosts: mixed with grey)."""
        if self.opacity >= 1.0:
            return colors
        return (self.opacity * colors + (1 - self.opacity) * 90).astype(np.uint8)

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
        if self.disc is not None:
            self.disc.point_size, self.rim.point_size = DISC_PX * world_per_px, RIM_PX * world_per_px
        if self.grab is not None and self.keys:
            self._set_grab(*self._grab_layout(len(self.grab.batched_positions)))

    def move(self, index: int, uv) -> None:
        """Put point ``index`` at pixel ``uv`` (while it is dragged)."""
        if not 0 <= index < len(self.keys):
            return
        self.uv[index] = uv
        self._draw()
        if self.grab is not None:
            self._set_grab(*self._grab_layout(len(self.grab.batched_positions)))

    def _instance(self, index: int | None, at_uv) -> int | None:
        """The point an event is about: the instance viser reports if that point is where the
        pointer hit, else the point nearest the hit within reach. (The browser picks among the
        instances it drew; when another tab's edit reorders the points, instance ``i`` there can
        be another point here. viser also reports no instance at times for a mesh whose
        instances moved.)"""
        if at_uv is None or not np.all(np.isfinite(at_uv)):
            return index if index is not None and 0 <= index < len(self.keys) else None
        if not self.keys:
            return None
        reach = 1.5 * GRAB_PX * self.world_per_px / placed(self.plane).scale  # image pixels
        d = np.hypot(*(self.uv - at_uv).T)
        if index is not None and 0 <= index < len(self.keys) and d[index] <= reach:
            return index
        i = int(np.argmin(d))
        return i if d[i] <= reach else None

    def _bind(self, node, events: WorkspaceEvents) -> None:
        grabbed: dict = {}  # the drag in progress: key, where it was grabbed, the point's pixel then

        def hit(event):
            """(the point clicked or None, the pixel the click's ray meets the image at)."""
            o = np.asarray(event.ray_origin, float)
            at = placed(self.plane).pixel_on_ray(o, o + np.asarray(event.ray_direction))
            return self._instance(event.instance_index, at), at

        @node.on_click
        async def _(event) -> None:
            i = hit(event)[0]
            if i is not None:
                events.pick(Selection(self.kind, self.keys[i]))

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

        @node.on_drag
        async def _(event) -> None:
            phase = DragPhase(event.phase)
            if phase is DragPhase.START:
                at = placed(self.plane).pixel(event.start_position)
                exact = bool(np.all(np.isfinite(at)))
                if not exact:  # viser lost the instance it hit: where the pointer is, on screen
                    at = events.screen_to_pixel(np.asarray(event.end_screen_pos, float))
                i = self._instance(event.instance_index, at)
                if i is None:
                    return
                grabbed.update(key=self.keys[i], index=i, at=at, uv=self.uv[i].copy(), exact=exact)
                self.dragging = True
            if "key" not in grabbed:
                return
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
                while self._retired:
                    self._retired.pop().remove()
            events.drag(DragEvent(self.kind, key, phase, now))


class Workspace:
    """The image view of one tab, under scene path ``root``."""

    def __init__(self, scene, root: str, events: WorkspaceEvents):
        self.scene, self.root, self.events = scene, f"{root}/image_view", events
        self.plane: ImagePlane | None = None
        self.image_key: Hashable | None = None  # what the pixels on the plane are (the frame's stem)
        self.world_per_px = 0.01  # scene units per screen pixel at the current zoom
        self._slots: list[dict] = []  # image nodes: the frame shown, and frames sent ahead (hidden)
        self._clock = 0
        self._backdrop = None
        self._ring = self._pin_boxes = None
        self.pins: tuple[dict, Markers] = ({}, Markers())  # pinned id -> flagged, and where the keypoints are
        self._lines: dict[str, object] = {}
        self.points = {kind: _PointNodes(scene, f"{self.root}/{kind}", kind, layer, opacity, events)
                       for kind, layer, opacity in ((PointKind.KEYPOINTS, "keypoints", 1.0),
                                                    (PointKind.GHOSTS, "ghosts", 0.55),
                                                    (PointKind.LINE_POINTS, "keypoints", 1.0))}
        self._labels: dict[object, Any] = {}  # keypoint id -> label node (viser's)
        self._label_uv: dict[object, np.ndarray] = {}
        self._label_rank: dict[object, int] = {}
        self.selected: Selection | None = None
        self.also: list[Selection] = []  # more selected keypoints (Ctrl+click)
        self.on_points: Callable[[], None] | None = None  # the points or their grab size changed

    # ------------------------------------------------------------------ the frame
    def show_image(self, key: Hashable, image_rgb: np.ndarray | Callable[[], np.ndarray]) -> bool:
        """Show the frame ``key`` (its pixels, or a function that reads them when they are not
        in the browser yet). A frame preloaded with :meth:`preload` is shown at once, with no
        image sent. True if anything changed."""
        if key == self.image_key:
            return False
        slot = next((sl for sl in self._slots if sl["key"] == key), None)
        if slot is None:
            slot = self._load(key, image_rgb() if callable(image_rgb) else image_rgb)
        for sl in self._slots:
            if sl is not slot and sl["visible"]:
                sl["handle"].visible, sl["handle"].position, sl["visible"] = False, (0.0, 0.0, PLANE_Z + 50.0), False
        slot["handle"].position, slot["handle"].visible, slot["visible"] = (0.0, 0.0, PLANE_Z), True, True
        slot["used"] = self._clock = self._clock + 1
        if slot["plane"] != self.plane:
            self._frame_backdrop(slot["plane"])
        self.plane, self.image_key = slot["plane"], key
        return True

    def holds(self, key: Hashable) -> bool:
        """Whether frame ``key``'s pixels are in the browser already (shown or sent ahead)."""
        return any(sl["key"] == key for sl in self._slots)

    def preload(self, key: Hashable, image_rgb: Callable[[], np.ndarray]) -> None:
        """Send frame ``key``'s pixels ahead, hidden, so that going there shows them at once."""
        if all(sl["key"] != key for sl in self._slots):
            self._load(key, image_rgb())

    def _load(self, key: Hashable, image_rgb: np.ndarray) -> dict:
        """Pixels into a hidden slot (a new one while there are fewer than :data:`FRAME_SLOTS`,
        else the one shown longest ago)."""
        H, W = image_rgb.shape[:2]
        plane = ImagePlane(W, H)
        w, h = plane.extent
        if len(self._slots) < FRAME_SLOTS:
            handle = self.scene.add_image(f"{self.root}/frame{len(self._slots)}", image_rgb, w, h, format="jpeg",
                                          jpeg_quality=90, position=(0.0, 0.0, PLANE_Z + 50.0), visible=False,
                                          cast_shadow=False, receive_shadow=False)
            slot = {"handle": handle, "visible": False, "used": 0, "key": key, "plane": plane}
            self._bind_frame(handle)
            self._slots.append(slot)  # complete before anyone can see it
        else:
            slot = min((sl for sl in self._slots if not sl["visible"]), key=lambda sl: sl["used"])
            if slot["plane"] != plane:
                slot["handle"].render_width, slot["handle"].render_height = w, h
            slot["handle"].image = image_rgb
        slot.update(key=key, plane=plane)
        return slot

    def _frame_backdrop(self, plane: ImagePlane) -> None:
        """A dark frame around the image (one mesh of four quads, none under the image: no pixel
        is drawn twice) that pans the view when dragged, like the image itself."""
        w, h = plane.extent
        m = BACKDROP_MARGIN
        x0, x1, y0, y1 = -w / 2, w / 2, -h / 2, h / 2
        X0, X1, Y0, Y1 = x0 - m * w, x1 + m * w, y0 - m * h, y1 + m * h
        quads = [(X0, Y0, X1, y0), (X0, y1, X1, Y1), (X0, y0, x0, y1), (x1, y0, X1, y1)]  # top, bottom, left, right
        vertices = np.array([[[a, b, 0.0], [c, b, 0.0], [c, d, 0.0], [a, d, 0.0]] for a, b, c, d in quads])
        vertices = vertices.reshape(-1, 3)
        vertices[:, 2] = PLANE_Z + 0.01
        faces = np.array([[k, k + 1, k + 2] for k in range(0, 16, 4)] + [[k, k + 2, k + 3] for k in range(0, 16, 4)])
        if self._backdrop is None:
            self._backdrop = self.scene.add_mesh_simple(
                f"{self.root}/backdrop", vertices, faces, color=BACKDROP_RGB, material="toon3", side="double",
                flat_shading=True, cast_shadow=False, receive_shadow=False)
            self._bind_pan(self._backdrop)
        else:
            update_changed(self._backdrop, vertices=vertices.astype(np.float32))

    def _bind_frame(self, node) -> None:
        ev = self.events

        @node.on_click(modifier="shift")
        async def _(event) -> None:
            uv = self._clicked(event)
            if uv is not None:
                ev.place(uv)

        @node.on_click
        async def _(event) -> None:
            uv = self._clicked(event)
            if uv is not None:
                ev.click(uv)

        self._bind_pan(node)

    def _bind_pan(self, node) -> None:
        start: dict = {}

        @node.on_drag
        async def _(event) -> None:
            phase = DragPhase(event.phase)
            if phase is DragPhase.START:
                start["at"] = np.array(event.start_screen_pos, float)
            if "at" in start:
                self.events.pan(phase, start["at"], np.array(event.end_screen_pos, float))

    def _clicked(self, event) -> np.ndarray | None:
        if self.plane is None:
            return None
        return self.plane.pixel_on_ray(event.ray_origin, np.asarray(event.ray_origin) + np.asarray(event.ray_direction))

    # ------------------------------------------------------------------ overlays
    def show_overlay(self, overlay: Overlay, line_colors: dict[str, np.ndarray] | None = None, *,
                     keypoints: bool = True, ghosts: bool = True, line_points: bool = False, ids: bool = True) -> None:
        """Every layer of ``overlay`` updated in place (``line_colors``: colours per segment end,
        (N, 2, 3), e.g. blended towards the image for a lower opacity)."""
        plane = placed(self.plane)  # the frame is shown first
        for name in set(self._lines) | set(overlay.segments):
            seg = overlay.segments.get(name, Segments())
            handle = self._lines.get(name)
            if not len(seg):
                if handle is not None:
                    update_changed(handle, visible=False)
                continue
            pts = plane.world(seg.points, {"residuals": "residuals", "refined_pitch_casing": "casing"}.get(name, "pitch"))
            cols = line_colors[name] if line_colors and name in line_colors else np.repeat(seg.colors[:, None], 2, 1)
            if handle is None:
                self._lines[name] = self.scene.add_line_segments(f"{self.root}/lines/{name}", pts, cols,
                                                                 thickness=THICKNESS.get(name, 1.5),
                                                                 thickness_units="screen")
            else:
                update_changed(handle, points=pts, colors=cols, visible=True)
        shown = {PointKind.KEYPOINTS: overlay.keypoints if keypoints else Markers(),
                 PointKind.GHOSTS: overlay.ghosts if ghosts else Markers(),
                 PointKind.LINE_POINTS: overlay.line_points if line_points else Markers()}
        for kind, markers in shown.items():
            self.points[kind].show(markers, plane, self.world_per_px)
        observed, ghosted = shown[PointKind.KEYPOINTS], shown[PointKind.GHOSTS]
        labelled = [(k, uv, 0) for k, uv in zip(observed.keys, observed.uv)] if ids else []
        labelled += [(k, uv, 1) for k, uv in zip(ghosted.keys, ghosted.uv)] if ids else []
        self._show_labels(labelled)
        self.pins = ({k: k in overlay.flagged for k in overlay.pinned if k in observed.keys}, observed)
        self._show_pins()
        self._show_selection()
        if self.on_points is not None:
            self.on_points()

    def _show_pins(self) -> None:
        """A box around each pinned keypoint, black, orange where the camera cannot agree with it."""
        (pins, observed), handle = self.pins, self._pin_boxes
        if not pins or self.plane is None:
            if handle is not None:
                update_changed(handle, visible=False)
            return
        h = PIN_BOX_PX * self.world_per_px / self.plane.scale
        corners = np.array([[-h, -h], [h, -h], [h, h], [-h, h], [-h, -h]])
        segs, cols = [], []
        for k, flagged in pins.items():
            box = observed.uv[observed.keys.index(k)] + corners
            segs.append(np.stack([box[:-1], box[1:]], 1))
            cols.append(np.tile(np.array(FLAGGED_RGB if flagged else PIN_RGB, np.uint8), (4, 2, 1)))
        pts, colors = self.plane.world(np.concatenate(segs), "selection"), np.concatenate(cols)
        if handle is None:
            self._pin_boxes = self.scene.add_line_segments(f"{self.root}/pins", pts, colors, thickness=2.0,
                                                           thickness_units="screen")
        else:
            update_changed(handle, points=pts, colors=colors, visible=True)

    def _show_labels(self, labelled: list) -> None:
        wanted = {k: (np.asarray(uv, float), rank) for k, uv, rank in labelled}
        for k in [k for k in self._labels if k not in wanted]:
            self._labels.pop(k).remove()
            self._label_uv.pop(k, None)
            self._label_rank.pop(k, None)
        for k, (uv, rank) in wanted.items():
            pos = placed(self.plane).world(uv, "selection")
            text = f"{k}" if rank == 0 else f"{k}?"
            handle = self._labels.get(k)
            if handle is None:
                self._labels[k] = self.scene.add_label(f"{self.root}/ids/{k}", text, position=pos,
                                                       font_screen_scale=0.9, anchor="bottom-left")
            elif k not in self._label_uv or not np.allclose(self._label_uv[k], uv) or self._label_rank[k] != rank:
                handle.position, handle.text = pos, text
            self._label_uv[k], self._label_rank[k] = uv, rank
        self.declutter()

    def declutter(self) -> None:
        """Ids too close to an earlier one on screen at this zoom are hidden (observed before ghosts)."""
        if not self._labels:
            return
        keys = sorted(self._labels, key=lambda k: (self._label_rank[k], str(k)))
        uv = np.array([self._label_uv[k] for k in keys])
        px_per_image_px = placed(self.plane).scale / self.world_per_px
        keep = declutter(uv * px_per_image_px, LABEL_MIN_GAP_PX)
        for k, show in zip(keys, keep):
            handle = self._labels[k]
            if handle.visible != bool(show):
                handle.visible = bool(show)

    # ------------------------------------------------------------------ selection and zoom
    def select(self, selected: Selection | None, also=()) -> None:
        """Ring the selected point (and ``also``: more selected keypoints)."""
        self.selected, self.also = selected, list(also)
        self._show_selection()

    def _show_selection(self) -> None:
        where = []
        for sel in [self.selected, *self.also]:
            nodes = self.points.get(sel.kind) if sel is not None and self.plane is not None else None
            if nodes is not None and sel is not None and sel.key in nodes.keys:
                where.append(nodes.uv[nodes.keys.index(sel.key)])
        if not where:
            if self._ring is not None:
                update_changed(self._ring, visible=False)
            return
        radius = RING_PX * self.world_per_px / placed(self.plane).scale
        segments = [np.stack([c[:-1], c[1:]], 1) for c in (ring(uv, radius, 32) for uv in where)]
        pts = placed(self.plane).world(np.concatenate(segments), "selection")
        if self._ring is None:
            self._ring = self.scene.add_line_segments(f"{self.root}/selection", pts, SELECTED_RGB, thickness=2.0,
                                                      thickness_units="screen")
        else:
            update_changed(self._ring, points=pts, visible=True)

    def set_zoom(self, world_per_px: float) -> None:
        """The camera zoomed: points keep their size on screen, ids are decluttered again."""
        if self.world_per_px > 0 and abs(math.log(world_per_px / self.world_per_px)) < 0.05:
            return
        self.world_per_px = world_per_px
        for nodes in self.points.values():
            nodes.rescale(world_per_px)
        if self.plane is not None:
            self.declutter()
            self._show_pins()
            self._show_selection()
