"""What the hand sees in the app, measured in the page: headless Chromium (software WebGL on this
machine) driving ``pnlviz serve``'s app with real mouse and keyboard events.

    python benchmarks/bench_app_browser.py [--frames 300] [--drags 30] [--steps 30] [--gestures 10]

* drag release -> overlay: a keypoint is dragged with the mouse and released; the time from the
  page's ``pointerup`` to the first frame the canvas draws with the overlays as they end up
  (the recalibrated pitch, the residuals). Measured twice: as the app runs (the frame is
  recalibrated while the point moves, so the release mostly confirms what is on screen) and
  with that live preview off (the full round trip: release -> edit saved -> recalibration ->
  overlay sent -> drawn). These times start at the page's ``pointerup``; a page busy drawing
  handles the release late, so the time from the hand's release (the benchmark's ``mouse.up``) to
  that ``pointerup`` is printed apart.
* next frame -> image: ``n`` pressed; the time from the page's ``keydown`` to the first frame
  the canvas draws with the next frame's pixels and overlays as they end up.
* pan and zoom: left drags on the image (10 moves each) and wheel gestures (5 notches each); the
  server's camera pushes per move and per notch (the page pans and zooms by itself: goal 0, one
  push at the end of each gesture) and the time from the input event to the animation frame that
  draws the page's transform (the bridge notes it in ``requestAnimationFrame``).

How: Chromium's screencast hands over every frame it composites, with its time; the page notes
when the event happened (same clock); once the scene has settled, the first frame after the
event whose patch around the change equals the settled one is when the change became visible.
The frames come from ``pnlviz synth`` (made once into a temporary folder). Prints p50/p95 and
the server process's peak memory.
"""

from __future__ import annotations

import argparse
import base64
import contextlib
import resource
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np
from playwright.sync_api import Error as PlaywrightError, sync_playwright

FLAGS = ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run", "--disable-background-networking",
         "--disable-component-update", "--disable-sync"]

#: the page records when the pointer is released and when a key goes down (wall clock, ms)
EVENTS = """() => {
  if (window.__events) return;
  window.__events = [];
  window.addEventListener("pointerup", () => window.__events.push(["up", Date.now()]), true);
  window.addEventListener("keydown", () => window.__events.push(["key", Date.now()]), true);
  window.addEventListener("wheel", (e) => window.__events.push(["wheel", e.timeStamp]), true);
}"""


class Screencast:
    """The frames Chromium composites, as they come (its DevTools screencast), with their times."""

    def __init__(self, page, width: int = 800):
        self.page, self.frames, self.scale = page, [], width / page.viewport_size["width"]
        self.cdp = page.context.new_cdp_session(page)
        self.cdp.on("Page.screencastFrame", self._frame)
        self.cdp.send("Page.startScreencast", {"format": "jpeg", "quality": 70, "maxWidth": width,
                                               "maxHeight": width, "everyNthFrame": 1})

    def _frame(self, event) -> None:
        self.frames.append((event["metadata"]["timestamp"], event["data"]))
        try:
            self.cdp.send("Page.screencastFrameAck", {"sessionId": event["sessionId"]})
        except PlaywrightError:  # a frame that came as the browser closed: nothing to acknowledge
            pass

    def wait(self, seconds: float) -> None:
        """Let time pass while the frames keep coming (events are handled inside playwright calls)."""
        end = time.time() + seconds
        while time.time() < end:
            self.page.wait_for_timeout(20)

    def crop(self, data: str, region) -> np.ndarray:
        img = cv2.imdecode(np.frombuffer(base64.b64decode(data), np.uint8), cv2.IMREAD_GRAYSCALE)
        x, y, w, h = (int(round(v * self.scale)) for v in region)
        return img[y:y + h, x:x + w].astype(float)

    def visible_after(self, kind: str, region, settle: float = 1.2) -> float | None:
        """ms from the page's last ``kind`` event to the first composited frame showing the
        ``region`` (CSS px: x, y, w, h) as it is once everything has settled."""
        n0 = len(self.frames)
        self.wait(settle)
        events = self.page.evaluate("() => window.__events")
        t0 = [t for k, t in events if k == kind][-1] / 1000.0
        return self.settled_since(n0, t0, region, 1.5)

    def settled_since(self, n0: int, t0: float, region, tolerance: float, changed: bool = False) -> float | None:
        """ms from ``t0`` (seconds, wall clock) to the first frame composited at ``t0`` or later
        (among those from ``n0 - 5`` on) whose ``region`` is within ``tolerance`` grey levels (mean)
        of the last frame's, the settled picture; with ``changed``, also unlike the last frame
        before ``t0``. None: no such frame (with ``changed``: or no frame before ``t0``); 0.0: no
        frame after ``t0`` (the screen already showed it), unless ``changed``."""
        frames = [f for f in self.frames[max(0, n0 - 5):] if f[0] >= t0 - 0.001]
        before = [f for f in self.frames if f[0] < t0 - 0.001] if changed else []
        if not frames or (changed and not before):
            return None if changed else 0.0
        pre = self.crop(before[-1][1], region) if changed else None
        final = self.crop(frames[-1][1], region)
        for t, data in frames:
            shown = self.crop(data, region)
            if (pre is None or not np.array_equal(shown, pre)) and np.mean(np.abs(shown - final)) < tolerance:
                return 1e3 * (t - t0)
        return None


@contextlib.contextmanager
def served_page(frames: int, init_script: str | None = None, data: Path | None = None):
    """``pnlviz serve``'s app on a fresh ``pnlviz synth`` set of ``frames`` frames (seed 5), or on
    ``data`` when given (its background pass working, as the command runs it), and a headless
    Chromium page on it at 1600x900 (``init_script`` run before the page's own): yields (app,
    page, browser). The app is stopped and the set removed afterwards (``data`` is left as it is;
    the edits go to a temporary folder)."""
    from pnlviz.app.server import PnlvizApp
    from pnlviz.app.state import AppState

    tmp = Path(tempfile.mkdtemp(prefix="pnlviz-bench-"))
    try:
        if data is None:
            data = tmp / "set"
            subprocess.run([sys.executable, "-m", "pnlviz.cli", "synth", "--out", str(data), "-n", str(frames),
                            "--seed", "5", "--workers", "2", "--no-progress"], check=True)
        app = PnlvizApp(AppState(data, edits=tmp / "edits"), port=free_port())
        try:
            with sync_playwright() as pw:
                browser = pw.chromium.launch(executable_path=shutil.which("chromium"), args=FLAGS)
                try:
                    page = browser.new_page(viewport={"width": 1600, "height": 900})
                    if init_script:
                        page.add_init_script(init_script)
                    page.goto(app.page_url)
                    page.get_by_text("review:").first.wait_for(timeout=60_000)
                    yield app, page, browser
                finally:
                    browser.close()
        finally:
            app.stop()
            app.state.close()
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def percentiles(values) -> str:
    v = np.array([x for x in values if x is not None])
    missed = len(values) - len(v)
    if not len(v):
        return "no sample"
    return (f"p50 {np.percentile(v, 50):.0f} ms, p95 {np.percentile(v, 95):.0f} ms, max {v.max():.0f} ms "
            f"({len(v)} events" + (f", {missed} not seen" if missed else "") + ")")


def idle(page, control, timeout: float = 30.0) -> None:
    """Wait until the page draws the server's latest view and has drawn two frames since (a
    gesture starts on a page that is not busy drawing)."""
    deadline = time.time() + timeout
    while time.time() < deadline and page.evaluate("() => window.__pnlvizBridge.base") != control.version:
        time.sleep(0.05)
    page.evaluate("() => new Promise((done) => requestAnimationFrame(() => requestAnimationFrame(done)))")
    time.sleep(0.3)


def pan_and_zoom(page, session, box, n: int):
    """``n`` pans (10 mouse moves each, from a spot with no point near) and ``n`` wheel zooms (5
    notches each): for each kind, (steps, camera pushes during the steps, pushes after them, the
    page's input -> frame latencies in ms)."""
    control = session.view_control
    out = []
    for kind in ("pan", "zoom"):
        steps = during = after = 0
        page.evaluate("() => { window.__pnlvizBridge.latency = []; }")
        for i in range(n):
            session.queue.enqueue(control.fit)
            session.flush()
            idle(page, control)
            view, canvas = control.view2d, np.array(control.canvas)
            pts = [nd.uv for nd in session.workspace.points.values() if len(nd.keys)]
            pts = np.concatenate(pts) if pts else np.zeros((0, 2))
            screen = view.to_screen(pts, tuple(canvas)) if len(pts) else np.zeros((0, 2))
            spots = [(x, y) for y in range(200, int(canvas[1]) - 200, 20) for x in range(200, int(canvas[0]) - 250, 20)
                     if not len(screen) or np.min(np.hypot(*(screen - [x, y]).T)) > 40]
            x, y = box["x"] + spots[i % len(spots)][0], box["y"] + spots[i % len(spots)][1]
            pushes = control.pushes
            page.mouse.move(x, y)
            if kind == "pan":
                page.mouse.down()
                for k in range(1, 11):
                    page.mouse.move(x + 5 * k, y + 3 * k)
                    time.sleep(0.03)
            else:
                for k in range(5):
                    page.mouse.wheel(0, -100 if i % 2 == 0 else 100)
                    time.sleep(0.03)
            now = control.pushes - pushes  # while the hand moved (the wheel waits 120 ms idle)
            if kind == "pan":
                page.mouse.up()
            time.sleep(1.0)
            session.flush()
            steps += 10 if kind == "pan" else 5
            during, after = during + now, after + control.pushes - pushes - now
        out.append((steps, during, after, page.evaluate("() => window.__pnlvizBridge.latency")))
    wheel = np.array([t for k, t in page.evaluate("() => window.__events") if k == "wheel"])
    gaps = np.diff(wheel)[np.diff(wheel) < 900]  # between the notches of a gesture (gestures are > 1 s apart)
    print(f"wheel notches arrived {np.median(gaps):.0f} ms apart (median); {np.mean(gaps > 120):.0%} of the gaps "
          f"were over the 120 ms that end a gesture (the page was busy drawing)")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=300, help="synthetic frames in the set served")
    ap.add_argument("--drags", type=int, default=30)
    ap.add_argument("--steps", type=int, default=30, help="'next frame' presses")
    ap.add_argument("--gestures", type=int, default=10, help="pans and wheel zooms, each")
    ap.add_argument("--data", type=Path, help="serve this folder instead of making a synthetic set")
    ap.add_argument("--hide", nargs="*", default=[], help="overlay layers to switch off (e.g. ids ghosts)")
    args = ap.parse_args()

    with served_page(args.frames, f"({EVENTS})()", data=args.data) as (app, page, _):
        deadline = time.time() + 20
        while time.time() < deadline and not (app.tabs() and app.tabs()[0].view_control.css_canvas):
            time.sleep(0.2)
        session = app.tabs()[0]
        for layer in args.hide:
            session.queue.enqueue(lambda layer=layer: session.painter.set_layer(layer, False))
        session.flush()
        print(f"served {len(app.state.stems)} frames from {app.state.data}; browser canvas {session.view_control.canvas[0]}x"
              f"{session.view_control.canvas[1]} CSS px, WebGL: "
              + page.evaluate("() => { const gl = document.createElement('canvas').getContext('webgl');"
                              "const i = gl.getExtension('WEBGL_debug_renderer_info');"
                              "return i ? gl.getParameter(i.UNMASKED_RENDERER_WEBGL) : 'unknown'; }"))
        cast = Screencast(page)
        box = max((c.bounding_box() for c in page.locator("canvas[data-engine]").all()),
                  key=lambda b: b["width"] * b["height"])  # the viewer's (three.js marks it)

        delays: dict[str, list[float]] = {}  # the hand's release -> the page's pointerup, per kind of drag

        def drags(n: int, kind: str) -> list[float | None]:
            out = []
            for i in range(n):
                view = session.view()
                obs = view.observations
                if obs is None or not obs.n_keypoints or not view.result or not view.result.ok:
                    session.queue.enqueue(lambda: session.step(1))
                    session.flush()
                    continue
                k = i % obs.n_keypoints
                uv = obs.kp_xy[k]
                x, y = session.view_control.view2d.to_screen(uv, session.view_control.canvas)
                region = (box["x"] + max(0, x - 150), box["y"] + max(0, y - 100), 300, 200)
                cast.wait(0.3)
                page.mouse.move(box["x"] + x, box["y"] + y)
                page.mouse.down()
                for step in range(1, 6):
                    page.mouse.move(box["x"] + x + 2 * step, box["y"] + y + step)
                    cast.wait(0.04)
                hand = time.time()
                page.mouse.up()
                out.append(cast.visible_after("up", region))
                page_up = [t for k, t in page.evaluate("() => window.__events") if k == "up"][-1] / 1000.0
                delays.setdefault(kind, []).append(1e3 * (page_up - hand))
                session.queue.enqueue(lambda: session.step(1))  # a fresh frame for the next drag
                session.flush()
                cast.wait(0.5)
            return out

        live = drags(args.drags, "live")
        session.editor.live_preview = False
        round_trip = drags(args.drags, "round trip")
        session.editor.live_preview = True
        steps = []
        for _ in range(args.steps):
            x, y = box["x"] + session.view_control.canvas[0] / 2, box["y"] + session.view_control.canvas[1] / 3
            cast.wait(0.3)
            page.keyboard.press("n")
            steps.append(cast.visible_after("key", (x - 200, y - 100, 400, 200), settle=1.0))
        pans, zooms = pan_and_zoom(page, session, box, args.gestures)
        print(f"drag release -> overlay (live preview, as the app runs): {percentiles(live)}")
        print(f"drag release -> overlay (no preview: release -> save -> recalibrate -> send -> draw): "
              f"{percentiles(round_trip)}")
        # the times above run from the page's pointerup; a page busy drawing sees the release late
        print("the hand's release -> the page's pointerup (not in the times above): "
              + "; ".join(f"{kind} {percentiles(d)}" for kind, d in delays.items()))
        print(f"next frame -> image: {percentiles(steps)}")
        print(f"server-side recalibration of the last drag: {session.editor.last_recalibration_ms:.0f} ms; previews "
              f"given up because their point was let go elsewhere: {session.editor.previews_given_up}")
        for name, (steps, during, after, latency) in (("pan (mouse move)", pans), ("zoom (wheel notch)", zooms)):
            print(f"{name}: server camera pushes per step {during / max(1, steps):.2f} ({during} during {steps} "
                  f"steps; {after} at the gestures' ends); input -> frame drawn: {percentiles(latency)}")
    print(f"peak memory of this process (server + benchmark): "
          f"{resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB")


if __name__ == "__main__":
    main()
