"""Drawing one tab: its frame's image (and the frames either side of it sent ahead), the overlays
and points over it (the label-error finder's findings among them), the
panel's texts, and in the 3D view the camera over the pitch. Only what changed is sent
(:func:`pnlviz.app.workspace.update_changed`), inside one message batch per draw.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar

import cv2
import numpy as np

from pnlviz.app import cards
from pnlviz.app.frameorder import sort_key_text
from pnlviz.app.modes import DragMode, Mode
from pnlviz.app.overlay import Layers, Overlay, overlay_geometry, render
from pnlviz.app.panels import LAYERS
from pnlviz.app.state import FrameView
from pnlviz.app.handles import update_changed
from pnlviz.app.host import Part, TabPart
from pnlviz.viz import blank_canvas, top_view

if TYPE_CHECKING:
    from pnlviz.app.frameorder import FrameOrder
    from pnlviz.app.panels import Panels
    from pnlviz.app.playback import ClipPlayer
    from pnlviz.app.scene import Scene3D
    from pnlviz.app.state import AppState
    from pnlviz.app.tabqueue import ActionGuard, TabQueue
    from pnlviz.app.viewcontrol import ViewControl
    from pnlviz.app.workspace import Workspace

TOP_PX_PER_M = 3.0  # the bird's-eye view in the panel: about 350 px wide


#: marks the title for the page script, which pins it to the top of the scrolling panel
TITLE_ANCHOR = '<span id="pnlviz-title"></span>'


@dataclass(frozen=True)
class PainterTab(TabPart):
    """What a tab's painter uses of its tab, and nothing else: the session's ``state``, the tab's
    ``queue``, ``lock`` and frame order (``frames``), its frame (``handle``), one message batch to
    the tab's browser (``atomic()``), a frame's detector status (``detection_status(stem)``) and
    the parts it draws for, made after it (``parts()``: the editor, the panel, the workspace, the
    view control, the 3D view, the clip player and the action guard, in this order)."""

    state: AppState
    queue: TabQueue
    lock: threading.RLock
    frames: FrameOrder
    atomic: Callable[[], Any]
    detection_status: Callable[[str], str | None]
    parts: Callable[[], tuple]

    editor: ClassVar[Part[Any]] = Part(0)  # its selection, place id and drag mode (the editor's module imports this one)
    panels: ClassVar[Part[Panels]] = Part(1)
    workspace: ClassVar[Part[Workspace]] = Part(2)
    view_control: ClassVar[Part[ViewControl]] = Part(3)
    scene3d: ClassVar[Part[Scene3D]] = Part(4)
    clip: ClassVar[Part[ClipPlayer]] = Part(5)
    guard: ClassVar[Part[ActionGuard]] = Part(6)


class Painter:
    """What one tab shows: ``shown`` the view drawn last, ``overlay`` its overlays, ``drawn`` how
    many times the tab was drawn; ``layers`` and ``opacity`` how the overlays are drawn. ``tab``:
    what it uses of its tab (:class:`PainterTab`), not the tab itself."""

    def __init__(self, tab: PainterTab) -> None:
        self.tab = tab
        self.layers = Layers()
        self.opacity = 1.0
        self._top_key: tuple | None = None  # what the panel's bird's-eye view was drawn from
        self._judged: tuple[FrameView, list] | None = None  # the last view judged and its findings' marks
        self._judging: FrameView | None = None  # a view whose verdict is queued
        self._grabs_queued = False  # the grab meshes' sync is on the tab's queue
        self.shown: FrameView | None = None
        self.overlay: Overlay | None = None
        self.drawn = 0

    @property
    def shown_stem(self) -> str:
        """The frame on the tab's screen (the tab's frame until it is first drawn)."""
        return self.shown.stem if self.shown is not None else self.tab.stem

    def draw(self, view: FrameView, panel: bool = True) -> None:
        """``view`` on the tab: image, overlays, panel (unless not ``panel``), and the 3D view when
        it is open."""
        tab = self.tab
        self.shown = view
        self.drawn += 1
        with self._atomic():
            self.show_image(view)
            self.show_overlay(view)
            if panel:
                self.show_panel(view)
            if tab.view_control.mode is Mode.THREE_D:
                tab.scene3d.show(view, render(view, tab.state.image(view.stem), self.layers,
                                              findings=self.findings(view)))

    def _atomic(self):
        return self.tab.atomic()

    # ------------------------------------------------------------------ settings
    def set_layer(self, name: str, value) -> None:
        if name in LAYERS:
            setattr(self.layers, name, bool(value))
            self.tab.show()

    def set_opacity(self, value) -> None:
        try:
            value = float(value)
        except (TypeError, ValueError):
            value = 1.0
        self.opacity = float(np.clip(value if math.isfinite(value) else 1.0, 0.1, 1.0))
        self.tab.show()

    # ------------------------------------------------------------------ the image
    def pixels(self, stem: str) -> np.ndarray:
        """The frame as the browser shows it: its image (BGR, as read), or a neutral canvas of its
        size."""
        image = self.tab.state.image(stem)
        return image if image is not None else blank_canvas(*self.tab.state.frame_size(stem))

    def show_image(self, view: FrameView) -> None:
        workspace = self.tab.workspace
        before = workspace.plane
        if workspace.show_image(view.stem, lambda: self.pixels(view.stem)):
            self.tab.queue.enqueue(self.preload_neighbours)
        self.tab.view_control.frame_placed(before)

    def preload_neighbours(self) -> None:
        """Send the frames before and after this one (in the filter's order) ahead, hidden, and
        calibrate the next one."""
        tab = self.tab
        with tab.lock:
            frames = tab.frames
            if tab.queue.closed or frames.index not in frames.order:
                return
            pos = frames.order.index(frames.index)
            stems = [tab.state.stems[frames.order[p]] for p in (pos + 1, pos - 1) if 0 <= p < len(frames.order)]
            ahead = tab.state.stems[frames.order[pos + 1]] if pos + 1 < len(frames.order) else None
            settings = tab.settings
        for stem in stems:  # the pixels are read outside the lock, the scene changed under it
            with tab.lock:
                if tab.queue.closed or tab.workspace.holds(stem):
                    continue
            pixels = self.pixels(stem)
            with tab.lock:
                if not tab.queue.closed:
                    tab.workspace.preload(stem, lambda: pixels)  # read at once, inside preload
        if ahead is not None and not tab.queue.closed:
            # the next frame calibrated ahead too (the state keeps the view): "next" only draws it
            tab.state.view(ahead, settings)

    # ------------------------------------------------------------------ overlays
    def hidden_ids(self, stem: str) -> set[int]:
        """The keypoints marked not visible on ``stem``."""
        kps = self.tab.state.edits.get(stem).get("keypoints") or {}
        return {int(k) for k, v in kps.items() if v is None}

    def findings(self, view: FrameView) -> list:
        """The label-error finder's findings on ``view`` as marks to draw
        (:func:`pnlviz.calib.qa.finding_marks`; judged once per view, not at all when the background
        pass judged the same inputs clean): none when the findings layer is off, or for a frame
        without an annotation. A frame not judged yet is drawn without them and judged right after,
        on the tab's queue: its findings are drawn then (judging takes one to 26 calibrations,
        which the frame does not wait for)."""
        if not self.layers.findings:
            return []
        if self._judged is None or self._judged[0] is not view:
            from pnlviz.app.triage import NOT_JUDGED, judge_view

            summary = self.tab.state.triage.lookup(view.stem, self.tab.settings)
            qa = None
            if summary is None or summary.suspect is None or summary.suspect >= 1.0:  # else: judged clean
                try:
                    qa = judge_view(view, judge=False)
                except Exception:  # noqa: BLE001 - a bug in the finder must not stop the frame being shown
                    qa = None
                if qa is NOT_JUDGED:
                    if self._judging is not view:  # once per view, however often it is asked meanwhile
                        self._judging = view
                        self.tab.queue.enqueue(lambda: self._judge_shown(view))
                    return []
            self._remember(view, qa)
        assert self._judged is not None  # remembered just now, or before for this view
        return self._judged[1]

    def _remember(self, view: FrameView, qa) -> list:
        """The marks of the finder's verdict ``qa`` on ``view`` (none without one), kept for it."""
        from pnlviz.calib.qa import finding_marks

        marks = finding_marks(qa, view.annotation or {}, view.size, self.tab.state.model) if qa else []
        self._judged = (view, marks)
        return marks

    def _judge_shown(self, view: FrameView) -> None:
        """``view`` judged by the label-error finder, and its findings drawn when it is still the
        frame shown (a frame left meanwhile is judged by the background pass in its turn)."""
        from pnlviz.app.triage import judge_view

        if self._judging is view:
            self._judging = None
        if self.shown is not view or self.tab.queue.closed:
            return
        try:
            qa = judge_view(view)
        except Exception:  # noqa: BLE001 - a bug in the finder must not stop the frame being shown
            return
        with self.tab.lock:
            if self.shown is not view:
                return
            if self._remember(view, qa):
                with self._atomic():
                    self.show_overlay(view)
                    self.show_card(view)

    def show_overlay(self, view: FrameView, preview: bool = False) -> None:
        """The overlays of ``view``; a ``preview`` (while a point is dragged) is not kept as the
        frame's overlay, nor judged by the label-error finder (its findings are drawn again when
        the point is let go)."""
        tab = self.tab
        overlay = overlay_geometry(view, self.layers, tab.state.model, hidden=self.hidden_ids(view.stem),
                                   findings=() if preview else self.findings(view),
                                   occluded=set(tab.state.edits.get(view.stem).get("occluded") or ()))
        tab.workspace.show_overlay(overlay, opacity=self.opacity, keypoints=self.layers.keypoints,
                                   ghosts=self.layers.ghosts, ids=self.layers.ids,
                                   line_points=tab.editor.drag_mode is DragMode.LINE_POINTS)
        if not self._grabs_queued:
            self._grabs_queued = True
            tab.queue.enqueue(self._sync_grabs)
        if not preview:
            self.overlay = overlay

    def _sync_grabs(self) -> None:
        """The points' grab meshes, as the tab's next action: in a message batch after the one
        that shows the overlays (:meth:`pnlviz.app.workspace.Workspace.sync_grabs` says why).
        A press that comes before them takes the point nearest it all the same."""
        self._grabs_queued = False
        with self.tab.lock:
            if not self.tab.queue.closed:
                with self._atomic():
                    self.tab.workspace.sync_grabs()

    # ------------------------------------------------------------------ the panel
    def show_panel(self, view: FrameView) -> None:
        tab, p = self.tab, self.tab.panels
        st, frames = tab.state, tab.frames
        flt, n = frames.filter_label(), len(frames.order)
        position = frames.position() + 1 if frames.index in frames.order else 0
        key = sort_key_text(frames.sort, st.triage.lookup(view.stem, tab.settings))
        update_changed(p.title, content=cards.title_text(view, position, n, frames.outside_filter, flt, key)
                       + TITLE_ANCHOR)  # the page keeps the title at the top of the panel (bridge.js)
        update_changed(p.status, content=cards.status_line(view, st.edits.review(view.stem), st.edits.get(view.stem),
                                                           tab.guard.save_error, tab.detection_status(view.stem)))
        update_changed(p.filter_text, content=cards.filter_text(view.stem, n, frames.outside_filter, flt))
        self.show_card(view)
        note = st.edits.get(view.stem).get("note") or ""
        if p.note.value != note:
            tab.queue.set_value(p.note, note)  # the frame's note (not an edit of it)
        self.show_points_list(view)
        self.show_selected()
        self.show_progress()
        self.show_top_view(view)
        tab.clip.show()

    def show_card(self, view: FrameView) -> None:
        """The frame's calibration card, its label-error findings under it."""
        update_changed(self.tab.panels.card, content=cards.calibration_card(view, self.tab.state)
                       + cards.findings_text(self.findings(view)))

    def show_top_view(self, view: FrameView) -> None:
        """The bird's-eye view under the frame's card: its camera's footprint and its keypoints put
        on the pitch (drawn again only when the camera or the keypoints change). Drawn as the tab's
        next action, after the frame's batch: the picture and its overlays reach the page first
        (the view costs 10-20 ms, and a shot's edit redraws every tab on the shot)."""
        cam = view.camera
        obs = view.observations
        kps = {int(k): tuple(xy) for k, xy in zip(obs.kp_ids, obs.kp_xy)} if obs is not None and cam else {}
        key = (None if cam is None else (cam.C.tobytes(), cam.R.tobytes(), cam.fx, cam.fy), sorted(kps.items()))
        if key != self._top_key:
            self._top_key = key
            self.tab.queue.enqueue(lambda: self._draw_top_view(key, cam, kps))

    def _draw_top_view(self, key: tuple, cam, kps: dict) -> None:
        # not when a later camera's view is on its way, nor for a tab that has gone
        if key == self._top_key and not self.tab.queue.closed:
            image = top_view(cam, keypoints=kps, px_per_m=TOP_PX_PER_M)
            self.tab.panels.top_view.image = cv2.cvtColor(image, cv2.COLOR_BGR2RGB)

    def show_points_list(self, view: FrameView) -> None:
        rows = cards.point_rows(self.overlay, self.hidden_ids(view.stem))
        p = self.tab.panels.points
        if tuple(p.options) != tuple(rows):
            p.options = rows
        if p.value not in rows:
            self.tab.queue.set_value(p, "-")

    def show_selected(self) -> None:
        tab = self.tab
        text = cards.selected_text(tab.editor.selected, self.overlay, tab.state.model, tab.editor.place_id,
                                   [s.kid for s in tab.editor.also])
        update_changed(tab.panels.selected, content=text)

    def show_progress(self) -> None:
        st, p = self.tab.state, self.tab.panels
        done, total = sum(st.edits.counts().values()), len(st.stems)
        update_changed(p.progress, value=100.0 * done / total)
        update_changed(p.progress_text, content=cards.progress_text(done, total, st.edits.counts()))

    def show_zoom(self, view2d) -> None:
        self.tab.panels.zoom_text.content = cards.zoom_text(view2d.zoom)


__all__ = ["Painter"]
