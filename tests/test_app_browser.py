"""End to end in real headless Chromium (Debian's, driven by playwright): the page loads, frame
navigation works, PnL toggles, a review status is autosaved and survives a server restart."""

import json
import shutil
import socket
import time

import pytest

from pnlviz import EXAMPLES_DIR

CHROMIUM = shutil.which("chromium")
pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="Debian's chromium is not installed "
                                "(scripts/install_test_deps.sh installs it)")
FLAGS = ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run", "--disable-background-networking",
         "--disable-component-update", "--disable-sync"]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture()
def data(tmp_path):
    src = EXAMPLES_DIR / "sample"
    dst = tmp_path / "set"
    (dst / "cameras").mkdir(parents=True)
    for stem in ("00000", "00001", "00002"):
        for name in (f"{stem}.jpg", f"{stem}.json", f"cameras/camera_{stem}.json"):
            shutil.copy(src / name, dst / name)
    return dst


@pytest.fixture(scope="module")
def browser():
    sync_playwright = pytest.importorskip("playwright.sync_api").sync_playwright
    with sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=CHROMIUM, args=FLAGS)
        yield b
        b.close()


def start(data):
    from pnlviz.app.server import PnlvizApp
    from pnlviz.app.state import AppState

    return PnlvizApp(AppState(data), port=_free_port())


def stop(app):
    app.stop()
    app.state.close()


def wait_for_text(page, text, timeout=20.0):
    page.get_by_text(text).first.wait_for(timeout=timeout * 1000)


def open_page(browser, app, text):
    """A page on the app, once ``text`` shows in the panels."""
    page = browser.new_page(viewport={"width": 1400, "height": 900})
    page.goto(app.url)
    wait_for_text(page, text)
    return page


def tab(app, n: int = 1):
    """The session of the ``n``-th connected browser tab."""
    wait_until(lambda: len(app.tabs()) >= n)
    return app.tabs()[n - 1]


def wait_until(condition, timeout=10.0):
    """Poll the server-side state until ``condition()`` holds (or time runs out)."""
    deadline = time.time() + timeout
    while time.time() < deadline and not condition():
        time.sleep(0.2)


def test_navigate_toggle_pnl_review_and_restart(data, browser):
    app = start(data)
    try:
        page = open_page(browser, app, "00000 (1/3)")
        wait_for_text(page, "focal")
        # navigation
        page.get_by_role("button", name="next").click()
        wait_for_text(page, "00001 (2/3)")
        assert tab(app).stem == "00001"
        # PnL off: the card says so, the server recalibrated without it
        page.get_by_text("PnL refinement").click()
        wait_for_text(page, "PnL set: 0 lines")
        assert tab(app).settings.pnl is False
        # review status: autosaved at once in the edits folder beside the data
        page.get_by_role("button", name="accepted").click()
        wait_for_text(page, "1 of 3 reviewed")
        saved = json.loads((app.state.edits.frames / "00001.json").read_text())
        assert saved["review"] == "accepted"
        page.close()
    finally:
        stop(app)
    # a new server on the same data restores the review
    app = start(data)
    try:
        page = open_page(browser, app, "1 of 3 reviewed")
        page.get_by_role("button", name="next").click()
        wait_for_text(page, "review: accepted")
        page.close()
    finally:
        stop(app)


def test_camera_view_puts_the_browser_camera_on_the_estimated_pose(data, browser):
    import numpy as np

    app = start(data)
    try:
        page = open_page(browser, app, "focal")
        page.get_by_role("button", name="camera view").click()
        cam = tab(app).view().result.camera
        deadline = time.time() + 10
        while time.time() < deadline:
            clients = list(app.server.get_clients().values())
            if clients and np.allclose(clients[0].camera.position, cam.C, atol=1e-3):
                break
            time.sleep(0.2)
        assert np.allclose(clients[0].camera.position, cam.C, atol=1e-3)
        page.close()
    finally:
        stop(app)


def test_place_a_keypoint_undo_redo_export_and_restart(data, browser, tmp_path):
    import zipfile

    import numpy as np

    app = start(data)
    try:
        page = open_page(browser, app, "focal")
        session = tab(app)
        stem = session.stem
        before = session.view().result.camera.C.copy()
        obs = session.view().observations
        # a keypoint in the left half of the frame (the panel covers the right), nudged by 6 px:
        # still an inlier, so the calibration follows it
        i = int(np.argmin(obs.kp_xy[:, 0]))
        kid = str(int(obs.kp_ids[i]))
        u, v = obs.kp_xy[i] + [6.0, 4.0]
        session.kp_id.value = kid  # choose the id...
        session.flush()
        page.get_by_role("button", name="camera view").click()
        time.sleep(2.0)
        # ...and shift+click on the image. In camera view the canvas shows the frame with the
        # frame's vertical field of view, centred: pixel (u, v) is at this canvas point.
        box = page.locator("canvas").first.bounding_box()
        W, H = session.view().size
        s = box["height"] / H
        page.keyboard.down("Shift")
        page.mouse.click(box["x"] + box["width"] / 2 + (u - W / 2) * s, box["y"] + v * s)
        page.keyboard.up("Shift")
        wait_until(lambda: "keypoints" in app.state.edits.get(stem))
        placed = app.state.edits.get(stem)["keypoints"][kid]
        np.testing.assert_allclose(placed, [u, v], atol=3.0)
        moved = session.view().result.camera.C.copy()
        assert not np.allclose(moved, before)
        # undo restores the calibration, redo brings the edit back
        page.get_by_role("button", name="undo").click()
        wait_until(lambda: not app.state.edits.get(stem).get("keypoints"))
        np.testing.assert_allclose(session.view().result.camera.C, before)
        page.get_by_role("button", name="redo").click()
        wait_until(lambda: bool(app.state.edits.get(stem).get("keypoints")))
        # export downloads a zip whose labels hold the edit
        with page.expect_download(timeout=30000) as dl:
            page.get_by_role("button", name="export labels (zip)").click()
        path = tmp_path / "labels.zip"
        dl.value.save_as(path)
        with zipfile.ZipFile(path) as zf:
            kps = json.loads(zf.read(f"keypoints/{stem}.json"))["keypoints"]
        np.testing.assert_allclose([kps[kid]["x"], kps[kid]["y"]], placed)
        page.close()
    finally:
        stop(app)
    # a restarted server keeps the edit
    app = start(data)
    try:
        np.testing.assert_allclose(app.state.edits.get(stem)["keypoints"][kid], placed)
        np.testing.assert_allclose(app.state.view(stem).result.camera.C, moved)
    finally:
        stop(app)


def test_dragging_a_keypoint_handle_recalibrates_and_autosaves(data, browser):
    import numpy as np

    from pnlviz.app.scene import HANDLE_SCALE

    app = start(data)
    try:
        page = open_page(browser, app, "focal")
        session = tab(app)
        stem = session.stem
        before = session.view().result.camera.C.copy()
        session.handles_mode.value = "keypoints"
        session.flush()
        page.get_by_role("button", name="camera view").click()
        time.sleep(2.5)
        view = session.view()
        obs, cam = view.observations, view.result.camera
        i = int(np.argmin(obs.kp_xy[:, 0]))  # left of the frame, away from the panel
        kid, (u, v) = str(int(obs.kp_ids[i])), obs.kp_xy[i]
        box = page.locator("canvas").first.bounding_box()
        W, H = view.size
        s = box["height"] / H
        x0, y0 = box["x"] + box["width"] / 2 + (u - W / 2) * s, box["y"] + v * s
        arrow = HANDLE_SCALE / (0.99 * 4.0) * cam.fx * s  # screen length of the handle's x arrow
        # grab the x arrow half way along and pull it 20 screen px to the right
        page.mouse.move(x0 + 0.5 * arrow, y0)
        page.mouse.down()
        page.mouse.move(x0 + 0.5 * arrow + 10, y0, steps=5)
        page.mouse.move(x0 + 0.5 * arrow + 20, y0, steps=5)
        page.mouse.up()
        wait_until(lambda: bool(app.state.edits.get(stem).get("keypoints")))
        moved = app.state.edits.get(stem)["keypoints"][kid]
        np.testing.assert_allclose(moved, [u + 20 / s, v], atol=2.0)  # along x only, by the pulled amount
        assert not np.allclose(session.view().result.camera.C, before)
        page.close()
    finally:
        stop(app)


def test_keyboard_shortcuts_n_p_and_ctrl_z(data, browser):
    app = start(data)
    try:
        page = open_page(browser, app, "00000 (1/3)")
        page.mouse.click(300, 300)  # focus the scene, not a text box
        page.keyboard.press("n")
        wait_for_text(page, "00001 (2/3)")
        page.keyboard.press("p")
        wait_for_text(page, "00000 (1/3)")
        app.state.hide_keypoint("00000", int(tab(app).view().observations.kp_ids[0]))
        page.keyboard.press("Control+z")
        wait_until(lambda: not app.state.edits.get("00000").get("keypoints"))
        assert not app.state.edits.get("00000").get("keypoints")
        page.close()
    finally:
        stop(app)


def test_a_page_from_another_origin_cannot_connect(data, browser):
    """A page served from another local port opens a websocket to the app: refused at the
    handshake, so it reads nothing and changes nothing."""
    import http.server
    import threading

    app = start(data)
    page_html = (f'<script>const ws = new WebSocket("ws://127.0.0.1:{app.policy.port}", ["viser-v1.1.1"]);'
                 'ws.onopen = () => document.title = "open"; ws.onmessage = () => document.title = "message";'
                 'ws.onerror = () => document.title = "refused";</script>').encode()

    class Page(http.server.BaseHTTPRequestHandler):
        def do_GET(self):
            self.send_response(200)
            self.send_header("Content-Type", "text/html")
            self.end_headers()
            self.wfile.write(page_html)

        def log_message(self, *args):
            pass

    other = http.server.HTTPServer(("127.0.0.1", 0), Page)
    threading.Thread(target=other.serve_forever, daemon=True).start()
    try:
        own = open_page(browser, app, "focal")  # the app's own page connects
        assert len(app.tabs()) == 1
        page = browser.new_page()
        page.goto(f"http://127.0.0.1:{other.server_address[1]}/")
        page.wait_for_function("document.title !== ''", timeout=20000)
        assert page.title() == "refused"
        time.sleep(1.0)
        assert len(app.tabs()) == 1  # no session was made for it
        page.close()
        own.close()
    finally:
        other.shutdown()
        stop(app)


def test_serve_starts_clean_with_a_client_while_the_detector_loads(tmp_path, browser):
    """`pnlviz serve` as a user starts it (the light default model detecting in the background),
    three times, with both cores busy: the page shows the frame calibrated from the detections,
    the server lives on, and its process never loads torch (importing torch in a thread beside
    scipy crashed it: issue #10)."""
    import subprocess
    import sys

    import cv2

    from pnlviz.synth import make_frame

    data = tmp_path / "set"
    data.mkdir()
    cv2.imwrite(str(data / "solo.jpg"), make_frame(2, 777, (960, 540))["image"])  # an image only: detect it
    burners = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(2)]
    try:
        for round_ in range(3):
            port = _free_port()
            proc = subprocess.Popen([sys.executable, "-m", "pnlviz.cli", "serve", "--data", str(data), "--port", str(port),
                                     "--edits", str(tmp_path / f"edits{round_}")],
                                    stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
            try:
                for line in proc.stdout:
                    if "open http" in line:
                        break
                page = browser.new_page()
                page.goto(f"http://127.0.0.1:{port}/")
                wait_for_text(page, "calibrated from: detections", timeout=120)
                wait_for_text(page, "detections ready for solo", timeout=30)
                page.close()
                assert proc.poll() is None
                maps = open(f"/proc/{proc.pid}/maps").read()
                assert "libtorch" not in maps
            finally:
                proc.terminate()
                out, err = proc.communicate(timeout=30)
            assert "Traceback" not in err and "Error" not in err, err
    finally:
        for b in burners:
            b.kill()


def _screen_point(client, box, world):
    """Where a world point shows on the canvas of ``client`` (viser cameras: OpenCV axes)."""
    import numpy as np
    from scipy.spatial.transform import Rotation

    w, x, y, z = client.camera.wxyz
    p = Rotation.from_quat([x, y, z, w]).as_matrix().T @ (np.asarray(world) - client.camera.position)
    f = box["height"] / 2 / np.tan(client.camera.fov / 2)
    return box["x"] + box["width"] / 2 + f * p[0] / p[2], box["y"] + box["height"] / 2 + f * p[1] / p[2]


def test_two_tabs_dragging_on_one_frame_keep_every_edit(data, browser):
    """Two tabs on the same frame drag handles in turns without waiting: each release
    recalibrates the frame and moves the other tab's handles in place (never re-creating one
    under the hand); every drag that grabbed a handle is on disk, and both tabs show them all."""
    import numpy as np

    from pnlviz.app.scene import HANDLE_SCALE
    from pnlviz.app.session import KeypointHandle

    app = start(data)
    try:
        tabs = []
        for _ in range(2):
            page = open_page(browser, app, "focal")
            wait_until(lambda: len(app.tabs()) == len(tabs) + 1)
            session = next(t for t in app.tabs() if all(t is not s for _, s in tabs))
            session.handles_mode.value = "keypoints"
            session.flush()
            page.get_by_role("button", name="camera view").click()
            tabs.append((page, session))
        time.sleep(3.0)
        stem = tabs[0][1].stem
        obs = tabs[0][1].view().observations
        dragged = [int(obs.kp_ids[i]) for i in np.argsort(obs.kp_xy[:, 0])[:6]]  # left: away from the panel
        for n, kid in enumerate(dragged):
            page, session = tabs[n % 2]
            box = page.locator("canvas").first.bounding_box()
            pos = np.asarray(session._handles[KeypointHandle(kid)].position, float)
            cam = session._handle_frame[KeypointHandle(kid)][1]
            x0, y0 = _screen_point(session.client, box, pos + 0.5 * HANDLE_SCALE * cam.R[0])
            page.mouse.move(x0, y0)
            page.mouse.down()
            page.mouse.move(x0 + 8, y0, steps=3)
            page.mouse.move(x0 + 15, y0, steps=3)
            page.mouse.up()
        grabbed = lambda: sum(s.grabs for _, s in tabs)  # noqa: E731
        wait_until(lambda: sum(s.releases for _, s in tabs) == grabbed() and
                   len(app.state.edits.get(stem).get("keypoints") or {}) >= grabbed(), timeout=20)
        saved = app.state.edits.get(stem).get("keypoints") or {}
        assert grabbed() >= 4 and sum(s.releases for _, s in tabs) == grabbed()
        assert len(saved) == grabbed() and set(saved) <= {str(k) for k in dragged}
        for page, session in tabs:  # both tabs show every edit
            view = session.view()
            for kid, xy in saved.items():
                i = list(view.observations.kp_ids).index(int(kid))
                np.testing.assert_allclose(view.observations.kp_xy[i], xy)
            page.close()
    finally:
        stop(app)
