"""The image view's scene nodes for one tab: the overlays as line segments over the frame, and the
points you grab (observed keypoints, ghosts of the missing ones, points of annotated lines) as
batched discs. Every node is created once and then updated in place, so an edit sends only what
changed and a drag in progress is never cut short by a redraw. The frame's pixels are drawn by the
page behind the transparent canvas (sent once per frame: :mod:`pnlviz.app.pageframes`), the
points' ids by the page over it (:attr:`Workspace.id_labels`, sent with the view:
:mod:`pnlviz.app.pagesync`), and the dark frame around them is the page's background
(:data:`pnlviz.app.bridge.BACKDROP_RGB`); in the scene, invisible surfaces there take the pointer.

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
from pnlviz.app.modes import PointKind, Selection, WorkspaceEvents
from pnlviz.app.overlay import FLAGGED_RGB, PIN_RGB, Markers, Overlay, Segments
from pnlviz.app.pageframes import FrameSlots
from pnlviz.app.points import DragRoute, PointNodes
from pnlviz.app.view2d import PLANE_Z, ImagePlane, placed
from pnlviz.viz import ring

#: screen pixels: the radius of the selection ring
RING_PX = 11.0
PIN_BOX_PX = 8.5  #: screen pixels: half the side of the box around a pinned keypoint
#: screen thickness of each layer's lines
THICKNESS = {"refined_pitch": 2.0, "refined_pitch_casing": 4.5, "initial_pitch": 1.5, "reference_pitch": 1.5, "annotation": 2.0,
             "detected_lines": 2.0, "residuals": 1.5, "finding_annotated": 5.0, "finding_expected": 2.0}
BACKDROP_MARGIN = 6.0  # the pick surface around the image: this many image widths (heights) each side
SELECTED_RGB = (255, 255, 255)
#: CSS px: an id closer than this on screen to one before it is hidden (sent with the ids: the page
#: applies it at every zoom, ``pageframes.js``)
LABEL_MIN_GAP_PX = 16.0


class Workspace:
    """The image view of one tab, under scene path ``root``."""

    def __init__(self, scene, root: str, events: WorkspaceEvents):
        self.scene, self.root, self.events = scene, f"{root}/image_view", events
        self.world_per_px = 0.01  # scene units per screen pixel at the current zoom
        #: the frames' pixels in the page (:mod:`pnlviz.app.pageframes`; a tab with a browser gives
        #: it the panel to send them through)
        self.frames = FrameSlots()
        self._pick: dict[str, Any] = {}  # the invisible surfaces the pointer hits: "frame", "backdrop"
        self._ring = self._pin_boxes = None
        self.pins: tuple[dict, Markers] = ({}, Markers())  # pinned id -> flagged, and where the keypoints are
        self._lines: dict[str, object] = {}
        self.points = {kind: PointNodes(scene, f"{self.root}/{kind}", kind, layer, opacity, events)
                       for kind, layer, opacity in ((PointKind.KEYPOINTS, "keypoints", 1.0),
                                                    (PointKind.GHOSTS, "ghosts", 0.55),
                                                    (PointKind.LINE_POINTS, "keypoints", 1.0))}
        #: the ids the page writes next to the points, ``(text, u, v)`` in image pixels, observed
        #: keypoints first, then ghosts ("12?"), each in id order: the page hides one too close to
        #: one before it. Viser's labels cost a scene node each (three messages per id on every
        #: frame change, and a slow tail of the next frame's latency)
        self.id_labels: list[tuple[str, float, float]] = []
        self.selected: Selection | None = None
        self.also: list[Selection] = []  # more selected keypoints (Ctrl+click)
        #: what the page is told changed: the frame shown, the points or their grab size
        self.on_change: Callable[[], None] | None = None

    # ------------------------------------------------------------------ the frame
    @property
    def image_key(self) -> Hashable | None:
        """The frame shown (its stem), None before the first."""
        return self.frames.shown_key

    @property
    def plane(self) -> ImagePlane | None:
        """Where the frame shown sits in the scene, None before the first."""
        return self.frames.shown_plane

    def show_image(self, key: Hashable, image_bgr: np.ndarray | Callable[[], np.ndarray]) -> bool:
        """Show the frame ``key`` (its pixels, BGR as the frame reader gives them, or a function
        that reads them when they are not in the page yet). A frame preloaded with
        :meth:`preload` is shown at once, with no image sent. True if anything changed."""
        if key == self.image_key:
            return False
        before = self.plane
        plane = self.frames.show(key, image_bgr)
        if plane != before:
            self._pick_surfaces(plane)
        if self.on_change is not None:
            self.on_change()
        return True

    def holds(self, key: Hashable) -> bool:
        """Whether frame ``key``'s pixels are in the page already (shown or sent ahead)."""
        return self.frames.holds(key)

    def preload(self, key: Hashable, image_bgr: Callable[[], np.ndarray]) -> None:
        """Send frame ``key``'s pixels ahead, hidden, so that going there shows them at once."""
        self.frames.preload(key, image_bgr)

    def _pick_surfaces(self, plane: ImagePlane) -> None:
        """What the pointer hits in the scene: a quad where the image is (the page draws the
        pixels behind the canvas) and, around it, a mesh of four quads. A press there near a point
        whose grab mesh the browser's pick missed, or a drag, is routed as one on the image is (a
        point just outside the frame is still dragged). Both are invisible wireframes: the
        browser's pick tests their triangles while drawing fills only a few edges (filled, the
        mesh around the image cost 13-17 ms of every software-WebGL frame)."""
        w, h = plane.extent
        m = BACKDROP_MARGIN
        x0, x1, y0, y1 = -w / 2, w / 2, -h / 2, h / 2
        X0, X1, Y0, Y1 = x0 - m * w, x1 + m * w, y0 - m * h, y1 + m * h
        around = [(X0, Y0, X1, y0), (X0, y1, X1, Y1), (X0, y0, x0, y1), (x1, y0, X1, y1)]  # top, bottom, left, right
        for name, quads, depth in (("frame", [(x0, y0, x1, y1)], 0.0), ("backdrop", around, 0.01)):
            vertices = np.array([[[a, b, 0.0], [c, b, 0.0], [c, d, 0.0], [a, d, 0.0]] for a, b, c, d in quads])
            vertices = vertices.reshape(-1, 3).astype(np.float32)
            vertices[:, 2] = PLANE_Z + depth
            n = 4 * len(quads)
            faces = np.array([[k, k + 1, k + 2] for k in range(0, n, 4)] + [[k, k + 2, k + 3] for k in range(0, n, 4)])
            node = self._pick.get(name)
            if node is None:
                self._pick[name] = node = self.scene.add_mesh_simple(
                    f"{self.root}/{name}", vertices, faces, wireframe=True, opacity=0.0, side="double",
                    cast_shadow=False, receive_shadow=False)
                (self._bind_frame if name == "frame" else self._bind_pan)(node)
            else:
                update_changed(node, vertices=vertices)

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
        """A drag of the image (or of the backdrop) pans the view, unless it starts on a point:
        the page leaves a press near a point to viser, whose pick can miss a grab mesh made anew
        (another tab's edit redraws the points) and find the image: the point is dragged all the
        same (a pan there lost the drag)."""
        route = DragRoute(lambda: self.points.values(), self.events.pan)

        @node.on_drag
        async def _(event) -> None:
            route(event)

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
        self.id_labels = []
        if ids:  # observed keypoints first (an occluded one's label is "(12)"), then the ghosts
            labelled = sorted(zip(observed.keys, observed.labels, observed.uv), key=lambda e: str(e[0]))
            labelled += sorted(((k, f"{k}?", uv) for k, uv in zip(ghosted.keys, ghosted.uv)), key=lambda e: str(e[0]))
            self.id_labels = [(text, float(uv[0]), float(uv[1])) for _, text, uv in labelled]
        self.pins = ({k: k in overlay.flagged for k in overlay.pinned if k in observed.keys}, observed)
        self._show_pins()
        self._show_selection()
        if self.on_change is not None:
            self.on_change()

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
        """The camera zoomed: points keep their size on screen."""
        if self.world_per_px > 0 and abs(math.log(world_per_px / self.world_per_px)) < 0.05:
            return
        self.world_per_px = world_per_px
        for nodes in self.points.values():
            nodes.rescale(world_per_px)
        if self.plane is not None:
            self._show_pins()
            self._show_selection()
