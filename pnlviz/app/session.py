"""One browser tab of the app: its own current frame, filter, settings, view, selection and
panel. The frame opens in the image view (:mod:`pnlviz.app.view2d`): the picture straight on,
zoomed and panned like an image, with the overlays and the points drawn over it as scene geometry
(:mod:`pnlviz.app.workspace`); the 3D view (the pitch, the camera's frustum) is one key away.

A tab is a few parts with one job each, which the :class:`Session` wires together: its queue
(:mod:`pnlviz.app.tabqueue`: everything the tab asks for runs there, one action at a time, in
the order the browser sent it), its frame order (:mod:`pnlviz.app.frameorder`), its camera
(:mod:`pnlviz.app.viewcontrol`), its edits (:mod:`pnlviz.app.editing`), its clip
(:mod:`pnlviz.app.playback`) and its drawing (:mod:`pnlviz.app.drawing`, with the panel's texts
from :mod:`pnlviz.app.cards`). Values from the browser are never trusted: dropdowns are checked
against their options, numbers against their ranges, and edits go through
:class:`pnlviz.app.state.AppState`, which validates ids and positions. A refused value is
reverted and shown to that tab only.
"""

from __future__ import annotations

import threading
from dataclasses import replace

from pnlviz.app.drawing import Painter, PainterTab
from pnlviz.app.bindings import bind
from pnlviz.app.editing import Editor, EditorTab
from pnlviz.app.frameorder import FrameOrder, visible_order
from pnlviz.app.host import TabHandle
from pnlviz.app.modes import Filter, Mode, Sort, labels
from pnlviz.app.pageframes import FrameSlots
from pnlviz.app.pagesync import PageSync
from pnlviz.app.panels import Panels
from pnlviz.app.playback import ClipPlayer, ClipWidgets
from pnlviz.app.scene import OVERVIEW, Scene3D, behind_camera
from pnlviz.app.state import SOURCES, FrameView, Settings
from pnlviz.app.tabqueue import ActionGuard, TabQueue
from pnlviz.app.viewcontrol import ViewControl
from pnlviz.app.modes import WorkspaceEvents
from pnlviz.app.workspace import Workspace


class Session:
    """The panel and scene nodes of one tab (``gui``/``scene`` of its viser client), or of the
    server itself when ``client`` is None (a session without a browser, for scripts and tests)."""

    def __init__(self, app, gui, scene, client=None) -> None:
        self.app, self.state = app, app.state
        self.gui, self.scene, self.client = gui, scene, client
        st = self.state
        self.settings: Settings = st.default_settings
        self.sources = SOURCES if st.predictions is not None else ("annotation",)
        self.lock = threading.RLock()

        def notify(title: str, body: str, error: bool = True) -> None:
            self.notify(title, body, error)  # looked up on each call: a script may redirect a tab's messages

        self.frames = FrameOrder(len(st.stems), st.first_index)
        self.queue = TabQueue(notify, app.server.get_event_loop, app.state.activity)
        handle = TabHandle(index=lambda: self.index, settings=lambda: self.settings, goto=self.goto, show=self.show,
                           notify=notify)
        atomic = (lambda: client.atomic()) if client is not None else (lambda: app.server.atomic())
        self.painter = Painter(PainterTab(
            state=st, handle=handle, queue=self.queue, lock=self.lock, frames=self.frames, atomic=atomic,
            detection_status=app.detection_status,
            parts=lambda: (self.editor, self.panels, self.workspace, self.view_control, self.scene3d, self.clip,
                           self.guard)))
        self.guard = ActionGuard(notify, self.show, lambda: self.painter.drawn)
        self.editor = Editor(EditorTab(
            state=st, handle=handle, queue=self.queue, guard=self.guard, frames=self.frames,
            advance_from=self.advance_from, parts=lambda: (self.painter, self.panels, self.workspace, self.view_control)))
        self.clip = ClipPlayer(handle, st.clips, stems=st.stems, shots=st.shots, summaries=st.triage.lookup,
                               queue=self.queue)
        #: where this tab's scene nodes live: a client's own scene, or (without a browser, on the
        #: server's shared scene) a branch of its own
        nodes = "/tab" if client is not None else f"/tab/session-{id(self):x}"
        events = WorkspaceEvents(
            place=self.editor.on_place, click=self.editor.on_click, pick=self.editor.on_pick,
            pick_more=lambda p: self.queue.enqueue(lambda: self.editor.add_to_selection(p)), drag=self.editor.drag,
            pan=lambda phase, start, now: self.queue.enqueue(lambda: self.view_control.pan(phase, start, now)),
            screen_to_pixel=lambda fractions: self.view_control.to_pixel(fractions))
        self.workspace = Workspace(scene, nodes, events)
        self.view_control = ViewControl(self.workspace, client, self.painter.show_zoom, self.editor.nudge,
                                        self.queue.enqueue)
        self.view_control.on_box = self.editor.select_in_box
        self.scene3d = Scene3D(scene, nodes)
        self.panels = Panels(gui, self.queue, notify, st.model, clips=st.clips, splits=st.ds.splits,
                             layers=self.painter.layers, settings=self.settings, sources=self.sources)
        bind(self)
        if self.panels.clip_text is not None:  # a dataset with clips: the panel shows the tab's clip
            self.clip.widgets = ClipWidgets(self.panels.clip_text, self.panels.clip_strip, self.panels.clip_slider)
        self.panels.set_order(len(self.frames.order), self.index)
        self.queue.busy = self.panels.set_busy  # a cue over the image while an action takes long
        #: the image view as the page's bridge needs it (pans and zooms in the page: pnlviz.app.pagesync)
        self.page = PageSync(gui, self.workspace, self.view_control) if client is not None else None
        if self.page is not None:
            self.workspace.frames = FrameSlots(gui)  # the frame's pixels, drawn by the page
            self.workspace.on_change = self.page.sync
        if client is not None:
            client.camera.on_update(self.view_control.on_camera)
            client.scene.configure_default_lights(True, cast_shadow=False)  # no shadow pass on every frame

    @property
    def index(self) -> int:
        """The dataset index of the tab's frame."""
        return self.frames.index

    @property
    def stem(self) -> str:
        return self.state.stems[self.frames.index]

    def view(self) -> FrameView:
        """The tab's frame as it shows it: a clip frame under its shot model (unless the clip
        panel's toggle shows the frame's own camera), any other frame its own view."""
        view = self.state.view(self.stem, self.settings)
        if self.clip.shot_model and self.index in self.clip.clip_of:
            view = self.state.shots.shot_view(view, self.settings)
        return view

    def notify(self, title: str, body: str, error: bool = True) -> None:
        """A notification in this tab (printed when the session has no browser)."""
        if self.client is None:
            print(f"pnlviz: {title}: {body}")
            return
        self.client.add_notification(title, body, auto_close_seconds=8.0, color="red" if error else None)

    def show(self, panel: bool = True) -> FrameView | None:
        """Recompute (or fetch from the cache) this tab's frame and send what changed to this tab
        (without ``panel``: the picture and its overlays, the panel left as it is)."""
        with self.lock:
            if self.queue.closed:
                return None
            if self.state.needs_detection(self.stem):
                self.app.detect_in_background(self.stem)
            view = self.view()
            self.painter.draw(view, panel=panel)
            return view

    def flush(self, timeout: float = 30.0) -> None:
        """Wait until every action sent to this tab so far has run (:meth:`TabQueue.flush`)."""
        self.queue.flush(timeout)

    # ------------------------------------------------------------------ navigation
    def goto(self, index: int) -> None:
        with self.lock:
            index = self.frames.clamp(index)
            if index != self.frames.index:
                self.editor.selected = None
            self.frames.index = index
            self.panels.set_order(len(self.frames.order), self.frames.position())
            self.show()

    def step(self, delta: int) -> None:
        with self.lock:
            self.goto(self.frames.stepped(delta))

    def slider_moved(self, value) -> None:
        with self.lock:
            index = self.frames.at(value, first=1)  # the slider counts from 1
            if index != self.frames.index:  # not an echo of goto() moving the slider
                self.goto(index)

    def jump(self, text) -> None:
        idx = self.state.find(str(text)[:200])
        if idx is not None:
            self.goto(idx)

    def set_filter(self, value) -> None:
        self.frames.filter = Filter(self.panels.choice(self.panels.filter, labels(Filter), Filter.ALL.value))
        self.refresh_order()

    def set_split(self, value) -> None:
        """A dataset in splits: step through one split ("all": every split)."""
        splits = self.state.ds.splits
        self.frames.split = value if value in splits else ""
        self.refresh_order()

    def set_sort(self, value) -> None:
        self.frames.sort = Sort(self.panels.choice(self.panels.sort, labels(Sort), Sort.INDEX.value))
        self.refresh_order(first=self.frames.sort is not Sort.INDEX)

    def _visible_order(self) -> list[int]:
        st = self.state
        summaries = st.triage.summaries(self.settings)
        return visible_order(st.stems, summaries, st.edits.review, self.frames.filter, self.frames.sort,
                             self.frames.split)

    def refresh_order(self, first: bool = False) -> None:
        """The frames of the filter, in the chosen order; the tab stays on its frame if it is one
        of them (unless ``first``: a sort was chosen, its first frame is shown), else goes to the
        first (with no match it stays, and says so)."""
        with self.lock:
            index = self.frames.refreshed(self._visible_order(), first)
            if self.frames.outside_filter:
                self.notify("no match", f"no frame matches the filter '{self.frames.filter_label()}'", error=False)
            self.goto(index)

    def advance_from(self, stem: str) -> None:
        """Go to the frame after ``stem`` in the filter's order."""
        with self.lock:
            index, ended = self.frames.after(self.state.index_of(stem), self._visible_order())
            if ended:
                self.notify("end of the filter", f"{stem} was the last frame of '{self.frames.filter_label()}'",
                            error=False)
            self.goto(index)

    # ------------------------------------------------------------------ calibration settings
    def set_pnl(self, value) -> None:
        self.settings = replace(self.settings, pnl=bool(value))
        self.show()

    def set_alpha(self, value) -> None:
        try:
            self.settings = replace(self.settings, alpha=float(value))
        except (TypeError, ValueError) as exc:
            self.notify("refused", str(exc))
            self.queue.set_value(self.panels.alpha, self.settings.alpha)
        self.show()

    def set_source(self, value) -> None:
        source = self.panels.choice(self.panels.source, self.sources, self.settings.source)
        self.settings = replace(self.settings, source=source)
        self.show()

    # ------------------------------------------------------------------ image view <-> 3D view
    def toggle_mode(self) -> None:
        self.set_mode(self.view_control.mode.other)

    def set_mode(self, mode: Mode) -> None:
        if mode is self.view_control.mode:
            return
        self.view_control.mode = mode
        self.panels.set_mode(mode)
        if mode is Mode.THREE_D:
            view = self.show()
            self.view_control.look_3d(behind_camera(view.camera) if view is not None and view.camera is not None
                                      else OVERVIEW)
        else:
            self.scene3d.hide()
            self.show()
            self.view_control.restore()

    # ------------------------------------------------------------------ export and end
    def export(self) -> None:
        from pnlviz.app.export import export_zip_bytes

        if self.client is not None:
            st = self.state
            self.client.send_file_download(f"{st.data.name}_labels.zip", export_zip_bytes(st),
                                           save_immediately=True)

    def close(self, wait: bool = False) -> None:
        """The tab is gone: stop drawing (its GUI and scene nodes went with its connection). Edits
        already released still go through; ``wait``: until they have (the server stopping)."""
        with self.lock:
            self.queue.closed = True
        self.queue.close(wait=wait)


__all__ = ["Session"]
