"""The frame's pixels drawn by the page behind the WebGL canvas (pnlviz/app/pageframes.js), in real
headless Chromium: the image is where the camera puts the overlays, pixel for pixel; the next
frame, sent ahead, is shown with no pixels sent; viser's own camera moves (right drag, W A S D Q
E) are the page's pans and zooms, so the image moves with the overlays. The keypoints' ids, also
the page's, are by their points, the crowded ones hidden by the workspace's rule at every zoom."""


import cv2
import numpy as np

from pnlviz.app.modes import Mode
from pnlviz.app.workspace import LABEL_MIN_GAP_PX
import test_app_browser as base
from test_app_browser import open_page, tab, wait_until
from test_app_browser_rate import canvas_box, empty_spot, press_and_move, quiet

chromium, browser, data = base.chromium, base.browser, base.data  # the fixtures of the browser tests
pytestmark = base.pytestmark

#: the frame layer's state in the page: the slot shown ("slot,version") and the slots decoded
FRAMES = "() => { const f = window.__pnlvizFrames; return {shown: f.shown, swaps: f.swaps, " \
         "slots: [...f.slots.entries()].map(([s, e]) => `${s},${e.n}`)}; }"


def shown_image_rect(page) -> dict:
    return page.evaluate("() => { const i = [...document.querySelectorAll('#pnlviz-frames img')]"
                         ".find((i) => i.style.display === 'block'); const r = i.getBoundingClientRect();"
                         " return {x: r.x, y: r.y, width: r.width, height: r.height}; }")


def expected_rect(session, box) -> np.ndarray:
    """Where the server's camera puts the frame on the page: x, y, width, height (CSS px)."""
    plane = session.workspace.plane
    control = session.view_control
    corners = control.view2d.to_screen(np.array([[-0.5, -0.5], [plane.W - 0.5, plane.H - 0.5]]), control.canvas)
    return np.array([box["x"] + corners[0, 0], box["y"] + corners[0, 1], *(corners[1] - corners[0])])


def best_shift(page, session, rect) -> tuple[tuple[int, int], float]:
    """The whole-pixel shift (within 3) at which a screenshot of the frame's area best matches the
    frame's own pixels resampled to where ``rect`` (x, y, width, height: CSS px) puts them, and the
    median difference there (the overlays cover a small part)."""
    x0, y0 = int(np.floor(rect[0])), int(np.floor(rect[1]))
    w, h = int(rect[2]), int(rect[3])
    shot = cv2.imdecode(np.frombuffer(page.screenshot(clip={"x": x0, "y": y0, "width": w, "height": h}), np.uint8),
                        cv2.IMREAD_GRAYSCALE).astype(float)
    frame = cv2.cvtColor(session.app.state.image(session.stem), cv2.COLOR_BGR2GRAY).astype(np.float32)
    z = rect[2] / frame.shape[1]  # screen pixels per image pixel
    if z < 1:
        frame = cv2.GaussianBlur(frame, (0, 0), 0.5 / z)
    # screenshot pixel (j, i) has its centre at page (x0 + j + 0.5, y0 + i + 0.5): frame pixel
    # u = (x - rect.x) / z - 0.5 (integer coordinates are pixel centres)
    M = np.array([[1 / z, 0, (x0 + 0.5 - rect[0]) / z - 0.5], [0, 1 / z, (y0 + 0.5 - rect[1]) / z - 0.5]])
    expected = cv2.warpAffine(frame, M, (w, h), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP).astype(float)
    m = 3
    scores = {(dx, dy): float(np.median(np.abs(np.roll(shot, (dy, dx), (0, 1)) - expected)[m:-m, m:-m]))
              for dx in range(-m, m + 1) for dy in range(-m, m + 1)}
    best = min(scores, key=scores.get)
    return best, scores[best]


def to_3d_and_back(page, session, layer_display: str) -> None:
    """The tab to the 3D view, where the page's layer (``layer_display``: a script giving its
    CSS display) is hidden, and back to the image view, where it shows again; settled."""
    session.queue.enqueue(lambda: session.set_mode(Mode.THREE_D))
    wait_until(lambda: page.evaluate(layer_display) == "none")
    session.queue.enqueue(lambda: session.set_mode(Mode.IMAGE))
    wait_until(lambda: page.evaluate(layer_display) == "block")
    quiet(page, session)


def opened(browser, serve, data, viewport: dict | None = None):
    """The app on ``data`` in a page (of ``viewport``, the browser tests' size by default), settled:
    (app, page, the tab's session, the canvas's box)."""
    app = serve(data)
    page = open_page(browser, app, "focal", viewport=viewport)
    session = tab(app)
    quiet(page, session)
    return app, page, session, canvas_box(page)


def test_the_page_draws_the_frame_where_the_camera_puts_it_and_next_sends_no_pixels(data, browser, serve):
    app, page, session, box = opened(browser, serve, data)
    wait_until(lambda: page.evaluate(FRAMES)["shown"] != "")
    rect = shown_image_rect(page)
    np.testing.assert_allclose([rect["x"], rect["y"], rect["width"], rect["height"]], expected_rect(session, box),
                               atol=0.6)
    shift, diff = best_shift(page, session, expected_rect(session, box))
    assert shift == (0, 0) and diff < 12, (shift, diff)  # the frame's pixels, where its overlays are

    # the next frame was sent ahead: showing it sends no pixels, the page swaps in what it decoded
    nxt = app.state.stems[session.index + 1]
    wait_until(lambda: session.workspace.holds(nxt) and len(page.evaluate(FRAMES)["slots"]) >= 2)
    before, sent = page.evaluate(FRAMES), session.workspace.frames.sent
    page.keyboard.press("n")
    wait_until(lambda: session.stem == nxt and page.evaluate(FRAMES)["shown"] != before["shown"])
    now = page.evaluate(FRAMES)
    assert now["shown"] in before["slots"] and now["swaps"] == before["swaps"] + 1
    assert session.workspace.frames.page_state() == now["shown"]
    quiet(page, session)
    assert session.workspace.frames.sent <= sent + 1  # at most the frame after it, sent ahead
    shift, diff = best_shift(page, session, expected_rect(session, box))
    assert shift == (0, 0) and diff < 12, (shift, diff)

    # the 3D view draws no frame behind its scene; back in the image view, the frame is there again
    shown = "() => [...document.querySelectorAll('#pnlviz-frames img')].filter((i) => i.style.display === 'block').length"
    session.queue.enqueue(lambda: session.set_mode(Mode.THREE_D))
    wait_until(lambda: page.evaluate(shown) == 0)
    session.queue.enqueue(lambda: session.set_mode(Mode.IMAGE))
    wait_until(lambda: page.evaluate(shown) == 1)
    quiet(page, session)
    shift, diff = best_shift(page, session, expected_rect(session, box))
    assert shift == (0, 0) and diff < 12, (shift, diff)


def test_a_right_drag_and_the_camera_keys_pan_and_zoom_the_frame_with_its_overlays(data, browser, serve):
    app, page, session, box = opened(browser, serve, data)
    control = session.view_control

    # a right drag away from the points: the page's pan, one camera push, the frame under the hand
    start = empty_spot(session, (200, 150))
    before, pushes = control.view2d, control.pushes
    grabbed = before.to_pixel(start, control.canvas)
    press_and_move(page, box, start, button="right")
    assert abs(page.evaluate("() => window.__pnlvizBridge.T.tx") - 40) < 1e-6  # moved in the page
    page.mouse.up(button="right")
    wait_until(lambda: control.pushes > pushes)
    quiet(page, session)
    assert control.pushes == pushes + 1 and control.view2d.zoom == before.zoom
    assert np.hypot(*(control.view2d.to_pixel(start + [40, 25], control.canvas) - grabbed)) < 1.0
    assert not app.state.edits.get(session.stem).get("keypoints")  # a pan moved no point
    rect = shown_image_rect(page)
    np.testing.assert_allclose([rect["x"], rect["y"], rect["width"], rect["height"]], expected_rect(session, box),
                               atol=0.6)

    # W zooms in around the canvas's centre, A pans the frame right: the page's gestures
    page.mouse.move(box["x"] + 5, box["y"] + 5)
    before, pushes = control.view2d, control.pushes
    centre = np.array(control.canvas) / 2
    under = before.to_pixel(centre, control.canvas)
    page.keyboard.press("w")
    wait_until(lambda: control.pushes > pushes)
    quiet(page, session)
    np.testing.assert_allclose(control.view2d.zoom / before.zoom, 2 ** 0.25, rtol=1e-6)
    assert np.hypot(*(control.view2d.to_pixel(centre, control.canvas) - under)) < 1.0
    before, pushes = control.view2d, control.pushes
    page.keyboard.press("a")
    wait_until(lambda: control.pushes > pushes)
    quiet(page, session)
    assert control.view2d.zoom == before.zoom
    np.testing.assert_allclose(control.view2d.to_pixel(centre + [40, 0], control.canvas),
                               before.to_pixel(centre, control.canvas), atol=0.5)
    rect = shown_image_rect(page)
    np.testing.assert_allclose([rect["x"], rect["y"], rect["width"], rect["height"]], expected_rect(session, box),
                               atol=0.6)
    shift, diff = best_shift(page, session, expected_rect(session, box))
    assert shift == (0, 0) and diff < 12, (shift, diff)


#: the ids the page shows: text, and the bottom-left corner of each (page CSS px)
IDS = ("() => [...document.querySelectorAll('#pnlviz-ids span')].filter((s) => s.style.display !== 'none')"
       ".map((s) => { const r = s.getBoundingClientRect(); return [s.textContent, r.left, r.bottom]; })")
IDS_LAYER = "() => { const l = document.getElementById('pnlviz-ids'); return l ? l.style.display : 'missing'; }"


def declutter(screen_xy, min_gap: float) -> np.ndarray:
    """The page's rule for crowded ids, written out: in the order given, an id is shown unless it is
    closer than ``min_gap`` to one shown before it. Bool mask."""
    keep, kept = [], []
    for p in np.asarray(screen_xy, float).reshape(-1, 2):
        keep.append(all(np.hypot(*(p - q)) >= min_gap for q in kept))
        if keep[-1]:
            kept.append(p)
    return np.array(keep, bool)


def expected_ids(session, box) -> tuple[list, int]:
    """The workspace's ids where the server's camera puts their points (the bottom-left corner 3 px
    right of and above the point), those too close to one before them left out (:func:`declutter`);
    and how many were left out."""
    control = session.view_control
    labels = session.workspace.id_labels
    xy = control.view2d.to_screen(np.array([[u, v] for _, u, v in labels]).reshape(-1, 2), control.canvas)
    keep = declutter(xy, LABEL_MIN_GAP_PX)
    shown = [(t, box["x"] + x + 3, box["y"] + y - 3) for (t, _, _), (x, y), k in zip(labels, xy, keep) if k]
    return shown, int(np.sum(~keep))


def assert_ids_match(page, session, box) -> int:
    """The page shows exactly the expected ids, each within a pixel of its place; how many it hides."""
    want, hidden = expected_ids(session, box)
    wait_until(lambda: [t for t, _, _ in page.evaluate(IDS)] == [t for t, _, _ in want])
    got = page.evaluate(IDS)
    np.testing.assert_allclose([g[1:] for g in got], [w[1:] for w in want], atol=1.0)
    return hidden


def test_the_page_writes_each_id_by_its_point_and_hides_crowded_ones_at_every_zoom(data, browser, serve):
    app, page, session, box = opened(browser, serve, data)
    control = session.view_control
    wait_until(lambda: len(session.workspace.id_labels) > 0)
    counts = {}
    for step, key in enumerate(["", "s", "s", "s", "w", "w", "w", "w", "w", "w", "n"]):
        if key:
            pushes, stem = control.pushes, session.stem
            page.mouse.move(box["x"] + 5, box["y"] + 5)
            page.keyboard.press(key)
            wait_until(lambda: control.pushes > pushes or session.stem != stem)
            quiet(page, session)
        hidden = assert_ids_match(page, session, box)
        counts[step] = (len(session.workspace.id_labels) - hidden, hidden)
    # zoomed out, crowded ids were hidden; zoomed in, they show again
    assert counts[3][1] > 0 and counts[9][0] > counts[3][0], counts
    # the ghosts' ids end in "?", the observed ones are the workspace's labels
    texts = [t for t, _, _ in session.workspace.id_labels]
    assert any(t.endswith("?") for t in texts) and any(t.isdigit() for t in texts)

    # the 3D view shows no ids; switched off, none; back on, the same again
    to_3d_and_back(page, session, IDS_LAYER)
    assert_ids_match(page, session, box)
    session.queue.enqueue(lambda: session.painter.set_layer("ids", False))
    wait_until(lambda: page.evaluate(IDS) == [])
    assert session.workspace.id_labels == []
    session.queue.enqueue(lambda: session.painter.set_layer("ids", True))
    wait_until(lambda: len(page.evaluate(IDS)) > 0)
    assert_ids_match(page, session, box)


def screen_rgb(page, box) -> np.ndarray:
    """A screenshot of the canvas's area, RGB (CSS px = screenshot px at this device pixel ratio)."""
    png = page.screenshot(clip={"x": box["x"], "y": box["y"], "width": box["width"], "height": box["height"]})
    return cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)[..., ::-1].astype(int)


def settled_rgb(page, box, timeout: float = 8.0) -> np.ndarray:
    """:func:`screen_rgb` once two shots 0.5 s apart agree (software WebGL compiles a shader the
    first time it is needed: the frame that uses it can come seconds later)."""
    import time

    shot, deadline = screen_rgb(page, box), time.time() + timeout
    while True:
        page.wait_for_timeout(500)
        again = screen_rgb(page, box)
        if np.abs(again - shot).max() <= 8 or time.time() > deadline:
            return again
        shot = again


def assert_marks_where_the_camera_puts_them(page, session, box) -> None:
    """Each keypoint's disc (those with no other point within 12 px, their centres on the canvas)
    is its colour at the point's screen pixel, and a stretch of the calibrated pitch's line is its
    amber there."""
    from pnlviz.app.overlay import REFINED_RGB

    control, ws = session.view_control, session.workspace
    shot = screen_rgb(page, box)
    nodes = ws.points["keypoints"]
    everything = np.concatenate([n.uv for n in ws.points.values() if n.keys])
    checked = 0
    for uv, rgb in zip(nodes.uv, nodes.shaded):
        x, y = control.view2d.to_screen(uv, control.canvas)
        near = np.sort(np.hypot(*(everything - uv).T))[1] * control.view2d.zoom  # screen px to the next point
        if near < 12 or not (5 <= x < shot.shape[1] - 5 and 5 <= y < shot.shape[0] - 5):
            continue
        checked += 1
        assert np.abs(shot[int(y), int(x)] - rgb).max() <= 24, (uv, shot[int(y), int(x)], rgb)
    assert checked >= 3
    seg = session.painter.overlay.segments["refined_pitch"]
    mids = control.view2d.to_screen(seg.points.mean(axis=1), control.canvas)
    lengths = np.hypot(*(seg.points[:, 1] - seg.points[:, 0]).T) * control.view2d.zoom
    clear = [(x, y) for (x, y), n in zip(mids, lengths) if n > 20 and 5 <= x < shot.shape[1] - 5
             and 5 <= y < shot.shape[0] - 5 and np.min(np.hypot(*(control.view2d.to_screen(everything, control.canvas)
                                                                   - [x, y]).T)) > 20]
    assert len(clear) >= 3
    amber = [np.abs(shot[int(round(y)) - 1:int(round(y)) + 2, int(round(x)) - 1:int(round(x)) + 2]
                    - REFINED_RGB).sum(axis=2).min() for x, y in clear]
    assert np.median(amber) <= 40, amber


def test_the_page_draws_the_overlays_and_points_where_the_camera_puts_them_at_every_zoom(data, browser, serve):
    """The overlays are the page's (pagedraw.py, pageframes.js): the points' discs in their colours
    and the calibrated pitch's lines are where the server's camera puts them, at fit and after a
    zoom; they are not drawn in the 3D view and come back after it."""
    app, page, session, box = opened(browser, serve, data)
    control = session.view_control
    wait_until(lambda: len(session.workspace.points["keypoints"].keys) > 0 and session.painter.overlay is not None)
    quiet(page, session)
    assert_marks_where_the_camera_puts_them(page, session, box)
    page.mouse.move(box["x"] + 5, box["y"] + 5)
    pushes, zoom = control.pushes, control.view2d.zoom
    page.keyboard.press("w")
    page.keyboard.press("w")
    wait_until(lambda: control.pushes > pushes)
    quiet(page, session)
    assert control.view2d.zoom > 1.15 * zoom
    assert_marks_where_the_camera_puts_them(page, session, box)
    to_3d_and_back(page, session, "() => document.getElementById('pnlviz-draw').style.display")
    assert_marks_where_the_camera_puts_them(page, session, box)


def test_the_pointer_over_the_image_lights_nothing_at_any_zoom(data, browser, serve):
    """viser outlines a hovered clickable mesh in yellow; the invisible surface over the frame and
    the points' grab meshes take clicks, so, zoomed in, a pointer resting on the image washed the
    whole view yellow and ringed the points. The page keeps the hover from the scene: the pixels
    under a resting pointer are those with the pointer off the canvas, at fit and zoomed in, on
    the image and on a point."""
    from pnlviz.app.view2d import View2D

    app, page, session, box = opened(browser, serve, data, {"width": 1600, "height": 900})  # the wash showed here
    control = session.view_control
    wait_until(lambda: len(session.workspace.points["keypoints"].keys) > 0)
    for zoom in (None, 4.0):
        if zoom is not None:
            uv = session.workspace.points["keypoints"].uv[0]
            pushes = control.pushes
            session.queue.enqueue(lambda: control.push(View2D(float(uv[0]), float(uv[1]), zoom)))
            wait_until(lambda: control.pushes > pushes)
        quiet(page, session)
        spot = empty_spot(session, (60, 60))
        point = control.view2d.to_screen(session.workspace.points["keypoints"].uv[0], control.canvas)
        page.mouse.move(box["x"] + box["width"] + 100, box["y"] + 5)  # over the panel
        away = settled_rgb(page, box)
        for where in (spot, point + [2.0, 1.0]):
            page.mouse.move(box["x"] + where[0], box["y"] + where[1], steps=4)
            over = settled_rgb(page, box)
            changed = np.abs(over - away).max(axis=2) > 40
            assert changed.mean() < 0.001, (zoom, where, changed.mean())
