"""``pnlviz serve``: the viser app. Each frame opens in an image view (zoom, pan, overlays and
points drawn over the picture, points dragged where they belong, the frame recalibrated as they
move); the 3D view shows the estimated camera's frustum over a model of the pitch. Panels
navigate, review, show the calibration card and switch PnL and its weight; every edit and review
is autosaved beside the data.

Each browser tab is a :class:`pnlviz.app.session.Session` with its own frame, view and panel;
this module holds what they share: the viser server (behind :mod:`pnlviz.app.guard`, which
refuses foreign pages), the lights, the background pass over every frame (triage) and the
background detector. Everything shown comes from :class:`pnlviz.app.state.AppState`.
"""

from __future__ import annotations

import functools
import threading

import viser

from pnlviz.app.bridge import page_url
from pnlviz.app.guard import AccessPolicy, guarded_viser_server
from pnlviz.app.session import Session
from pnlviz.app.state import AppState
from pnlviz.app.view2d import FOV_Y, PLANE_Z


class PnlvizApp:
    """The server: one :class:`Session` per connected tab, plus :meth:`session` for a session
    without a browser (scripts and tests drive it like a tab)."""

    def __init__(self, state: AppState, host: str = "127.0.0.1", port: int = 8080, token: str | None = None,
                 allowed_hosts: tuple[str, ...] = ()):
        self.state = state
        self.policy = AccessPolicy(host, token=token, allowed_hosts=allowed_hosts)
        self.server = guarded_viser_server(self.policy, host=host, port=port, label="pnlviz", verbose=False)
        self.policy.port = self.server.get_port()
        self.server.scene.set_up_direction("-z")  # SoccerNet world: z points down
        # the first view, until a tab puts its frame in it: straight at the image plane
        self.server.initial_camera.position = (0.0, 0.0, PLANE_Z - 30.0)
        self.server.initial_camera.look_at = (0.0, 0.0, PLANE_Z)
        self.server.initial_camera.up = (0.0, -1.0, 0.0)
        self.server.initial_camera.fov = FOV_Y
        self.sessions: dict[int, Session] = {}
        self._sessions_lock = threading.Lock()
        self._detecting: set[str] = set()
        self._detection_status: dict[str, str] = {}  # stem -> what the detector is doing or did there
        self._background_text = ""
        self._add_lights()
        state.subscribe(self._frame_changed)
        if state.clips:  # a video: an edit solves its shot again, and every tab on the shot redraws

            state.shots.listen(self._shot_changed)
        self.server.on_client_connect(self._connect)
        self.server.on_client_disconnect(self._disconnect)
        self._stop = threading.Event()
        self._worker = threading.Thread(target=self._calibrate_all, daemon=True)
        self._worker.start()

    @property
    def url(self) -> str:
        """The URL a browser on this machine opens (with the token when one is needed)."""
        return self.policy.urls()[0]

    @property
    def page_url(self) -> str:
        """:attr:`url` with the canvas at a fixed device pixel ratio (``?fixedDpr=1``; a page on
        another ratio reloads once with its own, see :func:`pnlviz.app.bridge.page_url`)."""
        return page_url(self.url)

    def page_urls(self) -> list[str]:
        """Every URL a browser can open (:meth:`AccessPolicy.urls`), as :attr:`page_url` is."""
        return [page_url(u) for u in self.policy.urls()]

    # ------------------------------------------------------------------ tabs
    def _connect(self, client: viser.ClientHandle) -> None:
        session = Session(self, client.gui, client.scene, client)
        with self._sessions_lock:
            self.sessions[client.client_id] = session
        session.panels.background.content = self._background_text
        problems = self.state.problems + self.state.edits.warnings
        if problems:  # the server's log has them all
            more = f" (and {len(problems) - 3} more, listed where the server runs)" if len(problems) > 3 else ""
            session.notify("files not used", "\n".join(problems[:3]) + more)
        session.show()

    def _disconnect(self, client: viser.ClientHandle) -> None:
        with self._sessions_lock:
            session = self.sessions.pop(client.client_id, None)
        if session is not None:
            self._closed(session)

    def close_session(self, session: Session) -> None:
        """Close a tab (what a browser leaving does)."""
        with self._sessions_lock:
            for key in [k for k, v in self.sessions.items() if v is session]:
                del self.sessions[key]
        self._closed(session)

    def _closed(self, session: Session) -> None:
        session.close()
        with self._sessions_lock:
            nobody = not self.sessions
        if nobody:  # no tab needs the frames' views and images any more
            self.state.release_caches()

    def session(self) -> Session:
        """A session on the server's own panels (no browser needed); shown at once."""
        session = Session(self, self.server.gui, self.server.scene, None)
        with self._sessions_lock:
            self.sessions[-1 - len(self.sessions)] = session
        session.show()
        return session

    def _all_sessions(self) -> list[Session]:
        with self._sessions_lock:
            return list(self.sessions.values())

    def tabs(self) -> list[Session]:
        """The sessions of connected browser tabs, oldest first."""
        return [s for s in self._all_sessions() if s.client is not None]

    def _shot_changed(self, stems: list[str], provisional: bool = False) -> None:
        """A shot was solved again after an edit: every tab showing one of its frames redraws (the
        picture alone for a ``provisional`` quick answer: its panel waits for the full one, which
        follows within a few hundred ms; two panel updates a shot edit cost a tab's page 20-40 ms)."""
        shown = set(stems)
        for session in self._all_sessions():
            if session.stem in shown:
                session.queue.enqueue(functools.partial(session.show, panel=not provisional))

    def _frame_changed(self, stem: str) -> None:
        """A frame changed (an edit from any tab, new detections): every tab showing it redraws,
        every tab updates its review progress."""
        for session in self._all_sessions():
            if session.stem == stem:
                session.show()
            else:
                session.painter.show_progress()

    # ------------------------------------------------------------------ scene
    def _add_lights(self) -> None:
        sc = self.server.scene
        # no shadows: the pitch is flat, and a shadow pass (three cascades of viser's default
        # light) would be drawn on every frame, the image view's too
        sc.configure_default_lights(True, cast_shadow=False)
        # no environment map: its reflections lit the image view's invisible grab meshes on every
        # frame (about 10 ms of each software-WebGL frame); the lights below light the 3D pitch
        sc.configure_environment_map(None)
        # light from above the pitch (z points down in this world)
        sc.add_light_ambient("/lights/ambient", intensity=0.6)
        sc.add_light_directional("/lights/sun", intensity=2.0, position=(30.0, 40.0, -100.0))

    # ------------------------------------------------------------------ background
    def _say(self, text: str) -> None:
        """The background pass's progress, in every tab."""
        self._background_text = text
        for session in self._all_sessions():
            session.panels.background.content = text

    def detection_status(self, stem: str) -> str | None:
        """What the detector does or did on ``stem`` (for the tabs showing it), None when nothing."""
        return self._detection_status.get(stem)

    def detect_in_background(self, stem: str) -> None:
        """Run the detector on a frame off the GUI threads; the tabs showing it redraw when done
        (and each tab says so for its own frame only)."""
        if stem in self._detecting:
            return
        self._detecting.add(stem)

        def work():
            self._detection_status[stem] = "detecting (light model: < 1 s; published networks: ~13 s on 2 cores)"
            self._frame_changed(stem)
            try:
                self.state.run_detector(stem)  # announces the change: the tabs on this frame redraw
                self._detection_status.pop(stem, None)
            except Exception as exc:  # noqa: BLE001 - a detector failure is shown, never fatal
                self._detection_status[stem] = f"**detection failed**: {type(exc).__name__}: {exc}"
            finally:
                self._detecting.discard(stem)
            self._frame_changed(stem)  # the status line too (it said "detecting" while they redrew)

        threading.Thread(target=work, daemon=True, name=f"detect-{stem}").start()

    def _calibrate_all(self) -> None:
        """Triage in the background: detect (with a detector) and calibrate every frame under the
        default settings, keeping summaries only (:class:`pnlviz.app.triage.Triage`), so filters,
        counts and sorts see the whole dataset; a frame on a tab's screen is computed by its tab
        meanwhile. Resumes from the summaries kept on disk; every tab's order is refreshed at the end."""
        progress = self.state.triage.run(self._stop, self._say)
        if progress.finished and not self._stop.is_set():
            for session in self._all_sessions():
                session.queue.enqueue(session.refresh_order)

    def stop(self) -> None:
        self._stop.set()
        self._worker.join(timeout=5.0)  # it stops after the frame it is on
        for session in self._all_sessions():
            session.close(wait=True)  # nothing queued for a tab is sent after the server stopped
        self.server.stop()
