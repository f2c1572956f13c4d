"""The app without a browser: state, autosaved review and edits, overlays, the server's panels."""

import json
import shutil
import socket

import numpy as np
import pytest

from pnlviz import EXAMPLES_DIR
from pnlviz.app.overlay import Layers, render
from pnlviz.app.state import AppState, default_edits_dir


@pytest.fixture()
def data(tmp_path):
    src = EXAMPLES_DIR / "sample"
    dst = tmp_path / "set"
    (dst / "cameras").mkdir(parents=True)
    for stem in ("00000", "00001", "00002"):
        shutil.copy(src / f"{stem}.jpg", dst / f"{stem}.jpg")
        shutil.copy(src / f"{stem}.json", dst / f"{stem}.json")
    shutil.copy(src / "sn22_00004.json", dst / "sn22_00004.json")  # annotation only, no image
    (dst / "bad.json").write_text("{broken")
    return dst


def test_views_calibrate_on_demand_and_agree_with_the_annotation(data):
    st = AppState(data)
    assert st.edits.root == default_edits_dir(data) and st.edits.root.parent == data.parent
    v = st.view("00000")
    assert v.result.ok and v.jac[5] > 0.9
    assert st.view("00000") is v  # cached
    w = st.view("sn22_00004")
    assert w.image is None and w.size == (960, 540) and w.result.ok
    bad = st.view("bad")
    assert bad.error and "bad.json" in bad.error and bad.result is None
    assert st.view("00001").result.ok  # the rest keeps working


def test_pnl_and_alpha_change_the_calibration(data):
    st = AppState(data)
    with_pnl = st.view("00002").result
    st.pnl = False
    without = st.view("00002").result
    assert without.pnl_lines == [] and with_pnl.pnl_lines
    assert not np.allclose(with_pnl.camera.C, without.camera.C)


def test_review_and_edits_autosave_and_survive_a_restart(data):
    before = {p.name: p.read_bytes() for p in data.iterdir() if p.is_file()}
    st = AppState(data)
    st.set_review("accepted", "00000")
    ann = st.annotation("00001")
    moved = {k: v.copy() for k, v in ann.items()}
    name = next(iter(moved))
    moved[name][0] += [0.01, 0.0]
    cam_before = st.view("00001").result.camera
    st.set_annotation(moved, "00001")
    cam_after = st.view("00001").result.camera
    assert not np.allclose(cam_before.C, cam_after.C)
    # a new server process sees the same state
    st2 = AppState(data)
    assert st2.edits.review("00000") == "accepted" and st2.edits.review("00001") == "corrected"
    np.testing.assert_allclose(st2.annotation("00001")[name], moved[name])
    assert st2.review_progress() == (2, len(st2.stems))
    # the source data is untouched and no temporary file is left behind
    assert {p.name: p.read_bytes() for p in data.iterdir() if p.is_file()} == before
    assert sorted(p.name for p in (st.edits.frames).iterdir()) == ["00000.json", "00001.json"]
    json.loads((st.edits.frames / "00001.json").read_text())


def test_a_damaged_edit_file_is_ignored(data):
    st = AppState(data)
    st.set_review("rejected", "00000")
    (st.edits.frames / "00002.json").write_text("{half a reco")
    st2 = AppState(data)
    assert st2.edits.review("00000") == "rejected" and st2.edits.review("00002") is None


def test_overlay_draws_keypoints_and_pitch(data):
    st = AppState(data)
    v = st.view("00000")
    img = render(v, Layers())
    assert img.shape == (540, 960, 3) and img.dtype == np.uint8
    plain = render(v, Layers(annotation=False, keypoints=False, initial_pitch=False, refined_pitch=False, residuals=False))
    changed = np.any(img != plain, axis=2)
    assert changed.mean() > 0.005  # overlays are drawn
    assert np.array_equal(plain[:, :, ::-1], v.image)  # and nothing else
    failed = render(st.view("bad"), Layers())
    assert failed.shape == (540, 960, 3)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_server_panels_navigate_review_and_toggle_pnl(data):
    from pnlviz.app.server import PnlvizApp

    st = AppState(data)
    app = PnlvizApp(st, port=_free_port())
    try:
        assert app.url.startswith("http://127.0.0.1:")
        app.goto(st.find("00000"))
        assert "00000" in app.card.content and "focal" in app.card.content
        app.step(1)
        assert st.stem == st.stems[st.find("00000") + 1] and app.slider.value == st.find("00000") + 1
        app.state.set_review("accepted")
        app.show()
        assert "1 of 5 reviewed" in app.progress_text.content
        app.filter.value = "accepted"
        app.refresh_order()
        assert app.order == [st.index]
        app.filter.value = "all"
        app.refresh_order()
        st.pnl = False
        app.show()
        assert "PnL set: 0 lines" in app.card.content
        app.goto(st.find("bad"))
        assert "error" in app.card.content and app._frustum is None
    finally:
        app.stop()
