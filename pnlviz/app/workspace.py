"""The image view of one tab. The page draws what you see (:mod:`pnlviz.app.pagesync` sends it
with the view): the frame's pixels behind viser's transparent canvas (sent once per frame:
:mod:`pnlviz.app.pageframes`), and over it the overlays, the points and the selection
(:attr:`Workspace.marks`, :mod:`pnlviz.app.pagedraw`) and the points' ids
(:attr:`Workspace.id_labels`); the dark frame around them is the page's background
(:data:`pnlviz.app.bridge.BACKDROP_RGB`). The scene holds only what the pointer hits, invisible:
a surface over the image and around it, and the points' grab meshes
(:class:`pnlviz.app.points.PointNodes`), left as they are while a point is dragged, so a drag in
progress is never cut short by a redraw, and sent after the overlays (:meth:`Workspace.sync_grabs`).

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
from pnlviz.app.overlay import FLAGGED_RGB, PIN_RGB, Markers, Overlay
from pnlviz.app.pagedraw import Mark, disc_marks, draw_text, segment_marks
from pnlviz.app.pageframes import FrameSlots
from pnlviz.app.points import DISC_PX, RIM_PX, DragRoute, PointNodes
from pnlviz.app.view2d import PLANE_Z, ImagePlane, placed

#: screen pixels: the radius of the selection ring
RING_PX = 11.0
PIN_BOX_PX = 8.5  #: screen pixels: half the side of the box around a pinned keypoint
#: the overlay's line layers, back to front (others after them, by name)
LINE_ORDER = ("finding_annotated", "refined_pitch_casing", "reference_pitch", "initial_pitch", "annotation",
              "detected_lines", "refined_pitch", "finding_expected", "residuals")
_LINE_RANK = {name: i for i, name in enumerate(LINE_ORDER)}
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
        self.pins: dict[int, bool] = {}  # the pinned keypoints shown -> flagged (drawn where their points are)
        self._line_marks: list[Mark] = []  # the overlay's lines, as the page draws them
        self._marks_text: str | None = None  # :attr:`marks_text`, until the next change
        self.points = {kind: PointNodes(scene, f"{self.root}/{kind}", kind, opacity, events)
                       for kind, opacity in ((PointKind.KEYPOINTS, 1.0), (PointKind.GHOSTS, 0.55),
                                             (PointKind.LINE_POINTS, 1.0))}
        for nodes in self.points.values():
            nodes.moved = self.changed  # a dragged point moves on the page at once
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
        self.changed()
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
    def show_overlay(self, overlay: Overlay, *, opacity: float = 1.0, keypoints: bool = True, ghosts: bool = True,
                     line_points: bool = False, ids: bool = True) -> None:
        """Every layer of ``overlay``, as the marks the page draws (``opacity``: the lines', over
        the image), and the points to grab (their grab meshes follow at :meth:`sync_grabs`)."""
        plane = placed(self.plane)  # the frame is shown first
        layers = sorted(overlay.segments, key=lambda n: (_LINE_RANK.get(n, len(_LINE_RANK)), n))
        self._line_marks = [m for name in layers
                            for m in segment_marks(overlay.segments[name].points, overlay.segments[name].colors,
                                                   THICKNESS.get(name, 1.5), opacity)]
        shown = {PointKind.KEYPOINTS: overlay.keypoints if keypoints else Markers(),
                 PointKind.GHOSTS: overlay.ghosts if ghosts else Markers(),
                 PointKind.LINE_POINTS: overlay.line_points if line_points else Markers()}
        for kind, markers in shown.items():
            self.points[kind].place(markers, plane, self.world_per_px)
        observed, ghosted = shown[PointKind.KEYPOINTS], shown[PointKind.GHOSTS]
        self.id_labels = []
        if ids:  # observed keypoints first (an occluded one's label is "(12)"), then the ghosts
            labelled = sorted(zip(observed.keys, observed.labels, observed.uv), key=lambda e: str(e[0]))
            labelled += sorted(((k, f"{k}?", uv) for k, uv in zip(ghosted.keys, ghosted.uv)), key=lambda e: str(e[0]))
            self.id_labels = [(text, float(uv[0]), float(uv[1])) for _, text, uv in labelled]
        self.pins = {k: k in overlay.flagged for k in overlay.pinned if k in observed.keys}
        self.changed()

    def sync_grabs(self) -> None:
        """The points' grab meshes where :meth:`show_overlay` put the points. Apart, because a
        message batch that holds scene nodes waits in the page for its next animation frame and
        mounts them before anything of it is shown, while one of panel elements only (the
        frame's pixels, its overlays and ids, the panel) is applied as it arrives: the tab sends
        this in a batch of its own, after the frame's."""
        for nodes in self.points.values():
            nodes.sync_grab()

    @property
    def marks(self) -> list[Mark]:
        """What the page draws over the frame, back to front: the lines (:data:`LINE_ORDER`), the
        ghosts, the keypoints and the points of annotated lines (each on a black rim), the boxes
        of the pinned keypoints and the selection rings."""
        out = list(self._line_marks)
        for kind in (PointKind.GHOSTS, PointKind.KEYPOINTS, PointKind.LINE_POINTS):
            nodes = self.points[kind]
            if nodes.keys:
                out += disc_marks(nodes.uv, nodes.shaded, DISC_PX, RIM_PX)
        observed = self.points[PointKind.KEYPOINTS]
        for rgb, flagged in ((PIN_RGB, False), (FLAGGED_RGB, True)):
            where = [observed.uv[observed.keys.index(k)] for k, f in self.pins.items() if f is flagged]
            if where:
                out.append(Mark("q", np.array(where), rgb, size=PIN_BOX_PX, width=2.0))
        rings = self._selected_uv()
        if len(rings):
            out.append(Mark("c", rings, SELECTED_RGB, size=RING_PX, width=2.0))
        return out

    @property
    def marks_text(self) -> str:
        """:attr:`marks` as the page reads them (:func:`pnlviz.app.pagedraw.draw_text`), written
        once per change: the page is told the view far more often than the marks change."""
        if self._marks_text is None:
            self._marks_text = draw_text(self.marks)
        return self._marks_text

    def changed(self) -> None:
        """Tell the page (the points moved, the overlays or the selection changed)."""
        self._marks_text = None
        if self.on_change is not None:
            self.on_change()

    # ------------------------------------------------------------------ selection and zoom
    def select(self, selected: Selection | None, also=()) -> None:
        """Ring the selected point (and ``also``: more selected keypoints)."""
        self.selected, self.also = selected, list(also)
        self.changed()

    def _selected_uv(self) -> np.ndarray:
        """Where the selected points are (image pixels)."""
        where = []
        for sel in [self.selected, *self.also]:
            nodes = self.points.get(sel.kind) if sel is not None else None
            if nodes is not None and sel is not None and sel.key in nodes.keys:
                where.append(nodes.uv[nodes.keys.index(sel.key)])
        return np.array(where, float).reshape(-1, 2)

    def set_zoom(self, world_per_px: float) -> None:
        """The camera zoomed: points keep their size on screen."""
        if self.world_per_px > 0 and abs(math.log(world_per_px / self.world_per_px)) < 0.05:
            return
        self.world_per_px = world_per_px
        for nodes in self.points.values():
            nodes.rescale(world_per_px)
