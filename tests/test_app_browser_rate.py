"""Pan, zoom and drag-follow at display rate, in real headless Chromium with real mouse events:
the page moves the canvas itself and the server pushes the camera once per gesture, to the view
the page showed; a dragged point has a ring at the hand; the canvas is drawn at the page's device
pixel ratio."""

import time

import numpy as np

import test_app_browser as base
from test_app_browser import open_page, settle, tab, to_screen, wait_until

chromium, browser, data = base.chromium, base.browser, base.data  # the fixtures of the browser tests
pytestmark = base.pytestmark

#: the bridge's state in the page
BRIDGE = "() => { const b = window.__pnlvizBridge; return {T: b.T, sent: b.sent, gestures: b.gestures, k: b.k}; }"


def canvas_box(page) -> dict:
    """The WebGL canvas on the page (asked in the page: no locator timeout while a busy machine
    compiles its shaders)."""
    return page.evaluate("() => { const r = document.querySelector('canvas[data-engine]').getBoundingClientRect();"
                         " return {x: r.x, y: r.y, width: r.width, height: r.height}; }")


def quiet(page, session, seconds=2.0, timeout=90.0):
    """Wait until the page answers and the tab pushed no camera for ``seconds`` (a busy machine
    can take half a minute to draw the first frame; its camera reports come late)."""
    deadline = time.time() + timeout
    while time.time() < deadline:
        page.evaluate("() => 1")
        pushes = session.view_control.pushes
        settle(session, seconds)
        if session.view_control.pushes == pushes:
            return
    raise AssertionError("the camera kept moving")


def empty_spot(session, start, step=(40, 25)):
    """A canvas point (CSS px) with no grabbable point within 40 px, and room for a drag ``step``
    from it: a press there is a pan."""
    view, canvas = session.view_control.view2d, np.array(session.view_control.canvas)
    pts = np.concatenate([n.uv for n in session.workspace.points.values() if len(n.keys)] or [np.zeros((0, 2))])
    screen = view.to_screen(pts, tuple(canvas)) if len(pts) else np.zeros((0, 2))
    for y in range(int(start[1]), int(canvas[1]) - 60, 20):
        for x in range(int(start[0]), int(canvas[0]) - 60 - step[0], 20):
            if not len(screen) or np.min(np.hypot(*(screen - [x, y]).T)) > 40:
                return np.array([x, y], float)
    raise AssertionError("no empty spot on the canvas")


def press_and_move(page, box, start, button: str = "left") -> tuple[float, float]:
    """Press ``button`` at canvas point ``start`` and move the pointer by (40, 25) CSS px in ten
    steps, not released; where the press was on the page."""
    x, y = box["x"] + start[0], box["y"] + start[1]
    page.mouse.move(x, y)
    page.mouse.down(button=button)
    for k in range(1, 11):
        page.mouse.move(x + 4 * k, y + 2.5 * k)
        time.sleep(0.03)
    return x, y


def test_wheel_zoom_and_drag_pan_push_the_camera_once_per_gesture_to_where_the_page_showed(data, browser, serve):
    app = serve(data)
    page = open_page(browser, app, "focal")
    session = tab(app)
    control = session.view_control
    quiet(page, session)
    # the canvas at the page's device pixel ratio (1 here): never lowered on this slow machine
    size = page.evaluate("() => { const c = document.querySelector('canvas[data-engine]');"
                         " return [c.width, c.height, c.clientWidth, c.clientHeight]; }")
    assert size[:2] == size[2:]
    page.evaluate("() => { window.__pnlvizBridge.idleMs = 1500; }")  # every notch below in one gesture
    box = canvas_box(page)

    # six wheel notches around a pointer: the page zooms, the server hears of it once
    at = np.array([300.0, 420.0])
    before, pushes = control.view2d, control.pushes
    under = before.to_pixel(at, control.canvas)
    page.mouse.move(box["x"] + at[0], box["y"] + at[1])
    for _ in range(6):
        page.mouse.wheel(0, -100)
        time.sleep(0.03)
    assert control.pushes == pushes  # nothing sent while the wheel turns
    transform = page.evaluate(BRIDGE)["T"]
    assert abs(transform["s"] - np.exp(0.0015 * 600)) < 1e-9  # the page shows it at once
    wait_until(lambda: control.pushes > pushes)
    settle(session, 1.0)
    assert control.pushes == pushes + 1 and page.evaluate(BRIDGE)["gestures"] == 1
    np.testing.assert_allclose(control.view2d.zoom / before.zoom, np.exp(0.0015 * 600), rtol=1e-9)
    assert np.hypot(*(control.view2d.to_pixel(at, control.canvas) - under)) < 1.0  # still under the pointer
    wait_until(lambda: page.evaluate(BRIDGE)["sent"] is None)  # answered: the transform is off

    # a left drag on the image, away from the points: a pan, one push at the release
    start = empty_spot(session, (200, 150))
    before, pushes = control.view2d, control.pushes
    grabbed = before.to_pixel(start, control.canvas)
    x, y = press_and_move(page, box, start)
    assert control.pushes == pushes  # the image followed the hand in the page only
    assert abs(page.evaluate(BRIDGE)["T"]["tx"] - 40) < 1e-6
    page.mouse.up()
    wait_until(lambda: control.pushes > pushes)
    settle(session, 1.0)
    assert control.pushes == pushes + 1 and control.view2d.zoom == before.zoom
    assert np.hypot(*(control.view2d.to_pixel(start + [40, 25], control.canvas) - grabbed)) < 1.0
    assert not app.state.edits.get(session.stem).get("keypoints")  # a pan moved no point
    # the camera controls are not left holding the button: moving the mouse changes nothing
    view = control.view2d
    for k in range(8):
        page.mouse.move(x + 30 * k, y + 10 * k)
        time.sleep(0.03)
    settle(session, 1.0)
    now = control.view2d
    np.testing.assert_allclose([now.cu, now.cv, now.zoom], [view.cu, view.cv, view.zoom], rtol=1e-9)
    assert control.pushes == pushes + 1

    # a point dragged: a ring follows the hand in the page; the edit lands as before
    obs = session.view().observations
    screen = np.array([to_screen(session, uv) for uv in obs.kp_xy])
    inside = np.flatnonzero(np.all((screen > 60) & (screen < np.array(control.canvas) - 60), axis=1))
    i = inside[0]
    kid, uv = int(obs.kp_ids[i]), obs.kp_xy[i]
    x, y = np.array([box["x"], box["y"]]) + to_screen(session, uv)
    page.mouse.move(x, y)
    page.mouse.down()
    for k in range(1, 9):
        page.mouse.move(x + 3 * k, y + 2 * k)
        time.sleep(0.03)
    ring = page.evaluate("() => { const r = document.getElementById('pnlviz-drag-ring');"
                         " return r ? [parseFloat(r.style.left), parseFloat(r.style.top)] : null; }")
    assert ring is not None and np.hypot(ring[0] - (x + 24), ring[1] - (y + 16)) < 1.0
    # the live preview has put the server's point under the ring: the ring goes with the release
    nodes = session.workspace.points["keypoints"]
    held = uv + np.array([24, 16]) / control.view2d.zoom
    wait_until(lambda: kid in nodes.keys and np.hypot(*(nodes.uv[nodes.keys.index(kid)] - held)) < 1.0)
    page_points = "() => (window.__pnlvizBridge.view || {points: []}).points"  # what the page was told
    wait_until(lambda: np.min(np.hypot(*(np.reshape(page.evaluate(page_points), (-1, 2)) - held).T), initial=9.0) < 1.0)
    page.mouse.up()
    assert page.evaluate("() => document.getElementById('pnlviz-drag-ring') === null")
    wait_until(lambda: str(kid) in (app.state.edits.get(session.stem).get("keypoints") or {}))
    np.testing.assert_allclose(np.array(app.state.edits.get(session.stem)["keypoints"][str(kid)]) - uv,
                               np.array([24, 16]) / control.view2d.zoom, atol=0.6)
    wait_until(lambda: page.evaluate("() => document.getElementById('pnlviz-drag-ring') === null"))
    page.close()


def test_the_canvas_is_drawn_at_the_device_pixel_ratio(data, browser, serve):
    """A page at device scale factor 2 opening the printed URL (fixedDpr=1) reloads once with its
    own ratio; its canvas then has two drawing-buffer pixels per CSS pixel each way."""
    app = serve(data)
    page = browser.new_page(viewport={"width": 1000, "height": 700}, device_scale_factor=2)
    page.goto(app.page_url)

    def drawn_at_2() -> bool:
        try:
            size = page.evaluate("() => { const c = document.querySelector('canvas[data-engine]');"
                                 " return c ? [c.width, c.height, c.clientWidth, c.clientHeight] : null; }")
        except Exception:  # noqa: BLE001 - the page is reloading
            return False
        return size is not None and size[2] > 0 and size[:2] == [2 * size[2], 2 * size[3]]

    wait_until(drawn_at_2, timeout=120)  # a busy machine takes its time to load a page twice
    assert "fixedDpr=2" in page.url
    assert page.evaluate("() => window.devicePixelRatio") == 2
    page.close()
