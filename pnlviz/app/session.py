"""One browser tab of the app: its own current frame, filter, settings, view, selection and
panel. The frame opens in the image view (:mod:`pnlviz.app.view2d`): the picture straight on,
zoomed and panned like an image, with the overlays and the points drawn over it as scene geometry
(:mod:`pnlviz.app.workspace`); the 3D view (the pitch, the camera's frustum) is one key away.

Everything a tab asks for runs on its own queue, one action at a time, in the order the browser
sent it. Every edit names the frame it was made on (captured when the pointer went down), so a
drag released after the tab moved on still lands on its own frame. Values from the browser are
never trusted: dropdowns are checked against their options, numbers against their ranges, and
edits go through :class:`pnlviz.app.state.AppState`, which validates ids and positions. A
refused value is reverted and shown to that tab only.
"""

from __future__ import annotations

import asyncio
import math
import threading
import time
import traceback
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace

import numpy as np

from pnlviz.app.bridge import parse_pointer
from pnlviz.app.overlay import Layers, Overlay, overlay_geometry, render
from pnlviz.app.panels import DRAG_MODES, FILTERS, KEYPOINT_CHOICES, LAYERS, SORTS, Panels
from pnlviz.app.scene import OVERVIEW, Scene3D, behind_camera
from pnlviz.app.state import REVIEW_STATES, SOURCES, AppState, EditError, FrameView, Settings
from pnlviz.app.timeline import frame_error, strip_image, worst_frames
from pnlviz.app.view2d import FOV_Y, PLANE_Z, View2D, snap
from pnlviz.app.workspace import Workspace, WorkspaceEvents, update_changed
from pnlviz.viz import blank_canvas

#: the canvas assumed until the browser reports its own (and for a session without a browser)
DEFAULT_CANVAS = (1280, 860)
SNAP_PX = 8.0  # screen pixels
PLAY_INTERVAL = 0.2  # seconds between frames while a clip plays
FOV_3D = math.radians(50.0)


def calibration_card(view: FrameView, state: AppState) -> str:
    """Markdown of the calibration card."""
    lines = []
    if view.error:
        lines.append(f"**error**: {view.error}")
    elif view.stem in state.image_errors:
        lines.append(f"**image not shown**: {state.image_errors[view.stem]}")
    res = view.result
    if view.origin is not None:
        settings = state.applied_detection_settings(view.origin, view.settings)
        used = ", ".join(f"{k}={v}" for k, v in settings.items())
        lines.append(f"calibrated from: **{view.origin}**"
                     + (f" (the detector's settings: {used})" if settings else ""))
    if view.reference_camera is not None:
        lines.append("reference camera (magenta): known for this frame")
    if res is None:
        return "\n\n".join(lines or ["nothing to calibrate from yet: place four keypoints (shift+click)"])
    if not res.ok:
        lines.append(f"**not calibrated**: {res.failure}")
        return "\n\n".join(lines)
    cam = res.camera
    pan, tilt, roll = cam.pan_tilt_roll_deg
    errs = np.array([v for v in res.point_residuals.values() if np.isfinite(v)])
    line_errs = np.array(list(res.line_residuals.values()))
    lines += [
        f"focal **{cam.fx:.1f} px** (hFOV {cam.hfov_deg:.1f} deg), k1 {cam.radial[0]:+.3f}",
        f"position ({cam.C[0]:.1f}, {cam.C[1]:.1f}, {cam.C[2]:.1f}) m; "
        f"pan {pan:.2f}, tilt {tilt:.2f}, roll {roll:.2f} deg",
        f"keypoints: {len(errs)}, median error {np.median(errs):.2f} px" if len(errs) else "keypoints: none",
        f"lines/circles: {len(line_errs)}, worst {line_errs.max():.1f} px" if len(line_errs) else "lines: none",
        f"won: subset **{res.subset}**, RANSAC {res.threshold:g} px, {res.plane} plane, {len(res.inliers)} inliers; "
        f"PnL set: {len(res.pnl_lines)} lines/circles",
    ]
    if view.jac:
        lines.append("JaC vs annotation: " + ", ".join(f"@{t} **{v:.2f}**" for t, v in view.jac.items()))
    lines.append(f"computed in {view.ms:.0f} ms")
    return "\n\n".join(lines)


def keypoint_name(model, kid: int) -> str:
    """What a keypoint is, in words (its defining lines and circles)."""
    kp = model.keypoints.get(int(kid))
    if kp is None:
        return "?"
    d = kp.definition
    parts = d.get("lines") or [p for p in (d.get("line"), d.get("circle")) if p] or d.get("on") or []
    return " x ".join(str(p) for p in parts) + f" ({kp.group})"


class Session:
    """The panel and scene nodes of one tab (``gui``/``scene`` of its viser client), or of the
    server itself when ``client`` is None (a session without a browser, for scripts and tests)."""

    def __init__(self, app, gui, scene, client=None):
        self.app, self.state = app, app.state
        self.gui, self.scene, self.client = gui, scene, client
        st = self.state
        self.index = st.first_index
        self.order = list(range(len(st.stems)))
        self.outside_filter = False  # the frame shown does not match the filter (nothing does)
        self.settings: Settings = st.default_settings
        self.sources = SOURCES if st.predictions is not None else ("annotation",)
        self.layers = Layers()
        self.mode = "image"
        self.view2d: View2D | None = None
        #: the canvas in screen (CSS) pixels, as the page's bridge reports it (until then, viser's
        #: drawing-buffer size, which is the same at a device pixel ratio of 1)
        self.canvas = DEFAULT_CANVAS
        self._css_canvas: tuple[int, int] | None = None
        self._relative_view: tuple[float, float, float] | None = None  # carried to frames of another size
        self._pushed_at = 0.0
        self._pan_from: View2D | None = None
        self.selected: tuple[str, object] | None = None
        self.place_id = 1
        self.snap = False
        self.opacity = 1.0
        self.drag_mode = "keypoints"
        self.grabs = self.releases = 0  # drags started and released in this tab
        self.live_preview = True  # recalibrate while a point is dragged (off: only on release)
        self.last_recalibration_ms = 0.0
        self.actions: list[str] = []  # frames this tab changed, most recent last: Ctrl+Z goes back there
        self.undone: list[str] = []
        self._drag: dict | None = None
        self._bridge_seen = (-1, 0.0, (0, 0))  # (n, log_zoom, nudge) of the last bridge message
        self._overlay: Overlay | None = None
        self._shown: FrameView | None = None
        self._shows = 0  # times this tab was drawn (an action that drew it need not draw it again)
        self._save_error: str | None = None  # why the last edit could not be written
        self._lock = threading.RLock()
        self._own_sets: dict[str, int] = {}  # widget -> values set by this tab whose callbacks are to come
        self._own_lock = threading.Lock()
        #: everything this tab asks for runs here, one action at a time, in the order it was sent
        self._queue = ThreadPoolExecutor(max_workers=1, thread_name_prefix="pnlviz-tab")
        self._closed = False
        #: where this tab's scene nodes live: a client's own scene, or (without a browser, on the
        #: server's shared scene) a branch of its own
        self._nodes = "/tab" if client is not None else f"/tab/session-{id(self):x}"
        events = WorkspaceEvents(place=self._on_place, click=self._on_click, pan=self._on_pan, pick=self._on_pick,
                                 drag=self._on_drag, screen_to_pixel=self._screen_to_pixel)
        #: the clips of a video dataset (named clips of >= 3 frames) and which clip each frame is in
        self.clips = st.clips
        self.clip_of = {i: name for name, members in self.clips.items() for i in members}
        self._playing = False
        self._worst = 0  # how far "next worst" has gone down the current clip's list
        self.workspace = Workspace(scene, self._nodes, events)
        self.scene3d = Scene3D(scene, self._nodes)
        self.panels = Panels(self)
        self.panels.set_order(len(self.order), self.index)
        if client is not None:
            client.camera.on_update(self._on_camera)
            client.scene.configure_default_lights(True, cast_shadow=False)  # no shadow pass on every frame

    @property
    def stem(self) -> str:
        return self.state.stems[self.index]

    def view(self) -> FrameView:
        return self.state.view(self.stem, self.settings)

    # ------------------------------------------------------------------ messages
    def notify(self, title: str, body: str, error: bool = True) -> None:
        """A notification in this tab (printed when the session has no browser)."""
        if self.client is None:
            print(f"pnlviz: {title}: {body}")
            return
        self.client.add_notification(title, body, auto_close_seconds=8.0, color="red" if error else None)

    def _guarded(self, action: Callable[[], object]) -> object:
        """Run a user action; a refused value or a failed save is shown, never lost silently. The
        tab is redrawn after it, unless the change already redrew it (an edit announces itself to
        every tab on its frame) and there is no save error to show or clear."""
        result, shows, clean = None, self._shows, self._save_error is None
        try:
            result = action()
            self._save_error = None
        except EditError as exc:
            self.notify("not applied", str(exc))
        except OSError as exc:
            self._save_error = exc.strerror or str(exc)
            self.notify("not saved", f"the edits folder cannot be written: {self._save_error}")
        if self._shows == shows or not clean or self._save_error is not None:
            self.show()
        return result

    def _act(self, stem: str, action: Callable[[], object]) -> None:
        """An edit of ``stem`` by this tab: remembered, so that Ctrl+Z comes back to it."""
        before = self.state.history(stem)[0]
        self._guarded(action)
        if self.state.history(stem)[0] != before:
            self.actions.append(stem)
            self.undone.clear()

    # ------------------------------------------------------------------ ordering
    def ordered(self, fn: Callable):
        """``fn(event)`` as a viser callback that keeps the browser's order: viser awaits ``async``
        callbacks on its event loop in the order the messages came (its thread pool runs plain
        ones in any order: "accepted" then "rejected" could end "accepted"); this one only puts
        the call on the tab's queue. The callbacks of values this tab set itself
        (:meth:`set_value`) are not taken for the user's."""

        async def queued(event) -> None:
            impl = getattr(getattr(event, "target", None), "_impl", None)
            if getattr(event, "client", True) is None and impl is not None:
                with self._own_lock:
                    if self._own_sets.get(impl.uuid):
                        self._own_sets[impl.uuid] -= 1
                        return
            self.enqueue(lambda: fn(event))

        return queued

    def set_value(self, handle, value) -> None:
        """Set a widget's value from here. viser calls its update callback for such sets too,
        later, on its event loop: by then the tab may have moved on, so that call is dropped
        (the slider moved by ``goto`` would otherwise send the tab back)."""
        if handle.value == value:
            return  # viser does nothing either
        with self._own_lock:
            self._own_sets[handle._impl.uuid] = self._own_sets.get(handle._impl.uuid, 0) + 1
        handle.value = value

    def enqueue(self, action: Callable[[], object]) -> None:
        if not self._closed:
            self._queue.submit(self._run, action)

    def flush(self, timeout: float = 30.0) -> None:
        """Wait until every action sent to this tab so far has run (for scripts and tests: a value
        set from Python reaches the queue through viser's event loop)."""
        loop = self.app.server.get_event_loop()
        asyncio.run_coroutine_threadsafe(asyncio.sleep(0), loop).result(timeout)
        self._queue.submit(lambda: None).result(timeout)

    def _run(self, action: Callable[[], object]) -> None:
        """One queued action; an unexpected error is printed and shown, and the tab goes on."""
        try:
            action()
        except Exception as exc:  # noqa: BLE001 - the queue would swallow it silently
            traceback.print_exc()
            self.notify("internal error", f"{type(exc).__name__}: {exc}")

    # ------------------------------------------------------------------ navigation
    def visible_order(self) -> list[int]:
        st = self.state
        f, s = self.panels.filter.value, self.panels.sort.value
        views = {v.stem: v for v in st.cached_views(self.settings)}
        idx = list(range(len(st.stems)))
        if f == "failed":
            idx = [i for i in idx if st.stems[i] in views and (views[st.stems[i]].result is None
                                                               or not views[st.stems[i]].result.ok)]
        elif f == "unreviewed":
            idx = [i for i in idx if st.edits.review(st.stems[i]) is None]
        elif f in REVIEW_STATES:
            idx = [i for i in idx if st.edits.review(st.stems[i]) == f]
        if s.startswith("JaC"):
            idx.sort(key=lambda i: views[st.stems[i]].jac.get(5, -1.0) if st.stems[i] in views else 2.0)
        elif s.startswith("residual"):
            def worst(i):
                v = views.get(st.stems[i])
                if v is None or v.result is None or not v.result.ok:
                    return -1.0 if v is None else 1e9
                r = list(v.result.point_residuals.values()) + list(v.result.line_residuals.values())
                return max(r) if r else 0.0
            idx.sort(key=lambda i: -worst(i))
        return idx

    def refresh_order(self) -> None:
        """The frames of the filter, in the chosen order; the tab stays on its frame if it is one
        of them, else goes to the first (with no match it stays, and says so)."""
        with self._lock:
            order = self.visible_order()
            self.outside_filter = not order
            if not order:
                self.notify("no match", f"no frame matches the filter '{self.panels.filter.value}'", error=False)
            self.order = order or [self.index]
            index = self.index if self.index in self.order else self.order[0]
            self.goto(index)

    def set_filter(self, value) -> None:
        self.panels.choice(self.panels.filter, FILTERS, "all")
        self.refresh_order()

    def set_sort(self, value) -> None:
        self.panels.choice(self.panels.sort, SORTS, "index")
        self.refresh_order()

    def slider_moved(self, value) -> None:
        try:
            pos = int(value)
        except (TypeError, ValueError, OverflowError):
            pos = 0
        with self._lock:
            pos = int(np.clip(pos, 0, len(self.order) - 1))
            if self.order[pos] != self.index:  # not an echo of goto() moving the slider
                self.goto(self.order[pos])

    def jump(self, text) -> None:
        idx = self.state.find(str(text)[:200])
        if idx is not None:
            self.goto(idx)

    def step(self, delta: int) -> None:
        with self._lock:
            pos = self.order.index(self.index) if self.index in self.order else 0
            self.goto(self.order[int(np.clip(pos + delta, 0, len(self.order) - 1))])

    def goto(self, index: int) -> None:
        with self._lock:
            index = int(np.clip(index, 0, len(self.state.stems) - 1))
            if index != self.index:
                self.selected = None
            self.index = index
            pos = self.order.index(index) if index in self.order else 0
            self.panels.set_order(len(self.order), pos)
            self.show()

    # ------------------------------------------------------------------ review and history
    def review(self, status: str, advance: bool = True) -> None:
        """Record a review status for the frame; with ``advance``, go on to the next frame of the
        filter (the filter as it is after this review: "unreviewed" moves on to the next one)."""
        if status not in REVIEW_STATES + ("clear",):
            self.notify("refused", f"review status {str(status)[:20]!r} is not one of the options")
            return
        stem = self.stem
        self._act(stem, lambda: self.state.set_review(stem, None if status == "clear" else status))
        if advance and status != "clear" and self.state.edits.review(stem) == status:
            self.advance_from(stem)

    def advance_from(self, stem: str) -> None:
        """Go to the frame after ``stem`` in the filter's order."""
        with self._lock:
            old, i = self.order, self.state.index_of(stem)
            later = old[old.index(i) + 1:] if i in old else []
            new = self.visible_order()
            nxt = next((j for j in later if j in new), None)
            self.order = new or [i]
            self.outside_filter = not new
            if nxt is None:
                self.notify("end of the filter", f"{stem} was the last frame of '{self.panels.filter.value}'",
                            error=False)
                nxt = i if i in self.order or not new else new[0]
            self.goto(nxt)

    def undo(self) -> None:
        """Take back this tab's last change (going back to its frame), else the frame's last one."""
        self._history_step(self.actions, self.undone, self.state.undo)

    def redo(self) -> None:
        self._history_step(self.undone, self.actions, self.state.redo)

    def _history_step(self, trail: list[str], other: list[str], step: Callable[[str], bool]) -> None:
        stem = trail.pop() if trail else self.stem
        if stem != self.stem:
            self.goto(self.state.index_of(stem))
        if self._guarded(lambda: step(stem)):
            other.append(stem)

    # ------------------------------------------------------------------ settings
    def set_pnl(self, value) -> None:
        self.settings = replace(self.settings, pnl=bool(value))
        self.show()

    def set_alpha(self, value) -> None:
        try:
            self.settings = replace(self.settings, alpha=float(value))
        except (TypeError, ValueError) as exc:
            self.notify("refused", str(exc))
            self.set_value(self.panels.alpha, self.settings.alpha)
        self.show()

    def set_source(self, value) -> None:
        source = self.panels.choice(self.panels.source, self.sources, self.settings.source)
        self.settings = replace(self.settings, source=source)
        self.show()

    def set_layer(self, name: str, value) -> None:
        if name in LAYERS:
            setattr(self.layers, name, bool(value))
            self.show()

    def set_opacity(self, value) -> None:
        try:
            value = float(value)
        except (TypeError, ValueError):
            value = 1.0
        self.opacity = float(np.clip(value if math.isfinite(value) else 1.0, 0.1, 1.0))
        self.show()

    def set_place_id(self, value) -> None:
        self.place_id = int(self.panels.choice(self.panels.kp_id, KEYPOINT_CHOICES, str(self.place_id)))

    def set_drag_mode(self, value) -> None:
        self.drag_mode = self.panels.choice(self.panels.drag_mode, DRAG_MODES, "keypoints")
        self.selected = None
        self.show()

    def set_snap(self, value) -> None:
        self.snap = bool(value)

    # ------------------------------------------------------------------ points
    def select(self, selected: tuple[str, object] | None) -> None:
        """Select a point (``("keypoints", id)``, ``("ghosts", id)``, ``("line_points", (class,
        index))``) or nothing. Selecting a keypoint or a ghost also chooses its id for placing."""
        self.selected = selected
        if selected is not None and selected[0] in ("keypoints", "ghosts"):
            self.place_id = int(selected[1])
            self.set_value(self.panels.kp_id, str(self.place_id))
        self.workspace.select(selected)
        self._show_selected()

    def select_listed(self, value) -> None:
        """A choice in the panel's keypoint list ("12 · visible · 0.8 px")."""
        text = str(value).split(" ")[0]
        if not text.isdigit():
            return
        kid = int(text)
        overlay = self._overlay
        if overlay is not None and kid in overlay.keypoints.keys:
            self.select(("keypoints", kid))
        elif overlay is not None and kid in overlay.ghosts.keys:
            self.select(("ghosts", kid))
        elif 1 <= kid <= 73:  # hidden: choose it, shift+click puts it back
            self.select(None)
            self.place_id = kid
            self.set_value(self.panels.kp_id, str(kid))

    def hide_selected(self) -> None:
        if self.selected is None or self.selected[0] != "keypoints":
            self.notify("nothing to hide", "select a keypoint first (click it)", error=False)
            return
        stem, kid = self.stem, int(self.selected[1])
        self.selected = None
        self._act(stem, lambda: self.state.hide_keypoint(stem, kid))

    def place(self, stem: str, uv) -> None:
        """Put the chosen keypoint id at pixel ``uv`` of ``stem`` (shift+click)."""
        kid = self.place_id
        uv = self._snapped(uv)
        self._act(stem, lambda: self.state.move_keypoint(stem, kid, *uv))
        if stem == self.stem and self._overlay is not None and kid in self._overlay.keypoints.keys:
            self.select(("keypoints", kid))

    def nudge(self, dx: int, dy: int) -> None:
        """Move the selected point by (dx, dy) image pixels (arrow keys)."""
        if self.selected is None or self._overlay is None or self.selected[0] == "ghosts":
            return
        kind, key = self.selected
        markers = self._overlay.keypoints if kind == "keypoints" else self._overlay.line_points
        if key not in markers.keys:
            return
        uv = markers.uv[markers.keys.index(key)] + [dx, dy]
        self.release(self.stem, kind, key, uv, snap_to_pitch=False)

    def release(self, stem: str, kind: str, key, uv, snap_to_pitch: bool = True) -> None:
        """A point of ``stem`` was dropped at pixel ``uv``: the edit goes to ``stem``, the frame
        the drag began on, whatever this tab shows now."""
        t0 = time.perf_counter()
        uv = self._snapped(uv) if snap_to_pitch else np.asarray(uv, float)

        def edit() -> None:
            if kind == "line_points":
                self.state.move_line_point(stem, key[0], key[1], *uv)
            else:
                self.state.move_keypoint(stem, int(key), *uv)
            self.state.view(stem, self.settings)  # recalibrate now, to time it
            self.last_recalibration_ms = 1e3 * (time.perf_counter() - t0)

        self._act(stem, edit)
        if kind == "ghosts" and stem == self.stem:
            self.select(("keypoints", int(key)))

    def _snapped(self, uv) -> np.ndarray:
        uv = np.asarray(uv, float)
        view = self._shown
        if not self.snap or view is None or view.camera is None or self.view2d is None:
            return uv
        model = self.state.model
        proj, _ = view.camera.project(model.keypoint_xyz())
        ok = np.all(np.isfinite(proj), axis=1)
        segments = self._overlay.segments.get("refined_pitch") if self._overlay is not None else None
        snapped, _ = snap(uv, proj[ok], segments.points if segments is not None else np.zeros((0, 2, 2)),
                          SNAP_PX / self.view2d.zoom)
        return snapped

    # ------------------------------------------------------------------ pointer events (event loop)
    def _on_place(self, uv) -> None:
        stem = self._shown.stem if self._shown is not None else self.stem
        self.enqueue(lambda: self.place(stem, uv))

    def _on_click(self, uv) -> None:
        self.enqueue(lambda: self._click(uv))

    def _click(self, uv) -> None:
        """A click beside the points: the nearest point within reach is selected, else nothing."""
        best, best_d = None, 12.0 / (self.view2d.zoom if self.view2d else 1.0)
        for kind in ("keypoints", "ghosts") + (("line_points",) if self.drag_mode == "line points" else ()):
            nodes = self.workspace.points[kind]
            for key, p in zip(nodes.keys, nodes.uv):
                d = float(np.hypot(*(p - uv)))
                if d < best_d:
                    best, best_d = (kind, key), d
        self.select(best)

    def _on_pick(self, kind: str, key) -> None:
        self.enqueue(lambda: self.select((kind, key)))

    def _on_drag(self, kind: str, key, phase: str, uv) -> None:
        """A point is dragged (called on viser's event loop, in order): the point follows the hand
        on screen at once; the frame is recalibrated as it moves (the latest position only,
        nothing saved) and for good when it is released."""
        if phase == "start":
            stem = self._shown.stem if self._shown is not None else self.stem
            self.grabs += 1
            self._drag = {"stem": stem, "kind": kind, "key": key, "uv": np.asarray(uv, float), "pending": False,
                          "from": np.asarray(uv, float)}
            self.enqueue(lambda: self.select((kind, key)))
            return
        drag = self._drag
        if drag is None or drag["key"] != key:
            return
        drag["uv"] = np.asarray(uv, float)
        if phase == "update" and not drag["pending"] and self.live_preview:
            drag["pending"] = True
            self.enqueue(self._drag_preview)
        elif phase == "end":
            self._drag = None
            self.releases += 1
            if np.hypot(*(drag["uv"] - drag["from"])) > 0.05:  # a press without a move changes nothing
                self.enqueue(lambda: self.release(drag["stem"], kind, key, drag["uv"]))
            else:
                self.enqueue(self.show)

    def _drag_preview(self) -> None:
        drag = self._drag
        if drag is None:
            return
        drag["pending"] = False
        if drag["kind"] != "keypoints" or drag["stem"] != self.stem:
            return  # a ghost becomes a keypoint (and a line point changes no keypoint) on release
        try:
            view = self.state.preview(drag["stem"], self.settings, int(drag["key"]), *drag["uv"])
        except EditError:
            return
        if self._drag is drag:  # still dragging: show the frame as it would be
            self._show_overlay(view, preview=True)

    def _screen_to_pixel(self, fractions) -> np.ndarray:
        view = self.view2d or View2D(0.0, 0.0, 1.0)
        return view.to_pixel(np.asarray(fractions, float) * self.canvas, self.canvas)

    def _on_pan(self, phase: str, start, now) -> None:
        self.enqueue(lambda: self.pan(phase, start, now))

    # ------------------------------------------------------------------ the image view's camera
    def pan(self, phase: str, start, now) -> None:
        """A drag on the image (screen fractions ``start`` -> ``now``): the image follows the hand."""
        if self.mode != "image" or self.view2d is None:
            return
        if phase == "start" or self._pan_from is None:
            self._pan_from = self.view2d
        base = self._pan_from
        d = (np.asarray(now, float) - np.asarray(start, float)) * self.canvas
        self._push_view(base.panned(d[0] / base.zoom, d[1] / base.zoom))
        if phase == "end":
            self._pan_from = None

    def zoom_by(self, factor: float, at_screen=None) -> None:
        """Zoom by ``factor`` around a canvas point (pixels; default: the centre)."""
        if self.mode != "image" or self.view2d is None:
            return
        at = self.view2d.to_pixel(at_screen, self.canvas) if at_screen is not None else None
        self._push_view(self.view2d.zoomed(factor, at))

    def fit(self) -> None:
        if self.mode == "image" and self.workspace.plane is not None:
            self._push_view(View2D.fit(self.workspace.plane, self.canvas))

    def native(self) -> None:
        """One image pixel per screen pixel, around the centre of the view."""
        if self.mode == "image" and self.view2d is not None:
            self._push_view(View2D(self.view2d.cu, self.view2d.cv, 1.0))

    def bridge_message(self, text) -> None:
        """What the page's pointer bridge sent: a zoom around the pointer, a nudge."""
        msg = parse_pointer(text)
        n, log_zoom, nudge = self._bridge_seen
        if msg is None or msg.n <= n:
            return
        self._bridge_seen = (msg.n, msg.log_zoom, msg.nudge)
        if msg.canvas is not None and msg.canvas != self._css_canvas:
            self._css_canvas = msg.canvas
            self._resized(msg.canvas)
        if msg.log_zoom != log_zoom:
            self.zoom_by(math.exp(float(np.clip(msg.log_zoom - log_zoom, -3.0, 3.0))),
                         (msg.x * self.canvas[0], msg.y * self.canvas[1]))
        dx, dy = msg.nudge[0] - nudge[0], msg.nudge[1] - nudge[1]
        if (dx or dy) and self.mode == "image":
            self.nudge(int(np.clip(dx, -100, 100)), int(np.clip(dy, -100, 100)))

    def _push_view(self, view: View2D) -> None:
        """Put the browser camera on ``view`` (clamped to what the image view allows)."""
        plane = self.workspace.plane
        if plane is None:
            return
        view = view.clamped(plane, self.canvas)
        self.view2d = view
        self._relative_view = view.relative(plane, self.canvas)
        self.workspace.set_zoom(plane.scale / view.zoom)
        self._show_zoom()
        if self.client is None:
            return
        position, look_at = view.camera(plane, self.canvas[1])
        d = PLANE_Z - position[2]
        self._pushed_at = time.monotonic()
        cam = self.client.camera
        with self.client.atomic():
            cam.fov = FOV_Y
            cam.up_direction = (0.0, -1.0, 0.0)
            cam.position = position
            cam.look_at = look_at
            cam.near, cam.far = 0.25 * d, 2.0 * d + 1.0

    async def _on_camera(self, camera) -> None:
        """The browser's camera moved (viser's own controls, or an echo of ours)."""
        if self.mode != "image" or self._closed:
            return
        try:
            state = (np.array(camera.position), np.array(camera.wxyz), np.array(camera.look_at),
                     (int(camera.image_width), int(camera.image_height)))
        except AssertionError:  # no camera message yet
            return
        self.enqueue(lambda: self._camera_moved(*state))

    def _camera_moved(self, position, wxyz, look_at, canvas) -> None:
        """Keep the image view an image view: looking straight at the frame, within the zoom
        limits. viser's own controls may pan (right-drag, A/D/Q/E) and zoom (W/S); anything else
        (an orbit, a dolly through the image) is put back."""
        plane = self.workspace.plane
        if self.mode != "image" or plane is None or min(canvas) <= 0 or self.view2d is None:
            return
        if self._css_canvas is None and canvas != self.canvas:
            self._resized(canvas)
            return
        if time.monotonic() - self._pushed_at < 0.5:
            return  # an echo of a view we set (or of the 3D view we left): ours is newer
        d = PLANE_Z - position[2]
        straight = (d > 0 and abs(abs(wxyz[0]) - 1.0) < 1e-4 and abs(look_at[2] - PLANE_Z) < 1e-3 * d
                    and np.hypot(*(look_at[:2] - position[:2])) < 1e-3 * d)
        if not straight:
            self._push_view(self.view2d)
            return
        # the canvas height in the camera's own pixels gives the zoom it shows; in screen pixels:
        view = View2D.from_camera(plane, position, canvas[1])
        view = View2D(view.cu, view.cv, view.zoom * self.canvas[1] / canvas[1])
        clamped = view.clamped(plane, self.canvas)
        moved = abs(clamped.cu - view.cu) + abs(clamped.cv - view.cv)
        if abs(math.log(clamped.zoom / view.zoom)) > 1e-3 or moved > 0.5:
            self._push_view(clamped)
            return
        self.view2d = view
        self._relative_view = view.relative(plane, self.canvas)
        self.workspace.set_zoom(plane.scale / view.zoom)
        self._show_zoom()

    def _resized(self, canvas: tuple[int, int]) -> None:
        """The canvas changed size: the same part of the frame stays in view."""
        self.canvas = canvas
        plane = self.workspace.plane
        if plane is not None and self._relative_view is not None and self.mode == "image":
            self._push_view(View2D.from_relative(self._relative_view, plane, canvas))

    def _show_zoom(self) -> None:
        self.panels.zoom_text.content = f"zoom **{self.view2d.zoom:.2f}x** (screen pixels per image pixel)"

    def toggle_mode(self) -> None:
        """Image view <-> 3D view."""
        self.set_mode("3d" if self.mode == "image" else "image")

    def set_mode(self, mode: str) -> None:
        if mode == self.mode:
            return
        self.mode = mode
        self.panels.set_mode(mode)
        if mode == "3d":
            view = self.show()
            pose = behind_camera(view.camera) if view is not None and view.camera is not None else OVERVIEW
            if self.client is not None:
                with self.client.atomic():
                    cam = self.client.camera
                    cam.near, cam.far, cam.fov = 0.05, 1000.0, FOV_3D
                    cam.up_direction = pose["up"]
                    cam.position = pose["position"]
                    cam.look_at = pose["look_at"]
        else:
            self.scene3d.hide()
            self.show()
            if self._relative_view is not None and self.workspace.plane is not None:
                self._push_view(View2D.from_relative(self._relative_view, self.workspace.plane, self.canvas))

    # ------------------------------------------------------------------ drawing
    def show(self) -> FrameView | None:
        """Recompute (or fetch from the cache) this tab's frame and send what changed to this tab."""
        with self._lock:
            if self._closed:
                return None
            st = self.state
            if st.needs_detection(self.stem):
                self.app.detect_in_background(self.stem)
            view = self.view()
            self._shown = view
            self._shows += 1
            with self._atomic():
                self._show_image(view)
                self._show_overlay(view)
                self._show_panel(view)
                if self.mode == "3d":
                    self.scene3d.show(view, render(view, st.image(view.stem), self.layers))
            return view

    def _pixels(self, stem: str) -> np.ndarray:
        """The frame as the browser shows it: its image (RGB), or a neutral canvas of its size."""
        image = self.state.image(stem)
        if image is None:
            image = blank_canvas(*self.state.frame_size(stem))
        return np.ascontiguousarray(image[:, :, ::-1])

    def _preload_neighbours(self) -> None:
        """Send the frames before and after this one (in the filter's order) ahead, hidden."""
        with self._lock:
            if self._closed or self.index not in self.order:
                return
            pos = self.order.index(self.index)
            stems = [self.state.stems[self.order[p]] for p in (pos + 1, pos - 1) if 0 <= p < len(self.order)]
        for stem in stems:  # the pixels are read outside the lock, the scene changed under it
            with self._lock:
                if self._closed or self.workspace.holds(stem):
                    continue
            pixels = self._pixels(stem)
            with self._lock:
                if not self._closed:
                    self.workspace.preload(stem, lambda pixels=pixels: pixels)

    def _show_image(self, view: FrameView) -> None:
        before = self.workspace.plane
        if self.workspace.show_image(view.stem, lambda: self._pixels(view.stem)):
            self.enqueue(self._preload_neighbours)
        plane = self.workspace.plane
        if plane != before or self.view2d is None:  # the first frame, or one of another size
            fit = View2D.fit(plane, self.canvas)
            view2d = View2D.from_relative(self._relative_view, plane, self.canvas) if self._relative_view else fit
            if self.mode == "image":
                self._push_view(view2d)
            else:
                self.view2d = view2d.clamped(plane, self.canvas)

    def _hidden_ids(self, stem: str) -> set[int]:
        kps = self.state.edits.get(stem).get("keypoints") or {}
        return {int(k) for k, v in kps.items() if v is None}

    def _show_overlay(self, view: FrameView, preview: bool = False) -> None:
        """The overlays of ``view``; a ``preview`` (while a point is dragged) is not kept as the
        frame's overlay."""
        overlay = overlay_geometry(view, self.layers, self.state.model, hidden=self._hidden_ids(view.stem))
        colors = self._blended(overlay, view) if self.opacity < 1.0 else None
        self.workspace.show_overlay(overlay, colors, keypoints=self.layers.keypoints, ghosts=self.layers.ghosts,
                                    line_points=self.drag_mode == "line points", ids=self.layers.ids)
        if not preview:
            self._overlay = overlay

    def _blended(self, overlay: Overlay, view: FrameView) -> dict[str, np.ndarray]:
        """Segment colours mixed with the image under each end: the overlays at ``opacity``."""
        image = self.state.image(view.stem)
        W, H = view.size
        if image is None:
            image = blank_canvas(W, H)
        out = {}
        for name, seg in overlay.segments.items():
            if not len(seg):
                continue
            uv = np.round(seg.points).astype(int)
            u, v = np.clip(uv[..., 0], 0, image.shape[1] - 1), np.clip(uv[..., 1], 0, image.shape[0] - 1)
            under = image[v, u, ::-1].astype(float)  # (N, 2, 3) RGB
            out[name] = (self.opacity * seg.colors[:, None].astype(float) + (1 - self.opacity) * under).astype(np.uint8)
        return out

    def _show_panel(self, view: FrameView) -> None:
        st, p = self.state, self.panels
        pos = self.order.index(self.index) + 1 if self.index in self.order else 0
        where = (f"not in the filter '{p.filter.value}' (no frame is)" if self.outside_filter
                 else f"{pos}/{len(self.order)}" + (f" of '{p.filter.value}'" if p.filter.value != "all" else ""))
        title = f"### {view.stem}\n{where} · {view.size[0]}x{view.size[1]}"
        update_changed(p.title, content=title)
        update_changed(p.status, content=self._status_line(view))
        n = len(self.order)
        update_changed(p.filter_text, content=f"**no frame matches '{p.filter.value}'**: showing {view.stem}"
                       if self.outside_filter else f"{n} frame" + ("s" if n != 1 else ""))
        update_changed(p.card, content=calibration_card(view, st))
        self._show_points_list(view)
        self._show_selected()
        self.show_progress()
        self._show_clip()

    # ------------------------------------------------------------------ the clip timeline
    def clip_members(self) -> list[int]:
        """Dataset indices of the frames of this tab's clip, in frame order ([] outside a clip)."""
        name = self.clip_of.get(self.index)
        return self.clips.get(name, []) if name is not None else []

    def clip_errors(self) -> list[float]:
        """Each clip frame's error (:func:`pnlviz.app.timeline.frame_error`), from the views already
        computed: a lookup per clip frame, not a pass over every cached frame."""
        st = self.state
        return [frame_error(st.cached_view(st.stems[i], self.settings)) for i in self.clip_members()]

    def _show_clip(self) -> None:
        p = self.panels
        members = self.clip_members()
        if p.clip_text is None:
            return
        if not members:
            update_changed(p.clip_text, content="this frame is not part of a clip")
            return
        pos = members.index(self.index)
        errors = self.clip_errors()
        e = errors[pos]
        said = ("not calibrated yet" if np.isnan(e) else "no camera" if np.isinf(e) else f"error {e:.1f} px")
        done = sum(not np.isnan(v) for v in errors)
        update_changed(p.clip_text, content=f"**{self.clip_of[self.index]}**: frame {pos + 1} of {len(members)} "
                                            f"· {said}" + ("" if done == len(members) else f" · {done} calibrated")
                                            + (" · playing" if self._playing else ""))
        strip = strip_image(errors, pos)
        if p.clip_strip.image is None or not np.array_equal(p.clip_strip.image, strip):
            p.clip_strip.image = strip
        p.clip_slider.max = max(2, len(members))
        self.set_value(p.clip_slider, pos + 1)

    def clip_slider_moved(self, value) -> None:
        members = self.clip_members()
        if not members:
            return
        try:
            pos = int(value) - 1
        except (TypeError, ValueError, OverflowError):
            pos = 0
        pos = int(np.clip(pos, 0, len(members) - 1))
        if members[pos] != self.index:
            self.goto(members[pos])

    def jump_worst(self, restart: bool = False) -> None:
        """To the clip's worst frame (``restart``), else the next worse one after the last jump."""
        members = self.clip_members()
        ranked = worst_frames(self.clip_errors())
        if not ranked:
            self.notify("nothing yet", "no frame of this clip is calibrated yet", error=False)
            return
        self._worst = 0 if restart else (self._worst + 1) % len(ranked)
        self.goto(members[ranked[self._worst]])

    def play(self) -> None:
        """Step through the clip, about 5 frames a second, until its end or a pause (navigating meanwhile
        moves where it plays from)."""
        if self._playing or not self.clip_members():
            return
        self._playing = True
        threading.Thread(target=self._play_loop, name="pnlviz-play", daemon=True).start()

    def pause(self) -> None:
        self._playing = False
        self._show_clip()

    def toggle_play(self) -> None:
        self.pause() if self._playing else self.play()

    def _play_loop(self) -> None:
        while self._playing and not self._closed:
            t0 = time.monotonic()
            done = threading.Event()

            def advance() -> None:
                members = self.clip_members()
                if not members or self.index == members[-1] or not self._playing:
                    self._playing = False
                    self._show_clip()
                else:
                    self.goto(members[members.index(self.index) + 1])
                done.set()

            self.enqueue(advance)
            done.wait(5.0)
            time.sleep(max(0.0, PLAY_INTERVAL - (time.monotonic() - t0)))

    def _status_line(self, view: FrameView) -> str:
        st = self.state
        review = st.edits.review(view.stem) or "not reviewed"
        rec = st.edits.get(view.stem)
        if self._save_error:
            saved = f"**not saved**: {self._save_error}"
        elif rec.get("updated"):
            saved = "saved " + time.strftime("%H:%M:%S", time.localtime(rec["updated"]))
        else:
            saved = "no edits"
        detection = self.app.detection_status(view.stem)
        line = f"review: **{review}** · {saved}" + (f" · {detection}" if detection else "")
        # why a frame has no camera, where it is seen first (the card below says more)
        if view.error:
            line += f"  \n**problem**: {view.error}"
        elif view.result is not None and not view.result.ok:
            line += f"  \n**not calibrated**: {view.result.failure}"
        return line

    def _show_points_list(self, view: FrameView) -> None:
        overlay = self._overlay
        rows = ["-"]
        if overlay is not None:
            for kid in sorted(overlay.keypoints.keys):
                r = overlay.residuals.get(kid)
                rows.append(f"{kid} · visible" + (f" · {r:.1f} px" if r is not None else ""))
            rows += [f"{kid} · hidden" for kid in sorted(self._hidden_ids(view.stem))]
            rows += [f"{kid} · ghost" for kid in sorted(overlay.ghosts.keys)]
        p = self.panels.points
        if tuple(p.options) != tuple(rows):
            p.options = rows
        if p.value not in rows:
            self.set_value(p, "-")

    def _show_selected(self) -> None:
        sel, overlay, model = self.selected, self._overlay, self.state.model
        if sel is None or overlay is None:
            text = f"nothing selected · shift+click places id **{self.place_id}**"
            update_changed(self.panels.selected, content=text)
            return
        kind, key = sel
        if kind == "line_points":
            m = overlay.line_points
            text = f"**{key[0]}**, point {key[1]}"
        else:
            m = overlay.keypoints if kind == "keypoints" else overlay.ghosts
            text = f"**{key}** {keypoint_name(model, key)}"
            if kind == "ghosts":
                text += " · not observed: drag it where it is"
            elif key in overlay.residuals:
                text += f" · residual {overlay.residuals[key]:.2f} px"
        if key in m.keys:
            u, v = m.uv[m.keys.index(key)]
            text += f" · at ({u:.1f}, {v:.1f})"
        update_changed(self.panels.selected, content=text)

    def show_progress(self) -> None:
        done, total = self.state.review_progress()
        counts = self.state.edits.counts()
        update_changed(self.panels.progress, value=100.0 * done / total)
        update_changed(self.panels.progress_text, content=f"{done} of {total} reviewed: " + ", ".join(
                       f"{k} {v}" for k, v in counts.items()))

    def _atomic(self):
        return self.client.atomic() if self.client is not None else self.app.server.atomic()

    # ------------------------------------------------------------------ export and end
    def export(self) -> None:
        from pnlviz.app.export import export_zip_bytes

        if self.client is not None:
            st = self.state
            self.client.send_file_download(f"{st.data.name}_labels.zip", export_zip_bytes(st, settings=self.settings),
                                           save_immediately=True)

    def close(self, wait: bool = False) -> None:
        """The tab is gone: stop drawing (its GUI and scene nodes went with its connection). Edits
        already released still go through; ``wait``: until they have (the server stopping)."""
        with self._lock:
            self._closed = True
        self._queue.shutdown(wait=wait)


__all__ = ["PLAY_INTERVAL", "Session", "calibration_card", "keypoint_name"]
