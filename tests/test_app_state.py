"""The app without a browser: state, autosaved review and edits, overlays, the server's panels."""

import json
import shutil

import numpy as np
import pytest

from pnlviz import EXAMPLES_DIR
from pnlviz.app.modes import DragEvent, DragPhase, PointKind, Selection
from pnlviz.app.overlay import Layers, render
from pnlviz.app.state import AppState, Settings
from pnlviz.calib.calibrate import CalibParams
from pnlviz.data.edits import default_edits_dir


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
    assert not w.has_image and st.image("sn22_00004") is None and w.size == (960, 540) and w.result.ok
    bad = st.view("bad")
    assert bad.error and "bad.json" in bad.error and bad.result is None
    assert st.view("00001").result.ok  # the rest keeps working


def test_a_preview_is_scored_only_when_its_view_is_kept(data):
    """A preview (a point being dragged) is not scored against the annotation; once that position
    is released its view is the frame's, and its JaC is the score of its camera."""
    from pnlviz.conventions import EVAL_SIZE
    from pnlviz.metrics.soccernet import evaluate_frame

    st = AppState(data)
    obs = st.view("00001").observations
    kid, (x, y) = int(obs.kp_ids[0]), obs.kp_xy[0] + [3.0, 2.0]
    preview = st.preview("00001", st.default_settings, kid, x, y)
    assert preview.measured_jac is None  # nothing measured while the point moves
    st.move_keypoint("00001", kid, x, y)
    kept = st.view("00001")
    assert kept is preview
    truth = evaluate_frame(kept.result.camera.scaled(*EVAL_SIZE), kept.annotation)
    assert kept.jac == {t: truth.accuracy(t) for t in (5, 10, 20)} and kept.jac[5] > 0.5
    assert kept.measured_jac is kept.jac  # measured once


def test_pnl_and_alpha_change_the_calibration(data):
    st = AppState(data)
    with_pnl = st.view("00002").result
    without = st.view("00002", Settings(pnl=False)).result
    assert without.pnl_lines == [] and with_pnl.pnl_lines
    assert not np.allclose(with_pnl.camera.C, without.camera.C)


def test_review_and_edits_autosave_and_survive_a_restart(data):
    before = {p.name: p.read_bytes() for p in data.iterdir() if p.is_file()}
    st = AppState(data)
    st.set_review("00000", "accepted")
    ann = st.reader.annotation("00001")
    moved = {k: v.copy() for k, v in ann.items()}
    name = next(iter(moved))
    moved[name][0] += [0.01, 0.0]
    cam_before = st.view("00001").result.camera
    st.set_annotation("00001", moved)
    cam_after = st.view("00001").result.camera
    assert not np.allclose(cam_before.C, cam_after.C)
    st.close()
    # a new server process sees the same state
    st2 = AppState(data)
    assert st2.edits.review("00000") == "accepted" and st2.edits.review("00001") == "corrected"
    np.testing.assert_allclose(st2.reader.annotation("00001")[name], moved[name])
    assert sum(st2.edits.counts().values()) == 2
    # the source data is untouched and no temporary file is left behind
    assert {p.name: p.read_bytes() for p in data.iterdir() if p.is_file()} == before
    assert sorted(p.name for p in (st.edits.frames).iterdir()) == ["00000.json", "00001.json"]
    json.loads((st.edits.frames / "00001.json").read_text())
    st2.close()


def test_a_damaged_edit_file_is_moved_aside(data):
    st = AppState(data)
    st.set_review("00000", "rejected")
    st.close()
    (st.edits.frames / "00002.json").write_text("{half a reco")
    st2 = AppState(data)
    assert st2.edits.review("00000") == "rejected" and st2.edits.review("00002") is None
    assert (st.edits.frames / "00002.json.damaged").read_text() == "{half a reco"
    assert len(st2.edits.warnings) == 1 and "00002.json" in st2.edits.warnings[0]
    st2.close()


def test_overlay_draws_keypoints_and_pitch(data):
    st = AppState(data)
    v = st.view("00000")
    img = render(v, st.image("00000"), Layers())
    assert img.shape == (540, 960, 3) and img.dtype == np.uint8
    plain = render(v, st.image("00000"), Layers(annotation=False, keypoints=False, initial_pitch=False,
                                                refined_pitch=False, residuals=False, reference_pitch=False))
    changed = np.any(img != plain, axis=2)
    assert changed.mean() > 0.005  # overlays are drawn
    assert np.array_equal(plain[:, :, ::-1], st.image("00000"))  # and nothing else
    failed = render(st.view("bad"), None, Layers())
    assert failed.shape == (540, 960, 3)


def test_server_panels_navigate_review_and_toggle_pnl(data, serve):
    app = serve(data)
    st = app.state
    assert app.url.startswith("http://127.0.0.1:")
    tab = app.session()
    p = tab.panels
    tab.goto(st.find("00000"))
    assert "00000" in p.title.content and "focal" in p.card.content
    tab.step(1)
    assert tab.stem == st.stems[st.find("00000") + 1] and p.slider.value == st.find("00000") + 2  # from 1
    st.set_review(tab.stem, "accepted")
    assert "1 of 5 reviewed" in p.progress_text.content  # the change reached the tab
    assert "review: **accepted**" in p.status.content
    p.filter.value = "accepted"
    tab.flush()
    assert tab.frames.order == [tab.index]
    p.filter.value = "all"
    tab.flush()
    p.pnl.value = False
    tab.flush()
    assert "PnL set: 0 lines" in p.card.content
    tab.goto(st.find("bad"))
    assert "error" in p.card.content and tab.scene3d._frustum is None
    assert tab.workspace.plane is not None  # a frame that cannot be read still has its image plane


def test_keypoint_edits_recalibrate_undo_redo_and_persist(data):
    st = AppState(data)
    stem = "00002"
    v0 = st.view(stem)
    kid = int(v0.observations.kp_ids[0])
    x, y = v0.observations.kp_xy[0]
    st.move_keypoint(stem, kid, x + 25, y - 10)
    v1 = st.view(stem)
    i = list(v1.observations.kp_ids).index(kid)
    np.testing.assert_allclose(v1.observations.kp_xy[i], [x + 25, y - 10])
    assert not np.allclose(v1.result.camera.C, v0.result.camera.C)
    assert st.edits.review(stem) == "corrected"
    st.hide_keypoint(stem, kid)
    assert kid not in st.view(stem).observations.kp_ids
    assert st.undo(stem)  # back to the moved keypoint
    assert kid in st.view(stem).observations.kp_ids
    assert st.undo(stem) and not st.undo(stem)  # back to the original, nothing more to undo
    np.testing.assert_allclose(st.view(stem).result.camera.C, v0.result.camera.C)
    assert st.edits.review(stem) is None  # undoing every edit undoes "corrected" too
    assert st.redo(stem)
    st.close()
    restarted = AppState(data)
    j = list(restarted.view(stem).observations.kp_ids).index(kid)
    np.testing.assert_allclose(restarted.view(stem).observations.kp_xy[j], [x + 25, y - 10])
    restarted.close()


def test_the_tabs_are_told_of_an_edit_before_its_review_snapshot_is_taken(data):
    """An edit reaches the tabs (they redraw) without waiting for the review snapshot, which is
    in the record by the time the edit returns, taken with that edit, even when a listener
    fails."""
    from pnlviz.data.snapshot import edits_digest

    st = AppState(data)
    stem = "00002"
    obs = st.view(stem).observations
    kid, (x, y) = int(obs.kp_ids[0]), obs.kp_xy[0]
    st.move_keypoint(stem, kid, x + 5, y)  # the frame is "corrected" from here: its edits take snapshots

    def label() -> tuple[float, float]:
        got = st.edits.get(stem)["snapshot"]["labels"][str(kid)]
        return got["x"], got["y"]

    told = []
    st.subscribe(lambda s: told.append(label()))
    st.move_keypoint(stem, kid, x + 25, y - 10)
    assert told == [pytest.approx((x + 5, y))]  # told first: the old snapshot is still there
    assert label() == pytest.approx((x + 25, y - 10))
    assert st.edits.get(stem)["snapshot"]["edits"] == edits_digest(st.edits.get(stem))  # taken with this edit

    def fails(_stem: str) -> None:
        raise RuntimeError("a listener failed")

    st.subscribe(fails)  # the error reaches the caller, and the snapshot of the edit is still taken
    with pytest.raises(RuntimeError, match="a listener failed"):
        st.move_keypoint(stem, kid, x + 30, y)
    assert label() == pytest.approx((x + 30, y)) and st.edits.get(stem)["keypoints"][str(kid)] == [x + 30, y]
    st.close()


def test_line_point_edit_goes_into_the_annotation(data):
    st = AppState(data)
    ann = st.reader.annotation("00001")
    name = next(iter(ann))
    st.move_line_point("00001", name, 0, 100.0, 200.0)
    np.testing.assert_allclose(st.reader.annotation("00001")[name][0], [100 / 959, 200 / 539])
    assert st.undo("00001")
    np.testing.assert_allclose(st.reader.annotation("00001")[name][0], ann[name][0])


def test_export_holds_the_edit_and_only_reviewed_frames(data, tmp_path):
    import zipfile

    from pnlviz.app.export import export_zip_bytes
    from pnlviz.cli import main
    from pnlviz.pipeline.export import write_export

    st = AppState(data)
    st.set_review("00000", "accepted")
    kid = int(st.view("00002").observations.kp_ids[0])
    st.move_keypoint("00002", kid, 123.0, 234.0)
    out = tmp_path / "export.zip"
    out.write_bytes(export_zip_bytes(st))
    with zipfile.ZipFile(out) as zf:
        names = set(zf.namelist())
        manifest = json.loads(zf.read("manifest.json"))
        kps = json.loads(zf.read("keypoints/00002.json"))
        coco = json.loads(zf.read("coco_keypoints.json"))
    assert set(manifest["frames"]) == {"00000", "00002"}
    assert manifest["frames"]["00002"]["keypoints_edited"] == [kid]
    assert manifest["source"] == "set" and manifest["edits"] == "set.edits"  # names, never server paths
    assert {"annotations/00000.json", "cameras/camera_00000.json", "cameras/camera_00002.json"} <= names
    assert kps["keypoints"][str(kid)]["x"] == 123.0 and kps["keypoints"][str(kid)]["y"] == 234.0
    image_id = next(im["id"] for im in coco["images"] if im["stem"] == "00002")
    ann = next(a for a in coco["annotations"] if a["image_id"] == image_id)
    assert ann["keypoints"][3 * (kid - 1):3 * kid] == [123.0, 234.0, 2]
    # the command line writes the same into a folder (while the app holds the edits), --all takes
    # every frame; the unreadable frame is in the manifest without label files
    folder = tmp_path / "folder"
    assert main(["export", "--data", str(data), "--out", str(folder), "--all"]) == 0
    frames = json.loads((folder / "manifest.json").read_text())["frames"]
    assert len(frames) == len(st.stems) and frames["bad"]["exported"] is False and "bad.json" in frames["bad"]["error"]
    assert not (folder / "keypoints" / "bad.json").exists() and (folder / "keypoints" / "00001.json").exists()
    assert len(write_export(st.reader, tmp_path / "again")) == 2
    assert main(["export", "--data", str(data), "--out", str(data)]) == 2  # never over the source


def test_export_only_reads_the_edits(data, tmp_path):
    from pnlviz.cli import main

    assert main(["export", "--data", str(data), "--out", str(tmp_path / "x.zip"), "--all"]) == 0
    assert not default_edits_dir(data).exists()  # export created no edits folder


def test_drag_end_recalibrates_on_the_server(data, serve):
    app = serve(data)
    st = app.state
    tab = app.session()
    tab.goto(st.find("00002"))
    view = tab.view()
    assert tab.workspace.points["keypoints"].keys == [int(k) for k in view.observations.kp_ids]
    before = view.result.camera.C.copy()
    kid, uv0 = int(view.observations.kp_ids[0]), view.observations.kp_xy[0]
    tab.editor.drag(DragEvent(PointKind.KEYPOINTS, kid, DragPhase.START, uv0))
    tab.editor.drag(DragEvent(PointKind.KEYPOINTS, kid, DragPhase.UPDATE, np.array([300.0, 200.0])))
    tab.flush()
    assert "keypoints" not in st.edits.get("00002")  # only the release counts...
    assert not np.allclose(tab.painter.overlay.keypoints.uv[0], [300.0, 200.0])  # ...and the preview is not kept
    tab.goto(st.find("00001"))  # the tab moves on before the release...
    tab.editor.drag(DragEvent(PointKind.KEYPOINTS, kid, DragPhase.END, np.array([300.0, 200.0])))
    tab.flush()
    saved = json.loads((st.edits.frames / "00002.json").read_text())  # ...which still lands on 00002
    np.testing.assert_allclose(saved["keypoints"][str(kid)], [300.0, 200.0], atol=1e-6)
    assert "keypoints" not in st.edits.get("00001")
    assert not np.allclose(st.view("00002").result.camera.C, before)
    assert tab.editor.last_recalibration_ms > 0 and tab.editor.grabs == tab.editor.releases == 1


@pytest.mark.parametrize("let_go", ["elsewhere", "there"])
def test_a_preview_is_given_up_when_its_point_is_let_go_elsewhere(data, serve, monkeypatch, let_go):
    """The hand lets go while the frame is being recalibrated for where the point was a moment ago:
    let go elsewhere, that preview stops (the release's own calibration need not wait for it) and
    the release keeps the camera the frame gives with the point where it was let go; let go there,
    the preview finishes and is the view the release keeps."""
    from pnlviz.pipeline import frame_view

    app = serve(data)
    st, tab = app.state, app.session()
    tab.goto(st.find("00002"))
    tab.flush()
    view = tab.view()
    kid, uv0 = int(view.observations.kp_ids[0]), view.observations.kp_xy[0].copy()
    moved, released = uv0 + [6.0, 3.0], (uv0 + [12.0, 5.0] if let_go == "elsewhere" else uv0 + [6.0, 3.0])
    original, shown = st.preview, []

    def preview(stem, settings, k, x, y):  # the release arrives while this preview computes
        tab.editor.drag(DragEvent(PointKind.KEYPOINTS, kid, DragPhase.END, released))
        shown.append(original(stem, settings, k, x, y))
        return shown[-1]

    monkeypatch.setattr(st, "preview", preview)
    tab.editor.drag(DragEvent(PointKind.KEYPOINTS, kid, DragPhase.START, uv0))
    tab.editor.drag(DragEvent(PointKind.KEYPOINTS, kid, DragPhase.UPDATE, moved))
    tab.flush()
    tab.flush()  # the release, queued while the preview ran
    np.testing.assert_allclose(st.edits.get("00002")["keypoints"][str(kid)], released, atol=1e-6)
    kept = st.view("00002")
    i = list(kept.observations.kp_ids).index(kid)
    np.testing.assert_allclose(kept.observations.kp_xy[i], released, atol=1e-6)
    if let_go == "elsewhere":
        assert tab.editor.previews_given_up == 1 and not shown  # stopped before it returned
        fresh = frame_view(st.reader, "00002", st.default_settings)
        np.testing.assert_allclose(kept.result.camera.R, fresh.result.camera.R)
        np.testing.assert_allclose(kept.result.camera.C, fresh.result.camera.C)
    else:
        assert tab.editor.previews_given_up == 0 and kept is shown[0]
    assert tab.painter.shown is kept and tab.editor.releases == 1


def tab_on(serve, data, stem: str):
    """The app on ``data`` and a tab of it (no browser) showing frame ``stem``, drawn."""
    app = serve(data)
    tab = app.session()
    tab.goto(app.state.find(stem))
    tab.flush()
    return app, tab


def test_the_ids_written_over_the_frame_are_the_points_shown_observed_first(data, serve):
    _, tab = tab_on(serve, data, "00002")
    ws = tab.workspace
    observed, ghosts = ws.points[PointKind.KEYPOINTS], ws.points[PointKind.GHOSTS]
    assert len(observed.keys) and len(ghosts.keys)
    want = sorted((str(k), tuple(uv)) for k, uv in zip(observed.keys, observed.uv))
    want += sorted((f"{k}?", tuple(uv)) for k, uv in zip(ghosts.keys, ghosts.uv))
    assert [(t, (u, v)) for t, u, v in ws.id_labels] == want
    # an occluded keypoint's id is in parentheses
    kid = observed.keys[0]
    tab.editor.select(Selection(PointKind.KEYPOINTS, kid))
    tab.editor.cycle_visibility()
    tab.flush()
    assert f"({kid})" in [t for t, _, _ in ws.id_labels] and str(kid) not in [t for t, _, _ in ws.id_labels]
    tab.painter.set_layer("ids", False)
    tab.flush()
    assert ws.id_labels == []


def test_the_page_draws_the_layers_shown_back_to_front_and_the_selection_over_them(data, serve):
    from pnlviz.app.overlay import FLAGGED_RGB, PIN_RGB
    from pnlviz.app.points import DISC_PX, RIM_PX
    from pnlviz.app.workspace import LINE_ORDER, RING_PX, THICKNESS

    app, tab = tab_on(serve, data, "00002")
    ws = tab.workspace
    overlay = tab.painter.overlay
    observed, ghosts = ws.points[PointKind.KEYPOINTS], ws.points[PointKind.GHOSTS]

    def kinds(marks):
        return [(m.kind, m.rgb) for m in marks]

    marks = ws.marks
    lines = [m for m in marks if m.kind == "s"]
    # the overlay's every segment, each layer in its colours and width, the layers in their order
    want = [(name, m) for name in LINE_ORDER if name in overlay.segments for m in [overlay.segments[name]] if len(m)]
    assert sum(len(m.xy) for m in lines) == 2 * sum(len(seg) for _, seg in want)
    widths = [m.width for m in lines]
    assert widths[0] == THICKNESS[want[0][0]] and widths[-1] == THICKNESS[want[-1][0]]
    assert marks[:len(lines)] == lines and all(m.alpha == 1.0 for m in lines)  # the lines first
    discs = marks[len(lines):]
    # the ghosts on their rims, then the keypoints on theirs, each point where the grab mesh is
    assert discs[0].size == RIM_PX and discs[0].rgb == (0, 0, 0) and len(discs[0].xy) == len(ghosts.keys)
    np.testing.assert_allclose(discs[0].xy, ghosts.uv)
    rim = next(i for i, m in enumerate(discs[1:], 1) if m.size == RIM_PX)
    np.testing.assert_allclose(discs[rim].xy, observed.uv)
    assert all(m.size == DISC_PX for m in discs[rim + 1:])
    assert sum(len(m.xy) for m in discs[rim + 1:]) == len(observed.keys)
    # a selected point and a pinned one: the box, then the ring, over everything
    kid = observed.keys[0]
    tab.editor.select(Selection(PointKind.KEYPOINTS, kid))
    app.state.move_keypoint("00002", kid, float(observed.uv[0, 0]) + 1.0, float(observed.uv[0, 1]), tab.settings)
    tab.show()
    tab.flush()
    marks = ws.marks
    assert kinds(marks[-2:]) in ([("q", PIN_RGB), ("c", (255, 255, 255))], [("q", FLAGGED_RGB), ("c", (255, 255, 255))])
    assert marks[-1].size == RING_PX
    np.testing.assert_allclose(marks[-1].xy, [observed.uv[observed.keys.index(kid)]])
    # the lines at the overlay's opacity; a layer switched off is not drawn
    tab.painter.set_opacity(0.4)
    tab.painter.set_layer("ghosts", False)
    tab.painter.set_layer("keypoints", False)
    tab.flush()
    marks = ws.marks
    assert {m.alpha for m in marks if m.kind == "s"} == {0.4}
    assert not [m for m in marks if m.kind in "dq"] and ws.points[PointKind.GHOSTS].keys == []


def test_annotation_and_detections_merge_with_the_side_convention_resolved(shared_dir, tmp_path):
    """PnLCalib's detections name the near goal 'left'; WC14 annotations name the true side.
    Merged, they must not fight: 'both' scores at least as well as either alone."""
    data = shared_dir / "data" / "wc14_test_half"
    st = AppState(data / "annotations.zip", detections=data / "detections_pnlcalib.zip", edits=tmp_path / "e")
    scores = {}
    for source in ("annotation", "detections", "both"):
        st.source = source
        scores[source] = np.mean([st.view(s).jac.get(5, 0.0) for s in st.stems[:20]])
    assert scores["both"] >= max(scores["annotation"], scores["detections"]) - 0.02


def test_light_default_detector_calibrates_frames_without_annotation(tmp_path, monkeypatch):
    """`pnlviz serve` with no weights runs the shipped light model: annotated frames keep the
    annotation as their source; a frame with only an image is calibrated from its detections."""
    import cv2

    from pnlviz.detect.run import Detector
    from pnlviz.synth import make_frame

    data = tmp_path / "set"
    data.mkdir()
    f = make_frame(2, 777, (960, 540))  # a seed the model was not trained on
    cv2.imwrite(str(data / "solo.jpg"), f["image"])
    shutil.copy(EXAMPLES_DIR / "sample" / "00000.jpg", data / "00000.jpg")
    shutil.copy(EXAMPLES_DIR / "sample" / "00000.json", data / "00000.json")
    st = AppState(data, detector=Detector.from_weights(None, None), source="annotation", edits=tmp_path / "e")
    assert st.default_settings.source == "annotation" and st.needs_detection("solo")
    before = st.view("solo")
    assert before.result is None or not before.result.ok  # nothing to calibrate from yet
    annotated = st.view("00000").observations
    for stem in ("solo", "00000"):
        st.run_detector(stem)
    assert not st.needs_detection("solo") and len(st.reader.detections("solo").keypoints) >= 4
    import pnlviz.calib.frame as frame_module
    from pnlviz.app.cards import calibration_card

    used = {}
    real = frame_module.calibrate

    def recording(obs, params, model=None):
        used[current] = params
        return real(obs, params, model)

    monkeypatch.setattr(frame_module, "calibrate", recording)
    for current in ("solo", "00000"):
        st.view(current)
    monkeypatch.undo()
    view = st.view("solo")
    assert view.result is not None and view.result.ok and view.annotation is None
    # detections get the detection settings (no k1, robust final loss), annotations the default
    assert used["solo"] == CalibParams().updated(st.detector.calibration)
    # the annotated frame was not calibrated again: detections do not change its annotation's camera
    assert "00000" not in used and st.view("00000").origin == "annotation"
    card = calibration_card(view, st)
    assert view.origin == "detections" and "calibrated from: **detections**" in card and "refine_k1=False" in card
    assert "calibrated from: **annotation**" in calibration_card(st.view("00000"), st)
    # the annotated frame's observations are still the annotation's alone
    again = st.view("00000").observations
    assert np.array_equal(again.kp_ids, annotated.kp_ids) and np.array_equal(again.kp_xy, annotated.kp_xy)
    assert again.lines.keys() == annotated.lines.keys()


def test_the_detector_process_keeps_torch_out_of_the_app():
    """The app's detector runs in a child process: the app process never imports torch (importing
    it in a thread beside scipy crashed `pnlviz serve`), and a checkpoint that does not fit is a
    clear error in the parent."""
    import subprocess
    import sys

    code = (
        "import sys, numpy as np\n"
        "from pnlviz.detect.worker import DetectorLoadError, DetectorProcess\n"
        "d = DetectorProcess()\n"
        "pred = d.detect([np.zeros((96, 160, 3), np.uint8)])[0]\n"
        "assert 'torch' not in sys.modules and len(pred.keypoints) < 57 and d.calibration\n"
        "d.close()\n"
        "bad = DetectorProcess(weights_kp=__import__('pathlib').Path('no-such.pth'))\n"
        "try:\n"
        "    bad.load()\n"
        "except DetectorLoadError as exc:\n"
        "    assert 'no-such.pth' in str(exc), exc\n"
        "else:\n"
        "    raise AssertionError('no error')\n"
        "bad.close()\n"
        "assert 'torch' not in sys.modules\n"
        "print('ok')\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0 and out.stdout.strip() == "ok", out.stderr


def test_nudges_of_one_point_in_a_row_are_one_undo_step(data, monkeypatch):
    """Each arrow nudge was its own undo step: ten nudges, ten Ctrl+Z. Nudges of one point in a
    row (each within 2 s of the last, nothing else between) are one step now."""
    import pnlviz.data.edits as edits_module

    st = AppState(data)
    kid, (x, y) = int(st.view("00000").observations.kp_ids[0]), st.view("00000").observations.kp_xy[0]
    for k in range(1, 4):
        st.move_keypoint("00000", kid, x + k, y, merge=("nudge", kid))
    assert st.edits.history("00000") == (1, 0)
    st.move_keypoint("00000", kid, x + 3, y + 1)  # a drag: its own step
    st.move_keypoint("00000", kid, x + 4, y + 1, merge=("nudge", kid))  # another run of nudges
    assert st.edits.history("00000") == (3, 0)
    monkeypatch.setattr(edits_module, "MERGE_S", 0.0)  # a pause: the next nudge is a step of its own
    st.move_keypoint("00000", kid, x + 5, y + 1, merge=("nudge", kid))
    assert st.edits.history("00000") == (4, 0)
    for _ in range(2):
        st.undo("00000")
    assert st.edits.get("00000")["keypoints"][str(kid)] == [x + 3, y + 1]
    st.undo("00000")  # the drag
    assert st.edits.get("00000")["keypoints"][str(kid)] == [x + 3, y]
    st.undo("00000")  # the three first nudges, in one step
    assert str(kid) not in (st.edits.get("00000").get("keypoints") or {}) and st.edits.review("00000") is None


def test_a_corrected_confirmed_by_hand_survives_undoing_the_edits(data):
    """An edit marks the frame corrected; the annotator then says *corrected* (C) too: undoing
    every edit used to clear it with them."""
    st = AppState(data)
    kid, (x, y) = int(st.view("00000").observations.kp_ids[0]), st.view("00000").observations.kp_xy[0]
    st.move_keypoint("00000", kid, x + 4, y)
    st.move_keypoint("00000", kid, x + 8, y)
    assert st.edits.review("00000") == "corrected"
    st.set_review("00000", "corrected")
    while st.undo("00000"):
        pass
    assert str(kid) not in (st.edits.get("00000").get("keypoints") or {})
    assert st.edits.review("00000") == "corrected"
    # without the confirmation the edits take their "corrected" back with them
    st.move_keypoint("00001", int(st.view("00001").observations.kp_ids[0]), 10.0, 10.0)
    while st.undo("00001"):
        pass
    assert st.edits.review("00001") is None


def test_the_views_and_images_go_when_the_last_tab_leaves(data, serve):
    """serve's memory only grew: every frame visited stayed cached after the client left."""
    app = serve(data)
    a, b = app.session(), app.session()
    for _ in range(3):
        a.step(1)
    st = app.state
    assert len(st._cache) >= 3 and len(st._images) >= 1
    app.close_session(a)
    assert len(st._cache) >= 3  # tab b still shows frames
    app.close_session(b)
    assert st._cache == {} and st._images == {} and st._previews == {}
    assert st.view("00000").result.ok  # and they come back when asked for


def test_the_panel_shows_the_frame_from_above(data, serve):
    """The bird's-eye view under the calibration card: the camera's footprint on the pitch, and
    another frame's camera gives another footprint."""
    from pnlviz.viz import top_view

    app = serve(data)
    tab = app.session()
    tab.goto(app.state.find("00000"))
    tab.flush()  # drawn as the tab's next action, after the frame
    first = tab.panels.top_view.image.copy()
    plain = top_view(None, px_per_m=3.0)[:, :, ::-1]
    assert first.shape == plain.shape and np.abs(first.astype(int) - plain).sum(axis=2).astype(bool).mean() > 0.05
    tab.goto(app.state.find("00001"))
    tab.flush()
    assert (tab.panels.top_view.image != first).any()


def test_releasing_the_caches_starts_no_process(monkeypatch):
    """The last tab leaving returns the freed heap (malloc_trim). Looking libc up through
    ctypes.util.find_library ran ldconfig in a child process each time; a child forked while the
    edits folder was handed to the next app held its lock, and that app was refused under load."""
    import subprocess

    from pnlviz.app import state

    started = []

    def no_process(self, *args, **kwargs):
        started.append(args)
        raise AssertionError(f"a process was started: {args[:1]}")

    monkeypatch.setattr(subprocess.Popen, "__init__", no_process)
    state._return_free_memory()
    assert started == []


def test_the_background_pass_waits_while_a_tab_acts_and_goes_on_after(data, tmp_path):
    """The pass takes no frame while a tab's action runs nor until the tabs have been quiet for a
    moment; then it calibrates every frame."""
    import threading

    from pnlviz.app.tabqueue import TabQueue

    with AppState(data, edits=tmp_path / "edits") as st:
        queue = TabQueue(lambda *a, **k: None, activity=st.activity)
        acting, release = threading.Event(), threading.Event()

        def long_action():
            acting.set()
            release.wait(30)

        queue.enqueue(long_action)
        assert acting.wait(10) and st.activity.busy()
        done = []
        worker = threading.Thread(target=lambda: done.append(st.triage.run(threading.Event(), lambda text: None)))
        worker.start()
        worker.join(1.5)
        assert worker.is_alive() and len(st.triage.store) == 0  # waiting: not one frame taken
        release.set()
        queue.flush()
        worker.join(120)
        assert done and done[0].finished and done[0].done == len(st.stems)
        assert set(st.triage.summaries()) == set(st.stems)
        queue.close(wait=True)


@pytest.mark.parametrize("interruptions", [1, 99])
def test_the_background_pass_gives_a_frame_up_when_a_tab_acts_and_takes_it_again(data, tmp_path, monkeypatch,
                                                                                 interruptions):
    """A tab that acts while the pass calibrates a frame stops that work at the solver's next
    iteration (nothing of it kept); once the tabs are quiet the frame is calibrated from the start,
    to the summary it would have had anyway, and the pass goes on to the end. A frame the tabs
    interrupt every time is given up YIELDS_PER_FRAME times, then run to its end."""
    import threading

    from pnlviz.app.triage import YIELDS_PER_FRAME, Triage

    given_up = min(interruptions, YIELDS_PER_FRAME)

    with AppState(data, edits=tmp_path / "reference") as ref:
        expected = {s: ref.triage.calibrate(s) for s in ref.stems}
    with AppState(data, edits=tmp_path / "edits") as st:
        calls, real = [], Triage.calibrate

        def calibrate(triage, stem):
            calls.append(stem)
            if stem == "00001" and calls.count(stem) <= interruptions:
                st.activity.begin()  # the hand starts a drag as the frame begins
                threading.Timer(0.3, st.activity.end).start()
            return real(triage, stem)

        monkeypatch.setattr(Triage, "calibrate", calibrate)
        progress = st.triage.run(threading.Event(), lambda text: None)
        assert st.triage.yielded == given_up and calls.count("00001") == given_up + 1  # given up, then done
        assert [c for c in calls if c != "00001"] == [s for s in st.stems if s != "00001"]
        assert progress.finished and progress.done == len(st.stems)
        got = st.triage.summaries()
        assert set(got) == set(st.stems)
        for stem, want in expected.items():
            assert (got[stem].ok, got[stem].worst, got[stem].median, got[stem].suspect) == \
                (want.ok, want.worst, want.median, want.suspect), stem


def test_a_tab_busy_for_good_does_not_stop_the_pass(data, tmp_path):
    """A tab that never pauses (a clip played for minutes) makes the pass wait its longest wait
    before each frame, and the frame is then calibrated to its end, not given up."""
    import threading

    from pnlviz.app.triage import Triage

    with AppState(data, edits=tmp_path / "edits") as st:
        triage = Triage(st.host, st.triage.store, run_detector=st.run_detector, user_busy=st.activity.busy,
                        wait_quiet=lambda stop: st.activity.wait_quiet(stop, longest=0.2))
        st.activity.begin()  # and never ends
        progress = triage.run(threading.Event(), lambda text: None)
        assert progress.finished and progress.done == len(st.stems) and triage.yielded == 0
        assert set(triage.summaries()) == set(st.stems)


def test_waiting_for_quiet_tabs_ends_on_stop_and_after_the_quiet_time():
    import threading
    import time

    from pnlviz.app.activity import UserActivity

    activity = UserActivity(quiet=0.2)
    stop = threading.Event()
    assert activity.wait_quiet(stop) < 0.1  # nobody acted yet
    activity.begin()
    stop.set()
    assert activity.wait_quiet(stop) < 0.1 and activity.busy()  # stopping does not wait for the tab
    stop.clear()
    activity.end()
    waited = activity.wait_quiet(stop)
    assert 0.15 <= waited < 5 and not activity.busy()
    activity.begin()
    activity.begin()
    activity.end()  # one of two actions ended: still busy
    t = time.monotonic()
    assert activity.wait_quiet(stop, longest=0.3) >= 0.3 and time.monotonic() - t < 5  # a tab busy for good
