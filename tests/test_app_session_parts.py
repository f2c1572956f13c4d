"""The parts of a tab, each on its own and without a browser: the queue (order, echoes of the
tab's own values, the action guard), the frame order (filters and sorts), the view control
(clamping, camera echoes, the bridge's messages), the edit trail (undo and redo across frames),
clip playback, the panel's texts and the typed modes."""

import asyncio
import contextlib
import json
import time
from types import SimpleNamespace

import numpy as np
import pytest

from helpers import copy_sample_set
from pnlviz.app import cards
from pnlviz.app.bridge import Gesture
from pnlviz.app.editing import Drag, EditTrail
from pnlviz.app.frameorder import FrameOrder, visible_order
from pnlviz.app.modes import DragMode, DragPhase, Filter, Mode, PointKind, Selection, Sort, labels
from pnlviz.app.overlay import Markers, Overlay
from pnlviz.app.host import TabHandle
from pnlviz.app.playback import ClipPlayer
from pnlviz.app.shots import ClipShots
from pnlviz.app.state import REVIEW_STATES, AppState, EditError
from pnlviz.app.tabqueue import ActionGuard, TabQueue
from pnlviz.app.view2d import MAX_ZOOM, MIN_ZOOM_OF_FIT, PLANE_Z, ImagePlane, View2D
from pnlviz.app.viewcontrol import ECHO_S, ViewControl


# ---------------------------------------------------------------------- the queue
def widget(value):
    """A stand-in for a viser widget handle: a value (viser's events carry the handle itself)."""
    return SimpleNamespace(value=value)


def test_the_queue_runs_actions_in_the_order_they_came_and_survives_an_error():
    said = []
    queue = TabQueue(lambda title, body, error=True: said.append((title, body)))
    seen = []
    for i in range(50):
        queue.enqueue(lambda i=i: seen.append(i) if i != 20 else 1 / 0)
    queue.flush()
    assert seen == [i for i in range(50) if i != 20]
    assert said == [("internal error", "ZeroDivisionError: division by zero")]
    queue.close(wait=True)
    queue.enqueue(lambda: seen.append("late"))  # a closed tab takes nothing more
    assert seen[-1] == 49


def test_the_queue_drops_the_echoes_of_its_own_values_and_keeps_the_users():
    queue = TabQueue(lambda *a, **k: None)
    slider = widget(0)
    got = []
    callback = queue.ordered(lambda event: got.append(event.target.value))

    def event(client):
        return SimpleNamespace(target=slider, client=client)

    queue.set_value(slider, 5)  # set from here: viser calls back later, with no client
    queue.set_value(slider, 5)  # unchanged: viser sends nothing, nothing to drop
    assert slider.value == 5
    asyncio.run(callback(event(None)))  # the echo of the set
    asyncio.run(callback(event(SimpleNamespace(client_id=1))))  # the user moves it
    asyncio.run(callback(event(None)))  # a set from Python that was not this tab's
    queue.flush()
    assert got == [5, 5]
    queue.close()


def test_the_guard_shows_refusals_and_failed_saves_and_redraws_once():
    said, redraws = [], []
    drawn = [0]
    guard = ActionGuard(lambda title, body, error=True: said.append(title), lambda: redraws.append(1),
                        lambda: drawn[0])

    def refused():
        raise EditError("no such keypoint")

    def disk_full():
        raise OSError(28, "No space left on device")

    def redraws_itself():
        drawn[0] += 1
        return "done"

    assert guard(refused) is None and said == ["not applied"] and len(redraws) == 1
    assert guard(disk_full) is None and said[-1] == "not saved" and guard.save_error == "No space left on device"
    assert len(redraws) == 2
    assert guard(redraws_itself) == "done" and guard.save_error is None
    assert len(redraws) == 3  # the save error shown has to be cleared: drawn again
    assert guard(redraws_itself) == "done" and len(redraws) == 3  # it drew itself: not twice


# ---------------------------------------------------------------------- frame order
def fake_view(ok=True, residuals=(), jac5=None):
    """A frame's summary as triage keeps it."""
    from pnlviz.app.triage import FrameSummary

    return FrameSummary("x", ok, None if ok else "failed", max(residuals, default=0.0),
                        float(np.median(residuals)) if residuals else 0.0, jac5 if ok else None, "")


STEMS = ["a", "b", "c", "d", "e"]
VIEWS = {"a": fake_view(residuals=(1.0, 2.0), jac5=0.9), "b": fake_view(ok=False),
         "c": fake_view(residuals=(7.0,), jac5=0.4), "e": fake_view(residuals=(), jac5=0.6)}  # d: not calibrated yet
REVIEWS = {"a": "accepted", "c": "rejected"}


def order(flt, sort):
    return [STEMS[i] for i in visible_order(STEMS, VIEWS, REVIEWS.get, flt, sort)]


def test_filters_pick_frames_by_calibration_and_review():
    assert order(Filter.ALL, Sort.INDEX) == STEMS
    assert order(Filter.FAILED, Sort.INDEX) == ["b"]  # not calibrated yet is not failed
    assert order(Filter.UNREVIEWED, Sort.INDEX) == ["b", "d", "e"]
    assert order(Filter.ACCEPTED, Sort.INDEX) == ["a"] and order(Filter.CORRECTED, Sort.INDEX) == []
    assert order(Filter.REJECTED, Sort.INDEX) == ["c"]


def test_sorts_put_the_worst_frames_first():
    # JaC@5 ascending; no JaC (no camera) counts as -1; not calibrated yet last
    assert order(Filter.ALL, Sort.JAC5) == ["b", "c", "e", "a", "d"]
    # largest residual first; no camera before all; not calibrated yet last; no residual as 0
    assert order(Filter.ALL, Sort.RESIDUAL) == ["b", "c", "a", "e", "d"]
    assert order(Filter.UNREVIEWED, Sort.RESIDUAL) == ["b", "e", "d"]


def test_the_frame_order_steps_clamps_and_goes_on_after_a_frame():
    frames = FrameOrder(5, 2)
    assert frames.position() == 2 and frames.stepped(1) == 3 and frames.stepped(-9) == 0 and frames.stepped(9) == 4
    assert frames.at("3") == 3 and frames.at("x") == 0 and frames.at(10 ** 9) == 4 and frames.clamp(-4) == 0
    assert frames.refreshed([0, 4]) == 0 and not frames.outside_filter  # the frame left the filter: its first
    assert frames.refreshed([]) == 2 and frames.outside_filter and frames.order == [2]  # nothing matches: stay
    frames.order = [0, 1, 3, 4]
    assert frames.after(1, [0, 3, 4]) == (3, False)  # frame 1 left the filter: the next one still in it
    assert frames.order == [0, 3, 4]
    assert frames.after(4, [0, 3, 4]) == (4, True)  # the last one: stays, and says so
    assert frames.after(4, [0, 3]) == (0, True)  # the last one, and out of the filter: its first
    assert frames.after(3, []) == (3, True) and frames.outside_filter


# ---------------------------------------------------------------------- view control
class FakeClient:
    """A client whose camera only remembers what was set on it."""

    def __init__(self):
        self.camera = SimpleNamespace()

    def atomic(self):
        return contextlib.nullcontext()


def view_control(client=None, clock=None):
    zooms, nudges = [], []
    workspace = SimpleNamespace(plane=ImagePlane(960, 540), zoom=None)
    workspace.set_zoom = lambda world_per_px: setattr(workspace, "zoom", world_per_px)
    control = ViewControl(workspace, client, zooms.append, lambda dx, dy: nudges.append((dx, dy)),
                          lambda action: action(), clock=clock or time.monotonic)
    control.frame_placed(None)
    return control, zooms, nudges


def test_the_view_is_clamped_to_the_zoom_limits_and_the_frame():
    control, zooms, _ = view_control()
    fit = View2D.fit(control.workspace.plane, control.canvas)
    assert control.view2d == fit and zooms[-1] == fit  # the first frame: all of it
    control.zoom_by(1e6)
    assert control.view2d.zoom == MAX_ZOOM
    control.zoom_by(1e-9)
    assert np.isclose(control.view2d.zoom, MIN_ZOOM_OF_FIT * fit.zoom)
    control.fit()
    # a drag of the image viser reports (the page pans by itself): the view moves once, on release
    control.pan(DragPhase.START, (0.5, 0.5), (0.5, 0.5))
    control.pan(DragPhase.UPDATE, (0.5, 0.5), (0.6, 0.5))
    assert control.view2d == fit  # nothing while the hand moves
    control.pan(DragPhase.END, (0.5, 0.5), (0.6, 0.5))  # a tenth of the canvas to the right
    np.testing.assert_allclose(control.view2d.cu, fit.cu - 0.1 * control.canvas[0] / fit.zoom)
    control.pan(DragPhase.START, (0.5, 0.5), (0.5, 0.5))
    control.pan(DragPhase.END, (0.5, 0.5), (50.0, -50.0))  # far off: the frame's centre stays on screen
    assert (control.view2d.cu, control.view2d.cv) == (-0.5, 539.5)
    control.native()
    assert control.view2d.zoom == 1.0
    control.mode = Mode.THREE_D
    control.zoom_by(2.0)  # the 3D view has its own camera
    assert control.view2d.zoom == 1.0


def test_camera_echoes_are_ignored_and_an_orbit_is_put_back():
    now = [100.0]
    client = FakeClient()
    control, _, _ = view_control(client, clock=lambda: now[0])
    shown = control.view2d
    position, look_at = np.array(client.camera.position), np.array(client.camera.look_at)
    straight = np.array([1.0, 0.0, 0.0, 0.0])
    moved, at = View2D(200.0, 100.0, 2.0).camera(control.workspace.plane, control.canvas[1])
    control.camera_moved(moved, straight, at, control.canvas)
    assert control.view2d == shown  # within ECHO_S of our own move: an echo, ours is newer
    now[0] += 2 * ECHO_S
    control.camera_moved(moved, straight, at, control.canvas)  # viser's own pan and zoom: kept
    np.testing.assert_allclose([control.view2d.cu, control.view2d.cv, control.view2d.zoom], [200.0, 100.0, 2.0])
    now[0] += 2 * ECHO_S
    tilted = np.array([0.9, 0.3, 0.3, 0.0]) / np.linalg.norm([0.9, 0.3, 0.3])
    control.camera_moved(position, tilted, look_at, control.canvas)  # an orbit: back to the image view
    np.testing.assert_allclose([control.view2d.cu, control.view2d.cv, control.view2d.zoom], [200.0, 100.0, 2.0])
    np.testing.assert_allclose(client.camera.position, moved)
    assert client.camera.position[2] < PLANE_Z and tuple(client.camera.up_direction) == (0.0, -1.0, 0.0)


def test_a_page_gesture_moves_the_camera_once_to_where_the_page_showed():
    """The page zoomed by 2 around canvas point (300, 200) and panned by (40, -30) CSS px: one
    camera push lands on the view the page showed (the pixel under the pointer stays under it),
    announced with its answer; a gesture made on an older view, or sent again, moves nothing."""
    client = FakeClient()
    control, _, _ = view_control(client)
    told = []
    control.on_push = lambda answer, applied: told.append((answer, applied, control.version))
    before, pushes = control.view2d, control.pushes
    p = np.array([300.0, 200.0])
    under = before.to_pixel(p, control.canvas)  # the image pixel at the pointer
    s, t = 2.0, (1 - 2.0) * p + [40.0, -30.0]  # zoom around p, then the pan
    control.gesture(Gesture(1, control.version, s, tuple(t)))
    assert control.pushes == pushes + 1 and told[-1] == (1, True, control.version)
    np.testing.assert_allclose(control.view2d.zoom, 2 * before.zoom)
    np.testing.assert_allclose(control.view2d.to_pixel(p + [40.0, -30.0], control.canvas), under, atol=1e-9)
    np.testing.assert_allclose(client.camera.position, control.view2d.camera(control.workspace.plane,
                                                                              control.canvas[1])[0])
    after = control.view2d
    control.gesture(Gesture(1, control.version, 3.0, (0.0, 0.0)))  # the same gesture again: ignored
    control.gesture(Gesture(2, control.version - 1, 3.0, (0.0, 0.0)))  # made on an older view: refused
    assert control.view2d == after and control.pushes == pushes + 1 and told[-1][:2] == (2, False)
    control.gesture(Gesture(3, control.version, 1e4, (0.0, 0.0)))  # beyond the zoom limit: clamped
    assert control.view2d.zoom == MAX_ZOOM and told[-1][:2] == (3, True)



def test_a_view_key_sent_as_a_gesture_is_done_on_whatever_view_the_page_was_on():
    """Fit and native resolution come from the page as gestures with their key: done even when
    the page's view is older than the server's (a frame of another size came first), answered
    with the gesture's number; native resolution centred on what the page showed."""
    from pnlviz.app.bridge import FIT, NATIVE
    from pnlviz.app.view2d import View2D

    client = FakeClient()
    control, _, _ = view_control(client)
    told = []
    control.on_push = lambda answer, applied: told.append((answer, applied))
    plane, canvas = control.workspace.plane, control.canvas
    control.push(View2D(100.0, 80.0, 3.0))  # the server moved the view: the page's base is older
    control.gesture(Gesture(1, control.version - 1, 2.0, (5.0, 5.0), FIT))
    assert told[-1] == (1, True) and control.view2d == View2D.fit(plane, canvas).clamped(plane, canvas)
    # native resolution around the centre of what the page showed (zoomed 2x about the canvas centre
    # and panned by 40 CSS px to the right: the centre shows 20 screen px / zoom to the left)
    v = control.view2d
    centre = np.asarray(canvas, float) / 2
    s, t = 2.0, (1 - 2.0) * centre + [40.0, 0.0]
    shown = v.to_pixel(centre, canvas)  # what the canvas centre showed before the page's transform
    control.gesture(Gesture(2, control.version, s, tuple(t), NATIVE))
    assert told[-1] == (2, True) and control.view2d.zoom == 1.0
    np.testing.assert_allclose([control.view2d.cu, control.view2d.cv], shown - [20.0 / v.zoom, 0.0], atol=1e-9)


def test_bridge_messages_carry_the_page_gesture():
    control, _, _ = view_control(FakeClient())
    zoom = control.view2d.zoom
    d = {"kind": "pointer", "n": 1, "log_zoom": 0.0, "x": 0.5, "y": 0.5, "nudge": [0, 0],
         "view": [1, control.version, 1.5, 0.0, 0.0]}
    control.bridge_message(json.dumps(d))
    control.bridge_message(json.dumps(d | {"n": 2}))  # a later message still carrying it: once
    np.testing.assert_allclose(control.view2d.zoom, 1.5 * zoom)
    assert control.gesture_seen == 1


def test_bridge_messages_zoom_nudge_and_resize_once_each():
    control, _, nudges = view_control()
    fit = control.view2d.zoom

    def msg(n, log_zoom=0.0, nudge=(0, 0), canvas=None):
        d = {"kind": "pointer", "n": n, "log_zoom": float(log_zoom), "x": 0.5, "y": 0.5, "nudge": list(nudge)}
        control.bridge_message(json.dumps(d | ({"canvas": list(canvas)} if canvas else {})))

    msg(1, log_zoom=np.log(2.0))
    assert np.isclose(control.view2d.zoom, 2 * fit)
    msg(1, log_zoom=np.log(8.0))  # a repeated sequence number: ignored
    msg(2, log_zoom=np.log(2.0), nudge=(3, -1))  # the same total zoom, a nudge
    assert np.isclose(control.view2d.zoom, 2 * fit) and nudges == [(3, -1)]
    msg(3, log_zoom=np.log(2.0), nudge=(4, -1))
    assert nudges == [(3, -1), (1, 0)]
    relative = control.relative
    msg(4, log_zoom=np.log(2.0), nudge=(4, -1), canvas=(640, 430))  # the canvas halved: the same part in view
    assert control.canvas == (640, 430) and control.css_canvas == (640, 430)
    np.testing.assert_allclose(control.relative, relative)
    control.bridge_message("not a message")
    assert control.bridge_seen[0] == 4


# ---------------------------------------------------------------------- edits
@pytest.fixture()
def data(tmp_path):
    return copy_sample_set(tmp_path / "set", ("00000", "00001"))


def test_the_edit_trail_undoes_and_redoes_across_frames(data):
    with AppState(data) as st:
        def guard(action):
            try:
                return action()
            except EditError:
                return None

        trail, went = EditTrail(st, guard), []
        kid = int(st.view("00000").observations.kp_ids[0])
        trail.act("00000", lambda: st.move_keypoint("00000", kid, 100.0, 120.0))
        trail.act("00001", lambda: st.set_review("00001", "accepted"))
        trail.act("00001", lambda: st.set_review("00001", "maybe"))  # refused: not a step
        assert trail.done == ["00000", "00001"]
        trail.undo("00001", went.append)  # on 00001: its review goes
        assert st.edits.review("00001") is None and went == []
        trail.undo("00001", went.append)  # then back to 00000, where the move goes
        assert went == ["00000"] and not st.edits.get("00000").get("keypoints")
        trail.redo("00000", went.append)
        assert st.edits.get("00000")["keypoints"][str(kid)] == [100.0, 120.0]
        trail.redo("00000", went.append)
        assert went == ["00000", "00001"] and st.edits.review("00001") == "accepted"
        assert trail.done == ["00000", "00001"] and trail.undone == []
        trail.undo("00001", went.append)
        trail.act("00000", lambda: st.set_review("00000", "rejected"))  # a new edit: nothing to redo
        assert trail.undone == []
        trail.undo("00001", went.append)  # the tab's last change was on 00000: back there
        assert went[-1] == "00000" and st.edits.review("00000") == "corrected"  # as the move had left it


def test_a_drag_counts_as_a_move_only_past_a_twentieth_of_a_pixel():
    point = Selection(PointKind.KEYPOINTS, 5)
    assert not Drag("x", point, np.array([10.0, 10.0]), np.array([10.03, 10.0])).moved
    assert Drag("x", point, np.array([10.0, 10.0]), np.array([10.0, 10.1])).moved


# ---------------------------------------------------------------------- clip playback
def clip_tab(errors):
    """A tab on a clip of frames 2..6 of a dataset (frame 7 beside it), with these errors."""
    stems = [f"f{i}" for i in range(8)]
    views = {f"f{i}": fake_view(residuals=(e,)) for i, e in zip(range(2, 7), errors) if e is not None}
    tab = SimpleNamespace(index=2, notes=[])
    handle = TabHandle(index=lambda: tab.index, settings=lambda: None, goto=lambda i: setattr(tab, "index", i),
                       show=lambda: None, notify=lambda title, body, error=True: tab.notes.append(title))
    queue = SimpleNamespace(closed=False, enqueue=lambda action: action())
    return tab, ClipPlayer(handle, {"clip": [2, 3, 4, 5, 6]}, stems=stems, shots=ClipShots(SimpleNamespace(stems=stems)),
                           summaries=lambda stem, settings: views.get(stem), queue=queue)


def test_the_clip_steps_to_its_end_and_stops():
    tab, clip = clip_tab([1.0, 2.0, 3.0, 4.0, 5.0])
    clip.playing = True
    for _ in range(10):
        clip.advance()
    assert tab.index == 6 and not clip.playing
    tab.index = 7
    assert clip.members() == [] and clip.errors() == []
    clip.play()
    assert not clip.playing  # nothing to play outside a clip
    tab.index = 4
    clip.play()
    deadline = time.monotonic() + 30
    while clip.playing and time.monotonic() < deadline:
        time.sleep(0.05)
    assert tab.index == 6 and not clip.playing


def test_the_clip_slider_and_the_worst_frames():
    tab, clip = clip_tab([1.0, 9.0, None, 4.0, 0.5])  # frame 4 not calibrated yet
    assert np.isnan(clip.errors()[2])
    clip.slider_moved("4")
    assert tab.index == 5
    clip.slider_moved(99)
    assert tab.index == 6
    clip.jump_worst(restart=True)
    assert tab.index == 3
    clip.jump_worst()
    assert tab.index == 5
    clip.jump_worst()
    clip.jump_worst()
    assert tab.index == 6
    clip.jump_worst()  # round again, the frame not calibrated yet left out
    assert tab.index == 3 and tab.notes == []
    empty_tab, empty = clip_tab([None] * 5)
    empty.jump_worst(restart=True)
    assert empty_tab.index == 2 and empty_tab.notes == ["nothing yet"]


# ---------------------------------------------------------------------- the panel's texts
def test_the_panel_texts():
    view = SimpleNamespace(stem="00042", size=(960, 540))
    assert cards.title_text(view, 3, 7, False, "all") == "### 00042\n3/7 · 960x540"
    assert cards.title_text(view, 1, 2, False, "failed") == "### 00042\n1/2 of 'failed' · 960x540"
    assert cards.title_text(view, 1, 2, False, "all", "worst residual 14,479.0 px").endswith(
        "960x540  \nsorted by **worst residual 14,479.0 px**")
    assert "not in the filter 'rejected'" in cards.title_text(view, 0, 1, True, "rejected")
    assert cards.filter_text("00042", 1, False, "all") == "1 frame"
    assert cards.filter_text("00042", 2, False, "all") == "2 frames"
    assert cards.filter_text("00042", 1, True, "rejected") == "**no frame matches 'rejected'**: showing 00042"
    assert cards.progress_text(2, 5, {"accepted": 1, "rejected": 1}) == "2 of 5 reviewed: accepted 1, rejected 1"
    assert cards.clip_text("c", 1, [1.0, float("inf"), float("nan")], True) == \
        "**c**: frame 2 of 3 · no camera · 2 calibrated · playing"
    observed, ghosts = Markers([12, 3], np.array([[10.0, 20.0], [30.0, 40.0]])), Markers([40], np.array([[5.0, 6.0]]))
    overlay = Overlay({}, observed, ghosts, Markers([("Side line top", 0)], np.array([[1.0, 2.0]])), {12: 0.84})
    rows = cards.point_rows(overlay, {7})
    assert rows == ["-", "3 · visible", "12 · visible · 0.8 px", "7 · hidden", "40 · ghost"]
    assert [cards.listed_id(r) for r in rows] == [None, 3, 12, 7, 40]
    model = SimpleNamespace(keypoints={})
    from pnlviz.field.model import load_field_model

    assert cards.selected_text(None, overlay, load_field_model(), 45) == \
        "nothing selected · shift+click places **45** penalty mark left (Kp3)"
    assert cards.selected_text(None, overlay, load_field_model(), 36) == \
        "nothing selected · shift+click places **36** Big rect. right main x Circle right (bottom) (Kp1)"
    assert cards.selected_text(Selection(PointKind.KEYPOINTS, 12), overlay, model, 9) == \
        "**12** ? · residual 0.84 px · at (10.0, 20.0)"
    assert "not observed" in cards.selected_text(Selection(PointKind.GHOSTS, 40), overlay, model, 9)
    assert cards.selected_text(Selection(PointKind.LINE_POINTS, ("Side line top", 0)), overlay, model, 9) == \
        "**Side line top**, point 0 · at (1.0, 2.0)"


def test_the_modes_keep_the_texts_the_user_sees():
    assert labels(Filter) == ("all", "failed", "unreviewed", "accepted", "corrected", "rejected", "suspects")
    assert labels(Sort) == ("index", "JaC@5 (worst first)", "residual (worst first)", "suspect score (worst first)")
    assert labels(DragMode) == ("keypoints", "line points")
    assert {f.review for f in Filter} - {None} == set(REVIEW_STATES)
    assert Mode.IMAGE.other is Mode.THREE_D and Mode.THREE_D.other is Mode.IMAGE and Mode("3d") is Mode.THREE_D
    assert {"keypoints": 1}[PointKind.KEYPOINTS] == 1  # the point kinds name the nodes and layers
    assert Selection(PointKind.GHOSTS, 4).is_keypoint and not Selection(PointKind.LINE_POINTS, ("a", 0)).is_keypoint


def test_the_keypoint_map_shows_the_chosen_id_large_enough_to_read():
    """The picker's map is the part of the pitch around the chosen keypoint (60% of the pitch's
    length: ids about 8 px tall in the 320 px panel of a 1600x900 screen, not 5): for every id its
    guides (the yellow cross through it) are in the picture."""
    from pnlviz.app.panels import MAP_PX_PER_M, picker_map
    from pnlviz.field import load_field_model
    from pnlviz.viz import keypoint_map

    model = load_field_model()
    whole = picker_map(model, None).shape
    assert whole[1] <= 0.65 * keypoint_map(model, px_per_m=MAP_PX_PER_M, legend=False).shape[1]  # shown larger
    for kid in (int(k) for k in model.keypoint_ids):
        image = picker_map(model, kid).astype(int)
        assert image.shape == whole
        guide = (np.abs(image - (255, 215, 0)).sum(axis=2) < 90)
        assert guide.sum(axis=0).max() > 0.5 * image.shape[0], kid  # the vertical guide through the id


def test_the_queue_says_busy_only_for_an_action_slower_than_150_ms():
    import time

    calls = []
    queue = TabQueue(lambda *a, **k: None)
    queue.busy = calls.append
    queue.enqueue(lambda: time.sleep(0.02))
    queue.flush()
    assert calls == []
    queue.enqueue(lambda: time.sleep(0.5))
    queue.flush()
    assert calls == [True, False]
    queue.close()
