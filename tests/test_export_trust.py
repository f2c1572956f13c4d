"""One export from the data and the edits folder alone: the app's button and `pnlviz export` write
the same label files whatever the server detected; a reviewed frame exports what was on screen
when it was reviewed (its snapshot), never detections that came after; the outlier gate flags
visible points far from their frame's camera unless a hand placed them."""

import hashlib
import json
import shutil

import numpy as np
import pytest

from pnlviz import EXAMPLES_DIR
from pnlviz.cli import main

STEMS = ("00000", "00002", "00003", "00004", "00007")


def _true_detections(stem: str, moved: dict | None = None):
    """Detections of a synthetic sample frame: its keypoints through its true camera (``moved``:
    id -> pixel offset for some)."""
    from pnlviz.data import Predictions, open_dataset
    from pnlviz.field.model import load_field_model
    from pnlviz.geometry.camera import Camera

    model = load_field_model()
    ds = open_dataset(EXAMPLES_DIR / "sample")
    W, H = ds.image_size(stem)
    cam = Camera.from_soccernet(ds.camera_dict(stem)).scaled(W, H)
    ids = [int(i) for i in model.keypoint_ids if model.keypoints[int(i)].group == "Kp"]
    uv = cam.project(model.keypoint_xyz(np.array(ids)))
    kps = {}
    for kid, (x, y) in zip(ids, uv):
        if np.isfinite(x) and 5 <= x < W - 5 and 5 <= y < H - 5:
            dx, dy = (moved or {}).get(kid, (0.0, 0.0))
            kps[kid] = ((x + dx) / W, (y + dy) / H, 0.9)
    return Predictions(keypoints=kps)


class FakeDetector:
    """A detector for the app's state: the frames' true keypoints, known by their pixels."""

    calibration = {"refine_k1": False}

    def __init__(self, preds: dict):
        self.by_pixels = preds

    def detect(self, images):
        return [self.by_pixels[hashlib.sha1(np.ascontiguousarray(img).tobytes()).hexdigest()] for img in images]


@pytest.fixture()
def images_only(tmp_path):
    """Five sample frames as images alone (no annotation), and a detector that knows them."""
    from pnlviz.data import open_dataset

    data = tmp_path / "frames"
    data.mkdir()
    for stem in STEMS:
        shutil.copy(EXAMPLES_DIR / "sample" / f"{stem}.jpg", data / f"{stem}.jpg")
    ds = open_dataset(data)
    preds = {hashlib.sha1(np.ascontiguousarray(ds.image(s)).tobytes()).hexdigest():
             _true_detections(s, {5: (40.0, 25.0)} if s == "00007" else None) for s in STEMS}
    return data, FakeDetector(preds)



def _tab_on(images_only, tmp_path, serve, stem: str):
    """The app on the image-only frames, ``stem`` detected and shown in a tab whose notices are
    kept: (state, tab, the notices' titles)."""
    data, detector = images_only
    app = serve(data, edits=tmp_path / "edits", detector=detector)
    st = app.state
    st.run_detector(stem)
    tab = app.session()
    tab.goto(st.find(stem))
    said: list[str] = []
    tab.notify = lambda title, body, error=True: said.append(title)
    return st, tab, said

def _export_both(st, data, edits, tmp_path, *flags):
    from pnlviz.app.export import export_zip_bytes
    from pnlviz.pipeline.export import read_export_zip

    button = tmp_path / "button.zip"
    button.write_bytes(export_zip_bytes(st, include_all="--all" in flags))
    cli = tmp_path / "cli.zip"
    assert main(["export", "--data", str(data), "--edits", str(edits), "--out", str(cli), "--no-progress", *flags]) == 0
    return read_export_zip(button), read_export_zip(cli)


def test_the_button_and_the_command_write_the_same_files_where_the_server_detected(images_only, tmp_path):
    """The server detected on image-only frames and the annotator reviewed some of them (one after
    placing points by hand, before the detections came): the button's zip and `pnlviz export`
    (which never saw those detections) hold byte-identical label files, with and without --all."""
    from pnlviz.app.state import AppState

    data, detector = images_only
    edits = tmp_path / "edits"
    with AppState(data, edits=edits, detector=detector) as st:
        for stem in ("00000", "00007", "00002"):
            st.run_detector(stem)
        st.set_review("00000", "accepted")
        st.set_review("00007", "accepted")
        hand = {k: v for k, v in list(_true_detections("00003").keypoints_px(960, 540).items())[:5]}
        for kid, (x, y, _) in hand.items():
            st.move_keypoint("00003", kid, x, y)  # corrected, by hand, before any detection there
        st.run_detector("00003")  # 17 detections nobody reviewed arrive afterwards
        assert st.view("00003").observations.n_keypoints > len(hand)
        (b_members, b_manifest), (c_members, c_manifest) = _export_both(st, data, edits, tmp_path)
        assert b_members == c_members and b_manifest == c_manifest
        assert set(b_manifest["frames"]) == {"00000", "00007", "00003"}
        kps = json.loads(b_members["keypoints/00003.json"])
        assert {int(k) for k in kps["keypoints"]} == set(hand)  # only what was reviewed
        assert {k["provenance"] for k in kps["keypoints"].values()} == {"hand"} and kps["reviewed"] is True
        k0 = json.loads(b_members["keypoints/00000.json"])["keypoints"]
        assert k0 and {k["provenance"] for k in k0.values()} == {"detection"}
        assert "cameras/camera_00000.json" in b_members and b_manifest["frames"]["00000"]["labels"] == "snapshot"
        # --all: the unreviewed frames are there, marked so, the same from both
        (b_members, b_manifest), (c_members, c_manifest) = _export_both(st, data, edits, tmp_path, "--all")
        assert b_members == c_members and b_manifest == c_manifest
        # an unreviewed frame with something to export is there, marked so; one with nothing
        # (no annotation, no detections the command can read, no hand point) is listed, not written
        unreviewed = [s for s, e in b_manifest["frames"].items() if e["review"] is None]
        assert unreviewed and all(
            json.loads(b_members[f"keypoints/{s}.json"])["reviewed"] is False if b_manifest["frames"][s]["exported"]
            else b_manifest["frames"][s]["empty"] and f"keypoints/{s}.json" not in b_members for s in unreviewed)


def test_a_reviewed_frame_exports_what_was_on_screen_and_an_old_record_no_detections(images_only, tmp_path):
    """Detections made after a review never reach that frame's labels; a reviewed record of an
    older version (no snapshot) exports its hand points, not the detections given to export."""
    from pnlviz.app.state import AppState
    from pnlviz.data import write_predictions
    from pnlviz.pipeline.export import read_export_zip

    data, detector = images_only
    edits = tmp_path / "edits"
    with AppState(data, edits=edits, detector=detector) as st:
        st.set_review("00002", "accepted")  # nothing on screen yet: no labels
        st.run_detector("00002")
        assert st.view("00002").result.ok  # the server now calibrates it from the detections
    # an older record: reviewed, two hand points, no snapshot
    (edits / "frames" / "00004.json").write_text(json.dumps({"review": "accepted",
                                                             "keypoints": {"1": [10.0, 20.0], "2": [400.0, 30.0]}}))
    preds = tmp_path / "preds.zip"
    write_predictions(preds, {s: _true_detections(s) for s in STEMS})
    out = tmp_path / "x.zip"
    assert main(["export", "--data", str(data), "--edits", str(edits), "--detections", str(preds), "--out", str(out),
                 "--no-progress"]) == 0
    members, manifest = read_export_zip(out)
    assert json.loads(members["keypoints/00002.json"])["keypoints"] == {}
    assert "cameras/camera_00002.json" not in members
    k4 = json.loads(members["keypoints/00004.json"])["keypoints"]
    assert set(k4) == {"1", "2"} and manifest["frames"]["00004"]["labels"] == "edits"


def test_the_gate_flags_far_points_unless_a_hand_placed_them():
    """The gate's pure part: a visible point beyond the threshold (10 px at 960x540, scaled with
    the frame) is flagged unless hand-placed; points outside the image and frames without a
    camera are not checked."""
    from pnlviz.pipeline.snapshot import FrameLabels, Label, gate, gate_threshold

    assert gate_threshold((960, 540)) == pytest.approx(10.0)
    assert gate_threshold((1280, 720)) == pytest.approx(40 / 3)
    labels = {1: Label(100, 100, "Kp", "detection", 12.0), 2: Label(100, 100, "Kp", "hand", 80.0),
              3: Label(-30, 100, "Kp", "annotation", 90.0), 4: Label(200, 100, "Kp", "annotation", 9.0),
              5: Label(300, 100, "Kp", "detection", None)}
    fl = FrameLabels((960, 540), labels, {"camera": 1}, None, "snapshot")
    assert gate(fl) == {1: 12.0, 5: float("inf")}
    assert gate(FrameLabels((1280, 720), labels, {"camera": 1}, None, "snapshot")) == {5: float("inf")}
    assert gate(fl, gate_px=15.0) == {5: float("inf")}
    assert gate(FrameLabels((960, 540), labels, None, None, "snapshot")) == {}


def test_a_far_detection_is_exported_flagged_and_a_hand_confirms_it(images_only, tmp_path):
    """A detection 47 px off (40, 25) on an accepted frame: exported flagged (COCO v 0, its residual in the
    label file, counted in the manifest); after the annotator moves it, it is ground truth."""
    from pnlviz.app.state import AppState

    data, detector = images_only
    edits = tmp_path / "edits"
    with AppState(data, edits=edits, detector=detector) as st:
        st.run_detector("00007")
        st.set_review("00007", "accepted")
        (members, manifest), _ = _export_both(st, data, edits, tmp_path)
        k5 = json.loads(members["keypoints/00007.json"])["keypoints"]["5"]
        assert k5["flagged"] is True and k5["residual"] > 30 and k5["provenance"] == "detection"
        others = [k for kid, k in json.loads(members["keypoints/00007.json"])["keypoints"].items() if kid != "5"]
        assert all(not k["flagged"] and k["residual"] < 10 for k in others if k["visible"])
        coco = json.loads(members["coco_keypoints.json"])
        assert coco["annotations"][0]["keypoints"][3 * 4 + 2] == 0
        assert manifest["frames"]["00007"]["flagged"] == 1 and manifest["flagged"] == 1
        x, y = k5["x"] - 40.0, k5["y"] - 25.0
        st.move_keypoint("00007", 5, x, y)  # the annotator puts it where it belongs
        (members, manifest), _ = _export_both(st, data, edits, tmp_path)
        k5 = json.loads(members["keypoints/00007.json"])["keypoints"]["5"]
        assert k5["provenance"] == "hand" and not k5["flagged"] and manifest["frames"]["00007"]["flagged"] == 0


def test_accepting_a_frame_with_flagged_points_says_so_and_h_hides_them(images_only, tmp_path, serve):
    """G on a frame whose snapshot has a point beyond the gate: the panel names it, and H hides
    it on that frame (one undo step) although the tab has moved on, without recalibrating it or
    changing its review: still accepted, the same camera, the point gone from its labels and from
    the export; Ctrl+Z brings it back."""
    from pnlviz.pipeline.export import export_frame
    st, tab, said = _tab_on(images_only, tmp_path, serve, "00007")
    tab.editor.review("accepted", advance=True)
    assert "00007: 1 point flagged" in tab.panels.gate_text.content and "H" in tab.panels.gate_text.content
    assert said[0] == "1 flagged on 00007"
    before = st.edits.get("00007")["snapshot"]
    assert "5" in before["labels"]
    tab.editor.hide_flagged()
    record = st.edits.get("00007")
    assert record["keypoints"] == {"5": None} and st.edits.review("00007") == "accepted"
    assert record["snapshot"]["camera"] == before["camera"]  # not recalibrated
    assert set(record["snapshot"]["labels"]) == set(before["labels"]) - {"5"}
    assert tab.panels.gate_text.content == ""  # nothing flagged any more
    assert 5 not in st.view("00007", tab.settings).observations.kp_ids
    exported = export_frame(st.reader, "00007")  # what the export writes for it
    assert "5" not in json.loads(exported.files["keypoints/00007.json"])["keypoints"]
    assert exported.camera == before["camera"] and exported.entry["labels"] == "snapshot"
    assert st.undo("00007", tab.settings)
    assert st.edits.get("00007").get("keypoints") in (None, {}) and st.edits.review("00007") == "accepted"
    assert "5" in st.edits.get("00007")["snapshot"]["labels"]


# ---------------------------------------------------------------------- triage over the whole dataset
class CountingDetector(FakeDetector):
    """The fake detector, counting the frames it was asked about; frame 00004 gets nothing."""

    def __init__(self, preds: dict, empty: set):
        super().__init__(preds)
        self.calls, self.empty = 0, empty

    def detect(self, images):
        self.calls += len(images)
        return [Predictions_empty() if hashlib.sha1(np.ascontiguousarray(img).tobytes()).hexdigest() in self.empty
                else p for img, p in zip(images, super().detect(images))]


def Predictions_empty():
    from pnlviz.data import Predictions

    return Predictions()


def test_the_background_pass_sees_every_frame_and_resumes(images_only, tmp_path):
    """Opening an image-only folder: the pass detects and calibrates every frame, keeping
    summaries only; *failed* is then exactly the frames without a camera; a second opening
    resumes from the cache beside the edits (nothing detected or calibrated again)."""
    import threading

    from pnlviz.app.frameorder import visible_order
    from pnlviz.app.modes import Filter, Sort
    from pnlviz.app.state import AppState
    from pnlviz.data import open_dataset

    data, fake = images_only
    ds = open_dataset(data)
    empty = {hashlib.sha1(np.ascontiguousarray(ds.image("00004")).tobytes()).hexdigest()}
    detector = CountingDetector(fake.by_pixels, empty)
    edits = tmp_path / "edits"
    lines = []
    with AppState(data, edits=edits, detector=detector) as st:
        progress = st.triage.run(threading.Event(), lines.append)
        assert progress.finished and progress.done == 5 and detector.calls == 5
        assert st._cache == {}  # no view kept by the pass
        summaries = st.triage.summaries()
        assert set(summaries) == set(STEMS)
        failed = [st.stems[i] for i in visible_order(st.stems, summaries, st.edits.review, Filter.FAILED, Sort.INDEX)]
        no_camera = [s for s in st.stems if not st.view(s).result or not st.view(s).result.ok]
        assert failed == no_camera == ["00004"] and progress.failed == 1
        assert lines[-1].startswith("triage done: 5/5 frames, 4 with a camera, 1 without, 5 detected")
    assert (edits / "cache" / "summaries.jsonl").is_file() and (edits / "cache" / "detections.jsonl").is_file()
    with AppState(data, edits=edits, detector=detector) as st:
        calls = []
        st.triage.calibrate = lambda stem: calls.append(stem)
        progress = st.triage.run(threading.Event(), lines.append)
        assert progress.finished and progress.failed == 1 and detector.calls == 5 and calls == []
        assert st.reader.detections("00000") is not None  # read back from the cache


def test_detecting_a_frame_never_discards_its_calibration(tmp_path):
    """A frame calibrated from its annotation keeps its view when detections come; a frame
    whose detections change it keeps its summary until it is calibrated again."""
    from pnlviz.app.state import AppState, Settings

    data = tmp_path / "set"
    data.mkdir()
    for stem in ("00000", "00002"):
        for ext in ("jpg", "json"):
            shutil.copy(EXAMPLES_DIR / "sample" / f"{stem}.{ext}", data / f"{stem}.{ext}")
    from pnlviz.data import open_dataset

    ds = open_dataset(data)
    detector = FakeDetector({hashlib.sha1(np.ascontiguousarray(ds.image(s)).tobytes()).hexdigest(): _true_detections(s)
                             for s in ("00000", "00002")})
    with AppState(data, edits=tmp_path / "edits", detector=detector, source="annotation") as st:
        view = st.view("00000")
        both = st.view("00002", Settings(source="both"))
        st.view("00002")
        assert view.result.ok and both.result.ok
        st.run_detector("00000")
        st.run_detector("00002")
        assert st.cached_view("00000") is view  # the annotation's camera: unchanged, kept
        assert st.cached_view("00002", Settings(source="both")) is None  # the detections change it
        assert st.triage.lookup("00002") is not None and st.triage.lookup("00002").ok


def test_choosing_a_sort_goes_to_its_first_frame_and_the_title_shows_its_key(images_only, tmp_path, serve):
    import threading

    from pnlviz.app.frameorder import worst_residual

    data, fake = images_only
    app = serve(data, edits=tmp_path / "edits", detector=fake)
    st = app.state
    app._stop.set()
    app._worker.join()
    st.triage.run(threading.Event(), lambda text: None)
    tab = app.session()
    tab.goto(st.find("00000"))
    tab.panels.sort.value = "residual (worst first)"
    tab.flush()
    key = {s: worst_residual(st.triage.lookup(s)) for s in st.stems}
    worst = max(st.stems, key=key.get)
    assert tab.stem == worst == st.stems[tab.frames.order[0]] and tab.stem != "00000"
    expected = "no camera" if key[worst] == 1e9 else f"worst residual {key[worst]:,.1f} px"
    assert f"sorted by **{expected.replace('no camera', 'residual (worst first): no camera')}**" in \
        tab.panels.title.content
    tab.step(1)
    tab.panels.sort.value = "index"
    tab.flush()
    assert "sorted by" not in tab.panels.title.content


def test_the_summary_file_survives_a_torn_line_and_is_compacted(tmp_path):
    """A crash mid-line loses that line only; a file of mostly superseded lines is rewritten
    with the latest summary of each frame when it is opened."""
    from pnlviz.app.triage import FrameSummary, SummaryStore

    path = tmp_path / "summaries.jsonl"
    store = SummaryStore(path)
    for i in range(150):
        store.put(FrameSummary("a", True, None, float(i), 1.0, 0.5, "t"))
    store.put(FrameSummary("b", False, "no camera", 0.0, 0.0, None, "t"))
    with open(path, "ab") as f:
        f.write(b'{"stem": "c", "ok": tr')  # torn
    again = SummaryStore(path)
    assert again.get("a").worst == 149.0 and not again.get("b").ok and again.get("c") is None
    assert len(path.read_text().splitlines()) == 2  # compacted
    again.put(FrameSummary("c", True, None, 3.0, 1.0, None, "t"))
    assert SummaryStore(path).get("c").worst == 3.0


def test_a_hand_slip_is_kept_but_said_at_once_listed_when_accepted_and_in_the_manifest(images_only, tmp_path, serve):
    """A keypoint dragged 44 px off where the frame's other points put it: the hand rules (it stays
    there, exported at the hand's position), but the panel says "possible slip" on release,
    accepting the frame lists it, and the export carries it (manifest "slips", "slip": true). The
    same point put back where it belongs is no slip."""
    from pnlviz.app.modes import PointKind, Selection
    from pnlviz.pipeline.export import export_frame

    st, tab, said = _tab_on(images_only, tmp_path, serve, "00000")
    view = st.view("00000", tab.settings)
    obs = view.observations
    kid = int(obs.kp_ids[len(obs.kp_ids) // 2])
    true_xy = obs.kp_xy[len(obs.kp_ids) // 2]
    tab.editor.release("00000", Selection(PointKind.KEYPOINTS, kid), true_xy + [44.0, 0.0], snap_to_pitch=False)
    tab.queue.flush()  # said right after the frame is drawn
    assert said == []  # in the panel, not in a notice over the image
    assert f"point {kid} is 4" in tab.panels.gate_text.content and "a slip?" in tab.panels.gate_text.content
    assert st.edits.get("00000")["keypoints"][str(kid)] == pytest.approx(list(true_xy + [44.0, 0.0]))  # kept
    tab.editor.review("accepted", advance=False)
    assert said[-1] == "1 possible slip on 00000"
    slips = st.edits.get("00000")["snapshot"]["slips"]
    assert list(slips) == [str(kid)] and 40 < slips[str(kid)] < 48
    exported = export_frame(st.reader, "00000")
    label = json.loads(exported.files["keypoints/00000.json"])["keypoints"][str(kid)]
    assert label["slip"] is True and label["provenance"] == "hand" and not label["flagged"]
    assert (label["x"], label["y"]) == pytest.approx(tuple(true_xy + [44.0, 0.0]))
    assert exported.entry["slips"] == slips
    tab.editor.release("00000", Selection(PointKind.KEYPOINTS, kid), true_xy, snap_to_pitch=False)
    tab.queue.flush()
    assert "slip" not in st.edits.get("00000")["snapshot"] and "a slip?" not in tab.panels.gate_text.content


def test_accepting_a_frame_the_label_error_finder_flags_asks_once(tmp_path, serve):
    """A frame whose right touchline is annotated as the left one: G does not accept it but says
    what the label-error finder found (and that F fixes it); G again accepts it as it is. A frame
    the finder does not flag is accepted at the first G."""
    data = tmp_path / "frames"
    data.mkdir()
    for stem in ("sn22_00004", "sn22_00097"):
        shutil.copy(EXAMPLES_DIR / "sample" / f"{stem}.json", data / f"{stem}.json")
    ann = json.loads((data / "sn22_00004.json").read_text())
    ann["Side line left"] = ann.pop("Side line right")
    (data / "sn22_00004.json").write_text(json.dumps(ann))
    app = serve(data, edits=tmp_path / "edits")
    st = app.state
    tab = app.session()
    said = []
    tab.notify = lambda title, body, error=True: said.append((title, body))
    tab.goto(st.find("sn22_00004"))
    tab.editor.review("accepted", advance=False)
    assert st.edits.review("sn22_00004") is None
    assert said[-1][0] == "sn22_00004: accept anyway?" and "Side line left" in said[-1][1] and "F applies" in said[-1][1]
    assert "**G** again accepts it" in tab.panels.gate_text.content
    tab.editor.review("accepted", advance=False)
    assert st.edits.review("sn22_00004") == "accepted"
    tab.goto(st.find("sn22_00097"))
    tab.editor.review("accepted", advance=False)
    assert st.edits.review("sn22_00097") == "accepted"


def test_visible_occluded_absent_cycle_on_o_and_a_note_reach_the_export(images_only, tmp_path, serve):
    """O on a selected keypoint: occluded (drawn "(id)", the list says so; exported with its
    position, "visible": false, COCO v=1), then absent (not exported), then visible again, each one
    undo step. A note typed on the frame is saved at once, keeps the review status, and is in the
    manifest; the camera never moves for a visibility (occlusion is a label, not an observation)."""
    from pnlviz.app.modes import PointKind, Selection
    from pnlviz.pipeline.export import export_frame

    st, tab, said = _tab_on(images_only, tmp_path, serve, "00000")
    tab.editor.review("accepted", advance=False)
    camera = st.edits.get("00000")["snapshot"]["camera"]
    kid = int(st.view("00000", tab.settings).observations.kp_ids[0])

    def exported():
        part = export_frame(st.reader, "00000")
        return json.loads(part.files["keypoints/00000.json"])["keypoints"], part

    tab.editor.select(Selection(PointKind.KEYPOINTS, kid))
    tab.editor.cycle_visibility()
    assert said[-1] == f"point {kid} occluded" and st.edits.get("00000")["occluded"] == [kid]
    tab.show()
    assert f"({kid})" in tab.painter.overlay.keypoints.labels
    assert f"{kid} · occluded" in " ".join(tab.panels.points.options)
    kps, part = exported()
    assert kps[str(kid)]["occluded"] is True and kps[str(kid)]["visible"] is False
    coco = part.coco_annotation["keypoints"]
    assert coco[3 * (kid - 1) + 2] == 1 and part.entry["occluded"] == [kid]
    assert st.edits.get("00000")["snapshot"]["camera"] == camera  # not recalibrated
    tab.editor.select(Selection(PointKind.KEYPOINTS, kid))
    tab.editor.cycle_visibility()
    assert said[-1] == f"point {kid} absent" and str(kid) not in exported()[0]
    assert "occluded" not in st.edits.get("00000")
    tab.editor.select(Selection(PointKind.KEYPOINTS, kid))  # selectable as a ghost's id: chosen from the list
    tab.editor.cycle_visibility()
    assert said[-1] == f"point {kid} visible" and exported()[0][str(kid)]["visible"] is True
    tab.editor.set_note("goal post hidden by the keeper; check 00001 too")
    record = st.edits.get("00000")
    assert record["note"] == "goal post hidden by the keeper; check 00001 too" and record["review"] == "corrected"
    assert exported()[1].entry["note"] == record["note"]
    steps = st.edits.history("00000")[0]
    tab.editor.set_note("goal post hidden by the keeper; check 00001 too!")  # typing on: the same undo step
    assert st.edits.history("00000")[0] == steps
    tab.editor.undo()
    assert st.edits.get("00000").get("note") is None


def test_a_bulk_action_is_counted_first_runs_on_the_filtered_frames_and_undoes_as_one_step(images_only, tmp_path,
                                                                                        serve):
    """Keypoint K detected on several frames: "absent" over the filtered frames first says how many
    frames it would change, the second apply changes exactly those (nothing else), and one Ctrl+Z
    takes all of it back. A rename moves the point to the other id where it is."""
    from pnlviz.app.modes import PointKind, Selection

    data, detector = images_only
    app = serve(data, edits=tmp_path / "edits", detector=detector)
    st = app.state
    for stem in st.stems:
        st.run_detector(stem)
    tab = app.session()
    tab.goto(0)
    shown = {s: {int(k) for k in st.view(s, tab.settings).observations.kp_ids} for s in st.stems}
    kid = max(set.union(*shown.values()), key=lambda k: sum(k in ids for ids in shown.values()))
    having = [s for s in st.stems if kid in shown[s]]
    assert 1 < len(having)
    tab.editor.select(Selection(PointKind.KEYPOINTS, kid))
    before = {s: st.edits.get(s) for s in st.stems}
    tab.editor.bulk("absent", "filtered frames")
    assert tab.panels.bulk_text.content.startswith(f"**make keypoint {kid} absent on {len(having)} of {len(st.stems)}")
    assert {s: st.edits.get(s) for s in st.stems} == before  # counted, nothing changed yet
    tab.editor.bulk("absent", "filtered frames")
    for s in st.stems:
        kps = st.edits.get(s).get("keypoints") or {}
        assert (kps.get(str(kid), 0) is None) == (s in having), s
        assert kid not in {int(k) for k in st.view(s, tab.settings).observations.kp_ids}
    tab.editor.undo()  # one step: every frame back
    assert all(not (st.edits.get(s).get("keypoints") or {}) for s in st.stems)
    # a rename on this frame: the point moves to the other id
    stem = having[0]
    tab.goto(st.find(stem))
    to = next(k for k in range(1, 74) if k not in shown[stem])
    xy = st.view(stem, tab.settings).observations.kp_xy[list(st.view(stem, tab.settings).observations.kp_ids).index(kid)]
    tab.editor.select(Selection(PointKind.KEYPOINTS, kid))
    tab.editor.bulk("rename", "this frame", to)
    tab.editor.bulk("rename", "this frame", to)
    kps = st.edits.get(stem)["keypoints"]
    assert kps[str(kid)] is None and kps[str(to)] == pytest.approx(list(xy))
