"""``pnlviz serve``: the viser app. The frame with its overlays sits on the estimated camera's
frustum in a 3D model of the pitch; panels navigate, show the calibration card, switch PnL and its
weight, and record the review status of each frame (autosaved beside the data).

GUI objects live here; everything they show comes from :class:`pnlviz.app.state.AppState`.
"""

from __future__ import annotations

import math
import threading
import time

import numpy as np
import viser
from scipy.spatial.transform import Rotation

from pnlviz.app.overlay import SET_BGR, Layers, render
from pnlviz.app.state import REVIEW_STATES, SOURCES, AppState, FrameView
from pnlviz.field.meshes import goals_mesh, grass_mesh, markings_mesh, nets_mesh

FILTERS = ("all", "failed", "unreviewed", "accepted", "corrected", "rejected")
SORTS = ("index", "JaC@5 (worst first)", "residual (worst first)")
FRUSTUM_SCALE = 4.0  # metres: size of the image plane in the 3D view
HANDLE_SCALE = FRUSTUM_SCALE * 0.035  # arrows of the drag handles, metres on the image plane


def camera_wxyz(R: np.ndarray) -> np.ndarray:
    """viser orientation (camera-to-world quaternion, w first) of a world-to-camera rotation."""
    x, y, z, w = Rotation.from_matrix(R.T).as_quat()
    return np.array([w, x, y, z])


def pixel_to_plane(cam, uv, depth: float = FRUSTUM_SCALE * 0.99) -> np.ndarray:
    """World point on the frustum's image plane (``depth`` in front of the camera) under pixel uv."""
    ray = np.array([(uv[0] - cam.cx) / cam.fx, (uv[1] - cam.cy) / cam.fy, 1.0])
    return cam.C + cam.R.T @ (depth * ray)


def plane_to_pixel(cam, point) -> np.ndarray:
    x = cam.R @ (np.asarray(point, float) - cam.C)
    return np.array([cam.fx * x[0] / x[2] + cam.cx, cam.fy * x[1] / x[2] + cam.cy])


def ray_to_pixel(cam, origin, direction, depth: float = FRUSTUM_SCALE * 0.999) -> np.ndarray | None:
    """Pixel where a click ray meets the frustum's image plane, or None."""
    o = cam.R @ (np.asarray(origin, float) - cam.C)
    d = cam.R @ np.asarray(direction, float)
    if abs(d[2]) < 1e-12:
        return None
    t = (depth - o[2]) / d[2]
    if t <= 0:
        return None
    p = o + t * d
    return np.array([cam.fx * p[0] / p[2] + cam.cx, cam.fy * p[1] / p[2] + cam.cy])


def calibration_card(view: FrameView, state: AppState) -> str:
    """Markdown of the calibration card."""
    lines = [f"**{view.stem}** ({view.index + 1}/{len(state.stems)}), {view.size[0]}x{view.size[1]}"]
    review = state.edits.review(view.stem)
    lines.append(f"review: **{review or 'not reviewed'}**")
    if view.error:
        lines.append(f"**error**: {view.error}")
    res = view.result
    if view.origin is not None:
        settings = state.applied_detection_settings(view.origin)
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


class PnlvizApp:
    def __init__(self, state: AppState, host: str = "127.0.0.1", port: int = 8080):
        self.state = state
        self.layers = Layers()
        self.order = list(range(len(state.stems)))
        self.server = viser.ViserServer(host=host, port=port, label="pnlviz", verbose=False)
        self.server.scene.set_up_direction("-z")  # SoccerNet world: z points down
        # the first view: the whole pitch from high above the main stand
        self.server.initial_camera.position = (0.0, 95.0, -70.0)
        self.server.initial_camera.look_at = (0.0, 0.0, 0.0)
        self.server.initial_camera.up = (0.0, 0.0, -1.0)
        self._lock = threading.RLock()
        self._frustum = self._rays = None
        self._handles: list = []
        self._detecting: set[str] = set()
        self._shown_camera = None
        self.last_recalibration_ms = 0.0
        self._add_pitch()
        self._build_gui()
        self.show()
        self._stop = threading.Event()
        self._worker = threading.Thread(target=self._calibrate_all, daemon=True)
        self._worker.start()

    @property
    def url(self) -> str:
        return f"http://{self.server.get_host()}:{self.server.get_port()}"

    # ------------------------------------------------------------------ scene
    def _add_pitch(self) -> None:
        sc = self.server.scene
        # light from above the pitch (z points down in this world)
        sc.add_light_ambient("/lights/ambient", intensity=0.6)
        sc.add_light_directional("/lights/sun", intensity=2.0, position=(30.0, 40.0, -100.0))
        g = grass_mesh()
        sc.add_mesh_simple("/pitch/grass", g.vertices + [0, 0, 0.01], g.faces, color=(40, 110, 50), side="double")
        m = markings_mesh()
        sc.add_mesh_simple("/pitch/markings", m.vertices, m.faces, color=(245, 245, 245), side="double")
        gm = goals_mesh()
        sc.add_mesh_simple("/pitch/goals", gm.vertices, gm.faces, color=(255, 255, 255))
        n = nets_mesh()
        sc.add_mesh_simple("/pitch/nets", n.vertices, n.faces, color=(200, 200, 210), opacity=0.35, side="double")

    def _update_scene(self, view: FrameView, image: np.ndarray) -> None:
        sc = self.server.scene
        res = view.result
        cam = res.camera if res is not None and res.ok else view.reference_camera
        if cam is None:  # a failed frame without a known camera: nothing to place in the scene
            for handle in (self._frustum, self._rays):
                if handle is not None:
                    handle.remove()
            self._frustum = self._rays = None
            self._shown_camera = None
            self._update_handles(view, None)
            return
        self._shown_camera = cam
        W, H = view.size
        fov_y = 2 * math.atan((H / 2) / cam.fy)
        self._frustum = sc.add_camera_frustum(
            "/camera", fov=fov_y, aspect=W / H, scale=FRUSTUM_SCALE, image=image, format="jpeg",
            jpeg_quality=85, wxyz=camera_wxyz(cam.R), position=cam.C, color=(255, 190, 40))
        obs = view.observations
        if obs is not None and obs.n_keypoints:
            seg = np.stack([np.repeat(cam.C[None], obs.n_keypoints, 0), obs.kp_xyz], axis=1)
            cols = np.array([SET_BGR.get(str(s), (255, 255, 255))[::-1] for s in obs.kp_sets], np.uint8)
            self._rays = sc.add_line_segments("/rays", seg, np.repeat(cols[:, None], 2, 1), thickness=1.5,
                                              thickness_units="screen")
        elif self._rays is not None:  # no keypoints on this frame: no rays from the previous one
            self._rays.remove()
            self._rays = None
        self._update_handles(view, cam)

    def _update_handles(self, view: FrameView, cam) -> None:
        """Drag handles on the image plane for keypoints or annotated line points."""
        for h in self._handles:
            h.remove()
        self._handles = []
        mode = self.handles_mode.value
        if cam is None or mode == "off":
            return
        targets = []  # (what, uv)
        if mode == "keypoints" and view.observations is not None:
            targets = [(("kp", int(k)), p) for k, p in zip(view.observations.kp_ids, view.observations.kp_xy)]
        elif mode == "line points" and view.annotation:
            W, H = view.size
            targets = [(("line", name, i), p * [W - 1, H - 1]) for name, pts in view.annotation.items()
                       for i, p in enumerate(pts)]
        wxyz = camera_wxyz(cam.R)
        for n, (what, uv) in enumerate(targets):
            h = self.server.scene.add_transform_controls(
                f"/handles/{n}", scale=HANDLE_SCALE, disable_rotations=True, disable_sliders=True,
                active_axes=(True, True, False), depth_test=False, wxyz=wxyz, position=pixel_to_plane(cam, uv))
            h.on_update(lambda event, what=what, cam=cam: self._on_drag(event, what, cam))
            self._handles.append(h)

    def _on_drag(self, event, what, cam) -> None:
        if event.phase != "end":
            return
        uv = plane_to_pixel(cam, event.target.position)
        t0 = time.perf_counter()
        if what[0] == "kp":
            self.state.move_keypoint(what[1], *uv)
        else:
            self.state.move_line_point(what[1], what[2], *uv)
        self.state.view()  # recalibrate now, to time it
        self.last_recalibration_ms = 1e3 * (time.perf_counter() - t0)
        self.show()

    def camera_view(self, client: viser.ClientHandle) -> None:
        """Put the browser camera at the estimated pose: the overlays then sit on the image."""
        view = self.state.view()
        cam = view.result.camera if view.result is not None and view.result.ok else view.reference_camera
        if cam is None:
            return
        with client.atomic():
            client.camera.fov = 2 * math.atan((view.size[1] / 2) / cam.fy)
            client.camera.position = cam.C
            client.camera.wxyz = camera_wxyz(cam.R)

    # ------------------------------------------------------------------ GUI
    def _build_gui(self) -> None:
        gui, st = self.server.gui, self.state
        gui.configure_theme(control_width="large")
        with gui.add_folder("Frame"):
            self.title = gui.add_markdown("")
            self.slider = gui.add_slider("frame", min=0, max=max(1, len(st.stems) - 1), step=1, initial_value=st.index)
            self.nav = gui.add_button_group("navigate", ("previous", "next"))
            self.jump = gui.add_text("jump to stem", initial_value="")
            self.filter = gui.add_dropdown("filter", FILTERS, initial_value="all")
            self.sort = gui.add_dropdown("sort", SORTS, initial_value="index")
            self.cam_button = gui.add_button("camera view")
        self.image = gui.add_image(np.zeros((54, 96, 3), np.uint8), label="frame", format="jpeg")
        with gui.add_folder("Calibration"):
            self.card = gui.add_markdown("")
        with gui.add_folder("Settings"):
            self.pnl = gui.add_checkbox("PnL refinement", initial_value=st.pnl)
            self.alpha = gui.add_slider("alpha (lines vs points)", min=0.0, max=1.0, step=0.05, initial_value=st.alpha)
            sources = SOURCES if st.predictions is not None else ("annotation",)
            self.source = gui.add_dropdown("keypoint source", sources, initial_value=st.source)
            self.layer_boxes = {name: gui.add_checkbox(name.replace("_", " "), initial_value=getattr(self.layers, name))
                                for name in ("annotation", "keypoints", "ids", "initial_pitch", "refined_pitch", "residuals",
                                             "reference_pitch", "detected_lines")}
        with gui.add_folder("Edit"):
            self.handles_mode = gui.add_dropdown("drag handles", ("off", "keypoints", "line points"), initial_value="off",
                                                 hint="drag a handle on the image plane; the frame recalibrates on release")
            self.history = gui.add_button_group("history", ("undo", "redo"))
            self.kp_id = gui.add_dropdown("keypoint", tuple(str(i) for i in range(1, 74)), initial_value="1",
                                          hint="shift+click on the image places this keypoint")
            self.kp_hide = gui.add_button("mark keypoint not visible")
            self.export = gui.add_button("export labels (zip)")
        with gui.add_folder("Review"):
            self.review = gui.add_button_group("status", REVIEW_STATES + ("clear",))
            self.progress = gui.add_progress_bar(0.0)
            self.progress_text = gui.add_markdown("")
            self.background = gui.add_markdown("")

        # keyboard shortcuts (viser's command palette; none clashes with its camera keys)
        commands = gui.add_command("next frame", hotkey="N", description="N"), \
            gui.add_command("previous frame", hotkey="P", description="P"), \
            gui.add_command("undo edit", hotkey="Z", modifier="cmd/ctrl", description="Ctrl+Z"), \
            gui.add_command("redo edit", hotkey="Z", modifier="cmd/ctrl+shift", description="Ctrl+Shift+Z"), \
            gui.add_command("camera view", hotkey="V", description="V")
        actions = (lambda e: self.step(1), lambda e: self.step(-1),
                   lambda e: (st.undo(), self.show()), lambda e: (st.redo(), self.show()),
                   lambda e: self.camera_view(e.client) if e.client is not None else None)
        for command, action in zip(commands, actions):
            command.on_trigger(action)

        @self.slider.on_update
        def _(_) -> None:
            self.goto(self.order[int(self.slider.value)] if self.order else 0, from_slider=True)

        @self.nav.on_click
        def _(event) -> None:
            self.step(-1 if event.target.value == "previous" else 1)

        @self.jump.on_update
        def _(_) -> None:
            idx = st.find(self.jump.value)
            if idx is not None:
                self.goto(idx)

        @self.filter.on_update
        def _(_) -> None:
            self.refresh_order()

        @self.sort.on_update
        def _(_) -> None:
            self.refresh_order()

        @self.cam_button.on_click
        def _(event) -> None:
            if event.client is not None:
                self.camera_view(event.client)

        @self.pnl.on_update
        def _(_) -> None:
            st.pnl = bool(self.pnl.value)
            self.show()

        @self.alpha.on_update
        def _(_) -> None:
            st.alpha = float(self.alpha.value)
            self.show()

        @self.source.on_update
        def _(_) -> None:
            st.source = self.source.value
            self.show()

        for name, box in self.layer_boxes.items():
            def on_layer(_, name=name, box=box) -> None:
                setattr(self.layers, name, bool(box.value))
                self.show()

            box.on_update(on_layer)

        @self.handles_mode.on_update
        def _(_) -> None:
            self.show()

        @self.history.on_click
        def _(event) -> None:
            (st.undo if event.target.value == "undo" else st.redo)()
            self.show()

        @self.kp_hide.on_click
        def _(_) -> None:
            st.hide_keypoint(int(self.kp_id.value))
            self.show()

        @self.export.on_click
        def _(event) -> None:
            from pnlviz.app.export import export_zip_bytes

            if event.client is not None:
                event.client.send_file_download(f"{self.state.data.name}_labels.zip", export_zip_bytes(st),
                                                save_immediately=True)

        @self.server.scene.on_click(modifier="shift")
        def _(event) -> None:
            cam = self._shown_camera
            if cam is None:
                return
            uv = ray_to_pixel(cam, event.ray_origin, event.ray_direction)
            if uv is not None:
                st.move_keypoint(int(self.kp_id.value), *uv)
                self.show()

        @self.review.on_click
        def _(event) -> None:
            value = event.target.value
            st.set_review(None if value == "clear" else value)
            self.show()

    # ------------------------------------------------------------------ navigation
    def visible_order(self) -> list[int]:
        st = self.state
        f, s = self.filter.value, self.sort.value
        views = {v.stem: v for v in st.cached_views()}
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
            self.order = self.visible_order() or [self.state.index]
            self.slider.max = max(1, len(self.order) - 1)
            pos = self.order.index(self.state.index) if self.state.index in self.order else 0
            self.slider.value = pos
            self.goto(self.order[pos])

    def step(self, delta: int) -> None:
        with self._lock:
            pos = self.order.index(self.state.index) if self.state.index in self.order else 0
            pos = int(np.clip(pos + delta, 0, len(self.order) - 1))
            self.slider.value = pos
            self.goto(self.order[pos], from_slider=True)

    def goto(self, index: int, from_slider: bool = False) -> None:
        with self._lock:
            self.state.go(index)
            if not from_slider and index in self.order:
                self.slider.value = self.order.index(index)
            self.show()

    def _detect_in_background(self, stem: str) -> None:
        """Run the detector on a frame off the GUI thread, then refresh if it is still shown."""
        if stem in self._detecting:
            return
        self._detecting.add(stem)

        def work():
            try:
                self.background.content = f"detecting on {stem} (light model: < 1 s; published networks: ~13 s on 2 cores)..."
                self.state.run_detector(stem)
                self.background.content = f"detections ready for {stem}"
                if self.state.stem == stem:
                    self.show()
            except Exception as exc:  # shown, never fatal
                self.background.content = f"detection failed on {stem}: {exc}"
            finally:
                self._detecting.discard(stem)

        threading.Thread(target=work, daemon=True).start()

    def show(self) -> FrameView:
        """Recompute (or fetch from the cache) the current frame and push it to every client."""
        with self._lock:
            st = self.state
            if st.needs_detection(st.stem):
                self._detect_in_background(st.stem)
            view = st.view()
            image = render(view, st.image(view.stem), self.layers)
            with self.server.atomic():
                self.title.content = f"### {view.stem}"
                self.image.image = image
                self.card.content = calibration_card(view, st)
                self._update_scene(view, image)
                done, total = st.review_progress()
                counts = st.edits.counts()
                self.progress.value = 100.0 * done / total
                self.progress_text.content = f"{done} of {total} reviewed: " + ", ".join(f"{k} {v}" for k, v in counts.items())
            return view

    # ------------------------------------------------------------------ background
    def _calibrate_all(self) -> None:
        """Calibrate every frame in the background (current settings) so filters and sorting see
        the whole dataset; the frame on screen always goes first because show() computes it."""
        st = self.state
        n = len(st.stems)
        for i, stem in enumerate(st.stems):
            if self._stop.is_set():
                return
            st.view(stem)
            if i % 10 == 0 or i == n - 1:
                try:
                    self.background.content = f"background calibration: {i + 1}/{n} frames"
                except Exception:
                    return  # server stopped
            time.sleep(0)

    def stop(self) -> None:
        self._stop.set()
        self.server.stop()
