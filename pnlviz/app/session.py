"""One browser tab of the app: its own current frame, filter, settings, overlay layers, panels and
scene nodes. Every edit it sends names the frame it was made on (captured when the handle or the
image was shown), so a drag released after another tab moved on still lands on its own frame.

Values coming from the browser are never trusted: dropdowns are checked against their options,
numbers against their ranges, and edits go through :class:`pnlviz.app.state.AppState`, which
validates ids and positions. A refused value is reverted and shown to that tab only.
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
from typing import NamedTuple

import numpy as np

from pnlviz.app.overlay import SET_BGR, Layers, render
from pnlviz.app.scene import FRUSTUM_SCALE, HANDLE_SCALE, camera_wxyz, pixel_to_plane, plane_to_pixel, ray_to_pixel
from pnlviz.app.state import REVIEW_STATES, SOURCES, AppState, EditError, FrameView, Settings

FILTERS = ("all", "failed", "unreviewed", "accepted", "corrected", "rejected")
SORTS = ("index", "JaC@5 (worst first)", "residual (worst first)")
HANDLE_MODES = ("off", "keypoints", "line points")
LAYERS = ("annotation", "keypoints", "ids", "initial_pitch", "refined_pitch", "residuals", "reference_pitch",
          "detected_lines")
KEYPOINT_CHOICES = tuple(str(i) for i in range(1, 74))


class KeypointHandle(NamedTuple):
    """A drag handle on a keypoint."""

    kid: int

    @property
    def path(self) -> str:
        return f"handles/kp/{self.kid}"


class LinePointHandle(NamedTuple):
    """A drag handle on point ``index`` of an annotated line or circle."""

    cls: str
    index: int

    @property
    def path(self) -> str:
        return f"handles/line/{self.cls.strip().replace(' ', '_')}/{self.index}"


HandleTarget = KeypointHandle | LinePointHandle


def calibration_card(view: FrameView, state: AppState) -> str:
    """Markdown of the calibration card."""
    lines = [f"**{view.stem}** ({view.index + 1}/{len(state.stems)}), {view.size[0]}x{view.size[1]}"]
    review = state.edits.review(view.stem)
    lines.append(f"review: **{review or 'not reviewed'}**")
    if view.error:
        lines.append(f"**error**: {view.error}")
    elif view.stem in state.image_errors:
        lines.append(f"**image not shown**: {state.image_errors[view.stem]}")
    res = view.result
    if view.origin is not None:
        settings = state.applied_detection_settings(view.origin, view.settings)
        lines.append(f"calibrated from: **{view.origin}**" + (
            " (the detector's settings: " + ", ".join(f"{k}={v}" for k, v in settings.items()) + ")" if settings else ""))
    if view.reference_camera is not None:
        lines.append("reference camera (magenta): known for this frame")
    if res is None:
        return "\n\n".join(lines)
    if not res.ok:
        lines.append(f"**not calibrated**: {res.failure}")
        return "\n\n".join(lines)
    cam = res.camera
    pan, tilt, roll = cam.pan_tilt_roll_deg
    errs = np.array([v for v in res.point_residuals.values() if np.isfinite(v)])
    line_errs = np.array(list(res.line_residuals.values()))
    lines += [
        f"focal **{cam.fx:.1f} px** (hFOV {cam.hfov_deg:.1f} deg), k1 {cam.radial[0]:+.3f}",
        f"position ({cam.C[0]:.1f}, {cam.C[1]:.1f}, {cam.C[2]:.1f}) m",
        f"pan {pan:.2f}, tilt {tilt:.2f}, roll {roll:.2f} deg",
        f"keypoints: {len(errs)}, median error {np.median(errs):.2f} px" if len(errs) else "keypoints: none",
        f"lines/circles: {len(line_errs)}, worst {line_errs.max():.1f} px" if len(line_errs) else "lines: none",
        f"won: subset **{res.subset}**, RANSAC {res.threshold:g} px, {res.plane} plane, {len(res.inliers)} inliers",
        f"PnL set: {len(res.pnl_lines)} lines/circles",
    ]
    if view.jac:
        lines.append("JaC vs annotation: " + ", ".join(f"@{t} **{v:.2f}**" for t, v in view.jac.items()))
    lines.append(f"computed in {view.ms:.0f} ms")
    return "\n\n".join(lines)


class Session:
    """The panels and scene nodes of one tab (``gui``/``scene`` of its viser client), or of the
    server itself when ``client`` is None (a session without a browser, for scripts and tests)."""

    def __init__(self, app, gui, scene, client=None):
        self.app, self.state = app, app.state
        self.gui, self.scene, self.client = gui, scene, client
        self.index = self.state.first_index
        self.order = list(range(len(self.state.stems)))
        self.settings: Settings = self.state.default_settings
        self.layers = Layers()
        self.last_recalibration_ms = 0.0
        self.grabs = self.releases = 0  # handle drags started and released in this tab
        self._lock = threading.RLock()
        self._frustum = self._rays = None
        self._handles: dict[HandleTarget, object] = {}  # what -> its transform controls
        self._handle_frame: dict[HandleTarget, tuple] = {}  # what -> (stem, camera) the handle is placed with
        self._dragging: dict[HandleTarget, tuple | None] = {}  # drags in progress: what -> (stem, camera) at start
        #: everything this tab asks for runs here, one action at a time, in the order it was sent
        self._queue = ThreadPoolExecutor(max_workers=1, thread_name_prefix="pnlviz-tab")
        self._shown: tuple[str, object] | None = None  # (stem, camera) of the image plane on screen
        self._closed = False
        #: where this tab's scene nodes live: a client's own scene, or (without a browser, on the
        #: server's shared scene) a branch of its own
        self._nodes = "/frame" if client is not None else f"/frame/session-{id(self):x}"
        self._build_gui()

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

    def _guarded(self, action: Callable[[], None]) -> None:
        """Run a user action; a refused value or a failed save is shown, never lost silently."""
        try:
            action()
        except EditError as exc:
            self.notify("not applied", str(exc))
        except OSError as exc:
            self.notify("not saved", f"the edits folder cannot be written: {exc.strerror or exc}")
        self.show()

    # ------------------------------------------------------------------ ordering
    def _ordered(self, fn: Callable):
        """``fn(event)`` as a viser callback that keeps the browser's order: viser awaits ``async``
        callbacks on its event loop in the order the messages came (its thread pool runs plain
        ones in any order: "accepted" then "rejected" could end "accepted"); this one only puts
        the call on the tab's queue."""

        async def queued(event) -> None:
            if not self._closed:
                self._queue.submit(self._run, lambda: fn(event))

        return queued

    def flush(self, timeout: float = 30.0) -> None:
        """Wait until every action sent to this tab so far has run (for scripts and tests: a value
        set from Python reaches the queue through viser's event loop)."""
        loop = self.app.server.get_event_loop()
        asyncio.run_coroutine_threadsafe(asyncio.sleep(0), loop).result(timeout)
        self._queue.submit(lambda: None).result(timeout)

    def _run(self, action: Callable[[], None]) -> None:
        """One queued action; an unexpected error is printed and shown, and the tab goes on."""
        try:
            action()
        except Exception as exc:  # noqa: BLE001 - the queue would swallow it silently
            traceback.print_exc()
            self.notify("internal error", f"{type(exc).__name__}: {exc}")

    # ------------------------------------------------------------------ GUI
    def _choice(self, handle, options, fallback: str) -> str:
        """The dropdown's value if it is one of ``options``; else it is reset to ``fallback``."""
        value = handle.value
        if value in options:
            return value
        self.notify("refused", f"{handle.label}: {str(value)[:40]!r} is not one of the options")
        handle.value = fallback
        return fallback

    def _build_gui(self) -> None:
        gui, st = self.gui, self.state
        gui.configure_theme(control_width="large")
        with gui.add_folder("Frame"):
            self.title = gui.add_markdown("")
            self.slider = gui.add_slider("frame", min=0, max=max(1, len(st.stems) - 1), step=1, initial_value=self.index)
            self.nav = gui.add_button_group("navigate", ("previous", "next"))
            self.jump = gui.add_text("jump to stem", initial_value="")
            self.filter = gui.add_dropdown("filter", FILTERS, initial_value="all")
            self.sort = gui.add_dropdown("sort", SORTS, initial_value="index")
            self.cam_button = gui.add_button("camera view")
        self.image = gui.add_image(np.zeros((54, 96, 3), np.uint8), label="frame", format="jpeg")
        with gui.add_folder("Calibration"):
            self.card = gui.add_markdown("")
        with gui.add_folder("Settings"):
            self.pnl = gui.add_checkbox("PnL refinement", initial_value=self.settings.pnl)
            self.alpha = gui.add_slider("alpha (lines vs points)", min=0.0, max=1.0, step=0.05,
                                        initial_value=self.settings.alpha)
            self.sources = SOURCES if st.predictions is not None else ("annotation",)
            self.source = gui.add_dropdown("keypoint source", self.sources, initial_value=self.settings.source)
            self.layer_boxes = {name: gui.add_checkbox(name.replace("_", " "), initial_value=getattr(self.layers, name))
                                for name in LAYERS}
        with gui.add_folder("Edit"):
            self.handles_mode = gui.add_dropdown("drag handles", HANDLE_MODES, initial_value="off",
                                                 hint="drag a handle on the image plane; the frame recalibrates on release")
            self.history = gui.add_button_group("history", ("undo", "redo"))
            self.kp_id = gui.add_dropdown("keypoint", KEYPOINT_CHOICES, initial_value="1",
                                          hint="shift+click on the image places this keypoint")
            self.kp_hide = gui.add_button("mark keypoint not visible")
            self.export = gui.add_button("export labels (zip)")
        with gui.add_folder("Review"):
            self.review = gui.add_button_group("status", REVIEW_STATES + ("clear",))
            self.progress = gui.add_progress_bar(0.0)
            self.progress_text = gui.add_markdown("")
            self.background = gui.add_markdown("")
        self._bind_commands()
        self._bind_navigation()
        self._bind_settings()
        self._bind_edits()

    def _bind_commands(self) -> None:
        """Keyboard shortcuts (viser's command palette; none clashes with its camera keys)."""
        gui = self.gui
        keys = (("next frame", "N", None, lambda: self.step(1)),
                ("previous frame", "P", None, lambda: self.step(-1)),
                ("undo edit", "Z", "cmd/ctrl", lambda: self._guarded(lambda: self.state.undo(self.stem))),
                ("redo edit", "Z", "cmd/ctrl+shift", lambda: self._guarded(lambda: self.state.redo(self.stem))),
                ("camera view", "V", None, self.camera_view))
        for label, key, modifier, action in keys:
            description = f"{modifier.replace('cmd/ctrl', 'Ctrl').replace('+shift', '+Shift')}+{key}" if modifier else key
            command = gui.add_command(label, hotkey=key, modifier=modifier, description=description)
            command.on_trigger(self._ordered(lambda _, action=action: action()))

    def _bind_navigation(self) -> None:
        @self.slider.on_update
        @self._ordered
        def _(_) -> None:
            try:
                pos = int(self.slider.value)
            except (TypeError, ValueError):
                pos = 0
            with self._lock:
                pos = int(np.clip(pos, 0, len(self.order) - 1))
                if self.order[pos] != self.index:  # not an echo of step() or goto() moving the slider
                    self.goto(self.order[pos], from_slider=True)

        @self.nav.on_click
        @self._ordered
        def _(event) -> None:
            if event.target.value in ("previous", "next"):
                self.step(-1 if event.target.value == "previous" else 1)

        @self.jump.on_update
        @self._ordered
        def _(_) -> None:
            idx = self.state.find(str(self.jump.value)[:200])
            if idx is not None:
                self.goto(idx)

        @self.filter.on_update
        @self._ordered
        def _(_) -> None:
            self._choice(self.filter, FILTERS, "all")
            self.refresh_order()

        @self.sort.on_update
        @self._ordered
        def _(_) -> None:
            self._choice(self.sort, SORTS, "index")
            self.refresh_order()

        @self.cam_button.on_click
        @self._ordered
        def _(_) -> None:
            self.camera_view()

    def _bind_settings(self) -> None:
        @self.pnl.on_update
        @self._ordered
        def _(_) -> None:
            self.settings = replace(self.settings, pnl=bool(self.pnl.value))
            self.show()

        @self.alpha.on_update
        @self._ordered
        def _(_) -> None:
            try:
                self.settings = replace(self.settings, alpha=float(self.alpha.value))
            except (TypeError, ValueError) as exc:
                self.notify("refused", str(exc))
                self.alpha.value = self.settings.alpha
            self.show()

        @self.source.on_update
        @self._ordered
        def _(_) -> None:
            self.settings = replace(self.settings, source=self._choice(self.source, self.sources, self.settings.source))
            self.show()

        for name, box in self.layer_boxes.items():
            def on_layer(_, name=name, box=box) -> None:
                setattr(self.layers, name, bool(box.value))
                self.show()

            box.on_update(self._ordered(on_layer))

        @self.handles_mode.on_update
        @self._ordered
        def _(_) -> None:
            self._choice(self.handles_mode, HANDLE_MODES, "off")
            self.show()

    def _bind_edits(self) -> None:
        st = self.state

        @self.history.on_click
        @self._ordered
        def _(event) -> None:
            stem = self.stem
            if event.target.value == "undo":
                self._guarded(lambda: st.undo(stem))
            elif event.target.value == "redo":
                self._guarded(lambda: st.redo(stem))

        @self.kp_hide.on_click
        @self._ordered
        def _(_) -> None:
            stem, kid = self.stem, self.kp_id.value
            self._guarded(lambda: st.hide_keypoint(stem, kid))

        @self.export.on_click
        @self._ordered
        def _(_) -> None:
            from pnlviz.app.export import export_zip_bytes

            if self.client is not None:
                self.client.send_file_download(f"{st.data.name}_labels.zip", export_zip_bytes(st, settings=self.settings),
                                               save_immediately=True)

        @self.scene.on_click(modifier="shift")
        @self._ordered
        def _(event) -> None:
            with self._lock:
                shown = self._shown
            if shown is None:
                return
            stem, cam = shown
            uv = ray_to_pixel(cam, event.ray_origin, event.ray_direction)
            kid = self.kp_id.value
            if uv is not None:
                self._guarded(lambda: st.move_keypoint(stem, kid, *uv))

        @self.review.on_click
        @self._ordered
        def _(event) -> None:
            value, stem = event.target.value, self.stem
            if value in REVIEW_STATES + ("clear",):
                self._guarded(lambda: st.set_review(stem, None if value == "clear" else value))

    # ------------------------------------------------------------------ scene
    def _update_scene(self, view: FrameView, image: np.ndarray) -> None:
        cam = view.camera
        if cam is None:  # a failed frame without a known camera: nothing to place in the scene
            for handle in (self._frustum, self._rays):
                if handle is not None:
                    handle.remove()
            self._frustum = self._rays = None
            self._shown = None
            self._update_handles(view, None)
            return
        self._shown = (view.stem, cam)
        W, H = view.size
        fov_y, wxyz = 2 * math.atan((H / 2) / cam.fy), camera_wxyz(cam.R)
        if self._frustum is None:
            self._frustum = self.scene.add_camera_frustum(
                f"{self._nodes}/camera", fov=fov_y, aspect=W / H, scale=FRUSTUM_SCALE, image=image, format="jpeg",
                jpeg_quality=85, wxyz=wxyz, position=cam.C, color=(255, 190, 40))
        else:  # the same scene node, updated in place
            f = self._frustum
            f.fov, f.aspect, f.image, f.wxyz, f.position = fov_y, W / H, image, wxyz, cam.C
        obs = view.observations
        if obs is not None and obs.n_keypoints:
            seg = np.stack([np.repeat(cam.C[None], obs.n_keypoints, 0), obs.kp_xyz], axis=1)
            cols = np.array([SET_BGR.get(str(s), (255, 255, 255))[::-1] for s in obs.kp_sets], np.uint8)
            cols = np.repeat(cols[:, None], 2, 1)
            if self._rays is None:
                self._rays = self.scene.add_line_segments(f"{self._nodes}/rays", seg, cols, thickness=1.5,
                                                          thickness_units="screen")
            else:
                self._rays.points, self._rays.colors = seg, cols
        elif self._rays is not None:  # no keypoints on this frame: no rays from the previous one
            self._rays.remove()
            self._rays = None
        self._update_handles(view, cam)

    def _update_handles(self, view: FrameView, cam) -> None:
        """Drag handles on the image plane for keypoints or annotated line points, updated in place
        (a handle keeps its identity across redraws, so a drag in progress is never cut short by a
        redraw that another tab's edit caused; the handle being dragged is left where the hand is)."""
        mode = self.handles_mode.value
        targets: dict[HandleTarget, np.ndarray] = {}  # what -> uv
        if cam is not None and mode == "keypoints" and view.observations is not None:
            targets = {KeypointHandle(int(k)): p for k, p in zip(view.observations.kp_ids, view.observations.kp_xy)}
        elif cam is not None and mode == "line points" and view.annotation:
            W, H = view.size
            targets = {LinePointHandle(name, i): p * [W - 1, H - 1] for name, pts in view.annotation.items()
                       for i, p in enumerate(pts)}
        for what in [w for w in self._handles if w not in targets and w not in self._dragging]:
            self._handles.pop(what).remove()
            self._handle_frame.pop(what, None)
        if not targets:
            return
        wxyz = camera_wxyz(cam.R)
        for what, uv in targets.items():
            self._handle_frame[what] = (view.stem, cam)
            handle = self._handles.get(what)
            if handle is None:
                handle = self.scene.add_transform_controls(
                    f"{self._nodes}/{what.path}", scale=HANDLE_SCALE, disable_rotations=True,
                    disable_sliders=True, active_axes=(True, True, False), depth_test=False, wxyz=wxyz,
                    position=pixel_to_plane(cam, uv))
                handle.on_update(self._drag_callback(what))
                self._handles[what] = handle
            elif what not in self._dragging:
                handle.wxyz, handle.position = wxyz, pixel_to_plane(cam, uv)

    def _drag_callback(self, what: HandleTarget):
        """An ``async`` callback: viser awaits those on its event loop in the order the browser sent
        them, so a drag's start is always seen before its end. It only records the phases; the edit
        itself runs on this tab's queue, one after the other in the order they were made."""

        async def on_update(event) -> None:
            if event.phase == "start":
                self.grabs += 1
                self._dragging[what] = self._handle_frame.get(what)  # the frame the drag began on
            elif event.phase == "end":
                began_on = self._dragging.pop(what, None) or self._handle_frame.get(what)
                if began_on is not None and not self._closed:
                    stem, cam = began_on
                    position = np.array(event.target.position, float)
                    self._queue.submit(self._run, lambda: self.release(stem, what, cam, position))

        return on_update

    def on_drag(self, event, stem: str, what: HandleTarget, cam) -> None:
        """A drag event of the handle ``what`` placed on ``stem`` with ``cam``: the release edits."""
        if event.phase == "end":
            self.release(stem, what, cam, event.target.position)

    def release(self, stem: str, what: HandleTarget, cam, position) -> None:
        """A handle was released at ``position`` (on the image plane of ``cam``): the edit goes to
        ``stem``, the frame the drag began on, whatever this tab shows now."""
        self.releases += 1
        uv = plane_to_pixel(cam, position)
        t0 = time.perf_counter()

        def edit() -> None:
            if isinstance(what, KeypointHandle):
                self.state.move_keypoint(stem, what.kid, *uv)
            else:
                self.state.move_line_point(stem, what.cls, what.index, *uv)
            self.state.view(stem, self.settings)  # recalibrate now, to time it
            self.last_recalibration_ms = 1e3 * (time.perf_counter() - t0)

        self._guarded(edit)

    def camera_view(self) -> None:
        """Put the browser camera at the estimated pose: the overlays then sit on the image."""
        if self.client is None:
            return
        view = self.view()
        cam = view.camera
        if cam is None:
            return
        with self.client.atomic():
            self.client.camera.fov = 2 * math.atan((view.size[1] / 2) / cam.fy)
            self.client.camera.position = cam.C
            self.client.camera.wxyz = camera_wxyz(cam.R)

    # ------------------------------------------------------------------ navigation
    def visible_order(self) -> list[int]:
        st = self.state
        f, s = self.filter.value, self.sort.value
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
        with self._lock:
            order = self.visible_order()
            if not order:
                self.notify("no match", f"no frame matches the filter '{self.filter.value}'; showing {self.stem}",
                            error=False)
            self.order = order or [self.index]
            self.slider.max = max(1, len(self.order) - 1)
            pos = self.order.index(self.index) if self.index in self.order else 0
            self.slider.value = pos
            self.goto(self.order[pos], from_slider=True)

    def step(self, delta: int) -> None:
        with self._lock:
            pos = self.order.index(self.index) if self.index in self.order else 0
            pos = int(np.clip(pos + delta, 0, len(self.order) - 1))
            self.slider.value = pos
            self.goto(self.order[pos], from_slider=True)

    def goto(self, index: int, from_slider: bool = False) -> None:
        with self._lock:
            self.index = int(np.clip(index, 0, len(self.state.stems) - 1))
            if not from_slider and self.index in self.order:
                self.slider.value = self.order.index(self.index)
            self.show()

    # ------------------------------------------------------------------ drawing
    def show(self) -> FrameView | None:
        """Recompute (or fetch from the cache) this tab's frame and send it to this tab."""
        with self._lock:
            if self._closed:
                return None
            st = self.state
            if st.needs_detection(self.stem):
                self.app.detect_in_background(self.stem)
            view = self.view()
            image = render(view, st.image(view.stem), self.layers)
            with self._atomic():
                self.title.content = f"### {view.stem}"
                self.image.image = image
                self.card.content = calibration_card(view, st)
                self._update_scene(view, image)
                self.show_progress()
            return view

    def show_progress(self) -> None:
        done, total = self.state.review_progress()
        counts = self.state.edits.counts()
        self.progress.value = 100.0 * done / total
        self.progress_text.content = f"{done} of {total} reviewed: " + ", ".join(f"{k} {v}" for k, v in counts.items())

    def _atomic(self):
        return self.client.atomic() if self.client is not None else self.app.server.atomic()

    def close(self) -> None:
        """The tab is gone: stop drawing (its GUI and scene nodes went with its connection). Edits
        already released still go through."""
        with self._lock:
            self._closed = True
        self._queue.shutdown(wait=False)
