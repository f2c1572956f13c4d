"""The app under abuse: concurrent edits, edits made on one frame and released on another, a
second server on the same edits, damaged and hostile edit records, an unwritable edits folder,
values no honest browser sends, and requests from pages or hosts that are not the app's own."""

import json
import math
import shutil
import threading
import urllib.error
import urllib.request

import numpy as np
import pytest
import viser

from pnlviz import EXAMPLES_DIR
from pnlviz.app.modes import DragEvent, DragPhase, PointKind
from pnlviz.app.state import AppState, EditError
from pnlviz.data.edits import EditsFolderError, EditsStore
from helpers import free_port


@pytest.fixture()
def data(tmp_path):
    src = EXAMPLES_DIR / "sample"
    dst = tmp_path / "set"
    dst.mkdir()
    for stem in ("00000", "00001", "00002", "00003"):
        shutil.copy(src / f"{stem}.jpg", dst / f"{stem}.jpg")
        shutil.copy(src / f"{stem}.json", dst / f"{stem}.json")
    return dst


# ------------------------------------------------------------------------------ concurrent edits
def test_concurrent_edits_from_threads_all_land_on_their_frames(data):
    """24 drags of different keypoints on two frames, from 8 threads at once (viser runs
    callbacks in a thread pool): every one is on disk, on its own frame, with its undo step."""
    st = AppState(data)
    jobs = []
    for stem in ("00001", "00002"):
        ids = [int(k) for k in st.view(stem).observations.kp_ids[:12]]
        jobs += [(stem, kid, 100.0 + kid, 50.0 + 2 * kid) for kid in ids]
    barrier = threading.Barrier(8)

    def worker(chunk):
        barrier.wait()
        for stem, kid, x, y in chunk:
            st.move_keypoint(stem, kid, x, y)

    threads = [threading.Thread(target=worker, args=(jobs[i::8],)) for i in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for stem in ("00001", "00002"):
        on_disk = json.loads((st.edits.frames / f"{stem}.json").read_text())["keypoints"]
        want = {str(kid): [x, y] for s, kid, x, y in jobs if s == stem}
        assert on_disk == want
    assert st.edits.history("00001") == (12, 0) and st.edits.history("00002") == (12, 0)
    st.close()


def test_two_tabs_on_two_frames_never_touch_each_other(data, serve):
    app = serve(data)
    st = app.state
    a, b = app.session(), app.session()
    a.goto(st.find("00003"))
    b.goto(st.find("00001"))
    kid = int(a.view().observations.kp_ids[0])
    a.editor.drag(DragEvent(PointKind.KEYPOINTS, kid, DragPhase.START, a.view().observations.kp_xy[0]))
    b.goto(st.find("00002"))  # the other tab moves while the drag is in the air
    a.editor.drag(DragEvent(PointKind.KEYPOINTS, kid, DragPhase.END, np.array([321.0, 123.0])))
    a.flush()
    assert a.stem == "00003" and b.stem == "00002"
    np.testing.assert_allclose(st.edits.get("00003")["keypoints"][str(kid)], [321.0, 123.0], atol=1e-6)
    assert st.edits.get("00002") == {} and st.edits.get("00001") == {}
    st.set_review(b.stem, "rejected")  # a review from tab b: a's frame and progress follow
    assert st.edits.review("00003") == "corrected" and "rejected 1" in a.panels.progress_text.content


# ------------------------------------------------------------------------------ one server per folder
def test_a_second_server_on_the_same_edits_refuses(data, capsys):
    from pnlviz.cli import main

    first = AppState(data)
    first.edits.describe_holder("http://127.0.0.1:8080/")
    with pytest.raises(EditsFolderError, match="in use by another pnlviz process .*http://127.0.0.1:8080/"):
        AppState(data)
    assert main(["serve", "--data", str(data), "--no-detect", "--port", str(free_port())]) == 2
    err = capsys.readouterr().err
    assert "in use by another pnlviz process" in err and "--edits" in err
    first.close()
    AppState(data).close()  # released: the next one may take it


def test_an_unwritable_edits_folder_is_refused_at_start(data, tmp_path, capsys):
    from pnlviz.cli import main

    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    with pytest.raises(EditsFolderError, match="cannot be written"):
        AppState(data, edits=blocker / "edits")
    assert main(["serve", "--data", str(data), "--no-detect", "--edits", str(blocker / "edits")]) == 2
    assert "cannot be written" in capsys.readouterr().err


def test_a_failed_write_is_shown_and_changes_nothing(data, monkeypatch, serve):
    import pnlviz.data.edits as edits_module
    app = serve(data)
    st = app.state
    tab = app.session()
    said = []
    monkeypatch.setattr(tab, "notify", lambda title, body, error=True: said.append((title, body)))

    def full_disk(*a, **k):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(edits_module, "atomic_write_text", full_disk)
    tab.guard(lambda: st.set_review(tab.stem, "accepted"))
    assert said and said[-1][0] == "not saved" and "No space left" in said[-1][1]
    assert st.edits.review(tab.stem) is None and st.edits.history(tab.stem) == (0, 0)  # nothing half-done


# ------------------------------------------------------------------------------ damaged records
DAMAGED = {
    "a list": "[1, 2]",
    "an id that is not a keypoint": '{"keypoints": {"abc": [1, 2]}}',
    "id 999": '{"keypoints": {"999": [1, 2]}}',
    "NaN coordinates": '{"keypoints": {"5": [NaN, 2]}}',
    "infinite coordinates": '{"keypoints": {"5": [Infinity, 2]}}',
    "a bad review": '{"review": "approved"}',
    "a bad annotation": '{"annotation": {"Not a class": [{"x": 0.1, "y": 0.2}]}}',
    "broken JSON": '{"review": "acc',
    "not UTF-8": b'{"review": "\xff"}',
}


@pytest.mark.parametrize("what", sorted(DAMAGED))
def test_a_damaged_edit_record_is_moved_aside_and_the_frame_falls_back(data, tmp_path, what, capsys):
    from pnlviz.cli import main

    frames = tmp_path / "set.edits" / "frames"
    frames.mkdir(parents=True)
    content = DAMAGED[what]
    (frames / "00000.json").write_bytes(content if isinstance(content, bytes) else content.encode())
    (frames / "00001.json").write_text('{"review": "accepted"}')
    (frames / ".00001.json.x1y2.tmp").write_text("{half")  # an interrupted write
    source_obs = AppState(data, edits=tmp_path / "other").view("00000").observations
    # export (read-only) skips it and moves nothing
    out = tmp_path / "export"
    assert main(["export", "--data", str(data), "--out", str(out), "--all"]) == 0
    assert "damaged edit record ignored" in capsys.readouterr().err and (frames / "00000.json").exists()
    for p in out.rglob("*.json"):
        json.loads(p.read_text(), parse_constant=lambda c: pytest.fail(f"{p} holds {c}"))
    # the app moves it aside, once, and shows the source labels
    st = AppState(data)
    assert not (frames / "00000.json").exists()
    assert (frames / "00000.json.damaged").read_bytes() == (content if isinstance(content, bytes) else content.encode())
    assert len(st.edits.warnings) == 1 and "00000.json" in st.edits.warnings[0]
    assert not list(frames.glob(".*.tmp")) and st.edits.review("00001") == "accepted"
    view = st.view("00000")
    assert view.result.ok and np.array_equal(view.observations.kp_ids, source_obs.kp_ids)
    st.set_review("00000", "accepted")  # and the frame can be edited again
    st.close()
    st2 = AppState(data)
    assert st2.edits.review("00000") == "accepted" and st2.edits.warnings == []
    st2.close()


def test_records_are_validated_before_they_are_written(tmp_path):
    store = EditsStore(tmp_path / "e")
    for bad in ({"keypoints": {"999": [1.0, 2.0]}}, {"keypoints": {"3": [math.nan, 2.0]}}, {"review": "yes"}):
        with pytest.raises(ValueError):
            store.update("00001", **bad)
    assert store.get("00001") == {} and not (tmp_path / "e" / "frames" / "00001.json").exists()
    store.close()


# ------------------------------------------------------------------------------ client values
def test_values_no_honest_browser_sends_are_refused(data, serve):
    app = serve(data)
    st = app.state
    tab = app.session()
    said = []
    tab.notify = lambda title, body, error=True: said.append(body)
    stem = tab.stem
    tab.panels.kp_id.value = "999"  # a dropdown value outside its options
    tab.flush()
    assert "999" in said[-1] and tab.panels.kp_id.value.startswith("1 · ") and tab.editor.place_id == 1
    tab.guard(lambda: st.hide_keypoint(stem, 999))
    assert "999" in said[-1] and st.edits.get(stem) == {}
    for x, y in ((math.nan, 10.0), (math.inf, 10.0), (1e9, 10.0), (-2000.0, 10.0)):
        with pytest.raises(EditError):
            st.move_keypoint(stem, 5, x, y)
    with pytest.raises(EditError):
        st.set_review(stem, "approved")
    with pytest.raises(EditError):
        st.move_keypoint("no-such-frame", 5, 10.0, 10.0)
    with pytest.raises(EditError):
        st.move_line_point(stem, "Not a class", 0, 10.0, 10.0)
    assert st.edits.get(stem) == {}
    p = tab.panels
    p.filter.value = "everything"  # resets to a known filter, the panels keep working
    tab.flush()
    assert p.filter.value == "all" and len(tab.frames.order) == len(st.stems)
    p.source.value = "telepathy"
    tab.flush()
    assert tab.settings.source == "annotation" and p.source.value == "annotation"
    p.alpha.value = 7.0
    tab.flush()
    assert tab.settings.alpha == 0.6
    p.opacity.value = math.nan
    tab.flush()
    assert tab.painter.opacity == 1.0
    p.slider.value = 10 ** 6  # past the end: the last frame, no IndexError
    tab.flush()
    assert tab.stem == st.stems[-1]
    for junk in ("", "{", "[1, 2]", '{"kind": "pointer", "n": "x"}', '{"kind": "pointer", "n": 5, "log_zoom": 1e400, '
                 '"x": 0, "y": 0}', "a" * 10000):
        tab.view_control.bridge_message(junk)  # nothing the page's bridge would send: ignored
    assert tab.view_control.bridge_seen[0] == -1


def test_a_filter_with_one_match_and_the_slider_past_it(data, serve):
    """Was an IndexError in the server (the slider's max is 1 with one match) and an empty panel."""
    app = serve(data)
    st = app.state
    tab = app.session()
    st.set_review("00002", "accepted")
    tab.panels.filter.value = "accepted"
    tab.flush()
    assert tab.frames.order == [st.find("00002")] and tab.stem == "00002"
    assert tab.panels.slider.disabled and tab.panels.slider.value == 1  # counted from 1, as the title
    tab.panels.slider.value = 2
    tab.flush()
    assert tab.stem == "00002" and "1/1 of 'accepted'" in tab.panels.title.content


def test_an_empty_filter_says_so_instead_of_staying_silently(data, serve):
    app = serve(data)
    st = app.state
    tab = app.session()
    tab.goto(st.find("00001"))
    tab.panels.filter.value = "rejected"  # no frame is rejected
    tab.flush()
    assert tab.frames.outside_filter and tab.stem == "00001"
    assert "no frame matches 'rejected'" in tab.panels.filter_text.content
    assert "not in the filter" in tab.panels.title.content
    st.set_review("00003", "rejected")
    tab.panels.filter.value = "all"
    tab.flush()
    tab.panels.filter.value = "rejected"
    tab.flush()
    assert not tab.frames.outside_filter and tab.stem == "00003"


# ------------------------------------------------------------------------------ who may connect
def _http(url, headers=None):
    req = urllib.request.Request(url, headers=headers or {})
    try:
        with urllib.request.urlopen(req, timeout=10) as r:
            return r.status, r.headers, r.read()
    except urllib.error.HTTPError as e:
        return e.code, e.headers, e.read()


def _handshake(port, path="/", host="127.0.0.1", **headers):
    """The status of a websocket handshake with these headers (101: accepted)."""
    import websockets.sync.client

    try:
        with websockets.sync.client.connect(f"ws://{host}:{port}{path}", additional_headers=headers,
                                            subprotocols=[f"viser-v{viser.__version__}"], open_timeout=10, origin=None):
            return 101
    except websockets.exceptions.InvalidStatus as e:
        return e.response.status_code


def test_loopback_server_refuses_foreign_origins_and_hosts(data, serve):
    app = serve(data)
    port = app.policy.port
    assert app.url == f"http://127.0.0.1:{port}/"
    assert _http(app.url)[0] == 200
    assert _handshake(port, Origin=f"http://127.0.0.1:{port}") == 101
    assert _handshake(port, host="localhost", Origin=f"http://localhost:{port}") == 101
    assert _handshake(port, Origin="http://127.0.0.1:9999") == 403  # another local port
    assert _handshake(port, Origin="https://evil.example") == 403
    assert _handshake(port, Host=f"evil.example:{port}") == 403  # a second Host header
    assert _http(app.url, {"Host": f"evil.example:{port}"})[0] == 403  # DNS rebinding: the name is not ours


def test_a_viser_that_binds_its_server_another_way_is_refused_not_served_unguarded(monkeypatch):
    from pnlviz.app import guard

    stopped = []

    class OtherViser:  # binds its web server without the websockets function the guard wraps
        def __init__(self, **kw):
            pass

        def stop(self):
            stopped.append(True)

    monkeypatch.setattr(guard.viser, "ViserServer", OtherViser)
    port = free_port()
    with pytest.raises(guard.UnguardedServerError, match="viser>=1.1.1,<1.2"):
        guard.guarded_viser_server(guard.AccessPolicy("127.0.0.1", port=port), host="127.0.0.1", port=port)
    assert stopped == [True]


def test_a_non_loopback_server_needs_its_token(data, serve):
    app = serve(data, host="0.0.0.0")
    port, token = app.policy.port, app.policy.token
    assert token and len(token) >= 20
    assert app.url == f"http://127.0.0.1:{port}/?token={token}"  # one a browser can open, not 0.0.0.0
    assert _http(f"http://127.0.0.1:{port}/")[0] == 403
    assert _http(f"http://127.0.0.1:{port}/?token=wrong")[0] == 403
    status, headers, _ = _http(app.url)
    assert status == 200 and f"pnlviz_token={token}" in headers["Set-Cookie"] and "HttpOnly" in headers["Set-Cookie"]
    assert _handshake(port, Origin=f"http://127.0.0.1:{port}") == 403
    assert _handshake(port, Origin=f"http://127.0.0.1:{port}", Cookie=f"pnlviz_token={token}") == 101
    assert _handshake(port, Origin="http://evil.example", Cookie=f"pnlviz_token={token}") == 403


def test_serve_on_all_interfaces_warns_and_prints_an_openable_url(data, tmp_path):
    import subprocess
    import sys

    port = free_port()
    proc = subprocess.Popen([sys.executable, "-m", "pnlviz.cli", "serve", "--data", str(data), "--no-detect",
                             "--host", "0.0.0.0", "--port", str(port)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        lines = []
        for line in proc.stdout:
            lines.append(line)
            if "open http" in line:
                break
        url = lines[-1].split("open ", 1)[1].strip()
        assert url.startswith(f"http://127.0.0.1:{port}/?token=") and "0.0.0.0" not in "".join(lines)
        assert _http(url)[0] == 200
    finally:
        proc.terminate()
        _, err = proc.communicate(timeout=30)
    assert "warning: listening on 0.0.0.0" in err


def test_unused_files_and_unreadable_images_are_said_not_hidden(data, tmp_path, capsys):
    """A file name that is not UTF-8 and a truncated image: the app and export say so in one
    line each; the frame with the bad image is still calibrated from its annotation."""
    import os

    from pnlviz.cli import main

    with open(os.path.join(os.fsencode(data), b"\xff.json"), "wb") as f:
        f.write(b"{}")
    (data / "00001.jpg").write_bytes(b"")  # unreadable even for its size
    (data / "00002.jpg").write_bytes((EXAMPLES_DIR / "sample" / "00002.jpg").read_bytes()[:2000])  # truncated
    st = AppState(data)
    assert len(st.problems) == 1 and "UTF-8" in st.problems[0]
    view = st.view("00001")
    assert view.result.ok and "00001.jpg" in view.error and not view.has_image
    from pnlviz.app.cards import calibration_card

    assert st.image("00002") is None and "image not shown" in calibration_card(st.view("00002"), st)
    st.close()
    assert main(["export", "--data", str(data), "--out", str(tmp_path / "x"), "--all"]) == 0
    err = capsys.readouterr().err
    assert "UTF-8" in err and sum("00001.jpg" in line for line in err.splitlines()) == 1 and "Traceback" not in err
    assert (tmp_path / "x" / "keypoints" / "00001.json").is_file()
