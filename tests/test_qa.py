"""The label-error finder (pnlviz.calib.qa) on synthetic frames with an exact camera: each kind
of error injected alone is found, named, and its suggested fix brings the frame's score back."""

import re

import numpy as np
import pytest

from pnlviz.calib.qa import FrameQA, apply_fix, check_frame, frame_score
from pnlviz.field import load_field_model
from pnlviz.synth import annotate, sample_camera

SCALE = np.array([959.0, 539.0])


def synthetic(seed: int):
    rng = np.random.default_rng(seed)
    cam, _ = sample_camera(rng, 960, 540)
    return cam, annotate(cam, rng)


@pytest.fixture(scope="module")
def left():
    """A main-camera view of the left penalty area, goal and all (12 classes)."""
    return synthetic(7)


def only(qa: FrameQA, kind: str):
    found = [f for f in qa.findings if f.kind == kind]
    assert found, f"no {kind} in {[(f.kind, f.cls, f.message) for f in qa.findings]}"
    return found[0]


def restored(ann, finding):
    fixed = check_frame(apply_fix(ann, finding.fix))
    assert fixed.score < 1.0, [(f.kind, f.cls, f.message) for f in fixed.findings]
    return fixed


def test_a_clean_frame_has_no_finding_and_scores_below_one(left):
    _, ann = left
    qa = check_frame(ann)
    assert qa.findings == [] and qa.score < 1.0
    assert qa.camera is not None
    line = qa.to_json("x")
    assert line["stem"] == "x" and line["findings"] == [] and line["score"] == pytest.approx(qa.score, abs=1e-4)


def test_a_class_named_from_the_other_side_is_renamed(left):
    _, ann = left
    bad = dict(ann)
    bad["Small rect. right main"] = bad.pop("Small rect. left main")
    qa = check_frame(bad)
    f = only(qa, "wrong_class")
    assert f.cls == "Small rect. right main" and "other side" in f.message
    assert f.fix == {"op": "rename", "class": "Small rect. right main", "to": "Small rect. left main"}
    assert qa.score >= 3.0
    restored(bad, f)


def test_a_neighbouring_marking_s_name_is_found():
    _, ann = synthetic(2)  # Big rect. left main and top, Circle left, two side lines
    bad = dict(ann)
    bad["Small rect. left top"] = bad.pop("Big rect. left top")
    qa = check_frame(bad)
    f = only(qa, "wrong_class")
    assert f.cls == "Small rect. left top" and f.fix["to"] == "Big rect. left top"
    assert "neighbouring" in f.message and f.evidence["left_out"] is True
    restored(bad, f)


def test_a_line_clicked_off_its_paint_is_found_and_moved_onto_it(left):
    _, ann = left
    bad = dict(ann)
    bad["Big rect. left main"] = ann["Big rect. left main"] + np.array([0.0, 25.0]) / SCALE
    qa = check_frame(bad)
    f = only(qa, "off_projection")
    assert f.cls == "Big rect. left main" and f.evidence["median_px"] > 15
    assert f.evidence["others_px"] < 8  # the camera without it fits the others
    assert f.fix["op"] == "move_points" and len(f.fix["points"]) == len(bad["Big rect. left main"])
    # the camera that judged it was not pulled by it: the points go back within a few px of the truth
    moved = np.asarray(f.fix["points"]) * SCALE
    assert np.max(np.abs(moved[:, 1] - ann["Big rect. left main"][:, 1] * SCALE[1])) < 6
    restored(bad, f)


def test_points_of_two_markings_in_one_class_are_split(left):
    _, ann = left
    bad = dict(ann)
    stray = ann["Small rect. left main"][:2]  # two clicks of another marking appended
    bad["Big rect. left main"] = np.vstack([ann["Big rect. left main"], stray])
    qa = check_frame(bad)
    f = only(qa, "split_class")
    n = len(ann["Big rect. left main"])
    assert f.cls == "Big rect. left main"
    assert f.fix == {"op": "drop_points", "class": "Big rect. left main", "points": [n, n + 1]}
    restored(bad, f)


def test_a_marking_left_out_is_found_where_the_camera_puts_it(left):
    cam, ann = left
    bad = {k: v for k, v in ann.items() if k != "Big rect. left bottom"}
    qa = check_frame(bad)
    f = only(qa, "missing_class")
    assert f.cls == "Big rect. left bottom" and f.fix["op"] == "add_class"
    # the suggested points are on the marking
    from pnlviz.geometry.distance import closest_on_polyline

    truth = cam.project(load_field_model().sample_polylines(0.5)["Big rect. left bottom"])
    d = closest_on_polyline(np.asarray(f.fix["points"]) * SCALE, truth[np.isfinite(truth).all(axis=1)]).distance
    assert np.max(d) < 3
    restored(bad, f)


def test_each_finding_is_drawn_where_the_annotation_put_it_and_where_the_camera_expects_it(left):
    from pnlviz.app.overlay import finding_segments
    from pnlviz.calib.qa import finding_marks
    from pnlviz.geometry.distance import closest_on_polyline

    cam, ann = left
    model = load_field_model()

    def truth(cls):
        uv = cam.project(model.sample_polylines(0.5, 0.25)[cls])
        return uv[np.isfinite(uv).all(axis=1)]

    cls = "Big rect. left top"
    bad = {**ann, cls: ann[cls] + np.array([0.0, 25.0]) / SCALE}  # off its paint
    bad["Big rect. left main"] = np.vstack([ann["Big rect. left main"], ann["Small rect. left main"]])  # + strays
    del bad["Big rect. left bottom"]  # left out
    qa = check_frame(bad)
    marks = {m.finding.kind: m for m in finding_marks(qa, bad, (960, 540), model)}
    assert set(marks) == {"off_projection", "split_class", "missing_class"}, [f.message for f in qa.findings]
    off = marks["off_projection"]
    np.testing.assert_allclose(off.annotated, bad[cls] * SCALE)  # as annotated: 25 px below the paint
    expected = np.vstack(off.expected)  # where the camera expects it: on the paint
    assert np.max(closest_on_polyline(expected, truth(cls)).distance) < 3
    assert np.min(closest_on_polyline(off.annotated, expected).distance) > 15
    np.testing.assert_allclose(off.points, np.asarray(off.finding.fix["points"]) * SCALE)  # where the fix moves them
    split = marks["split_class"]  # the fix's points: the two strays it drops
    np.testing.assert_allclose(split.points, ann["Small rect. left main"] * SCALE)
    gone = marks["missing_class"]  # nothing annotated; the camera puts it on the paint
    assert len(gone.annotated) == 0 and gone.expected
    assert np.max(closest_on_polyline(np.vstack(gone.expected), truth("Big rect. left bottom")).distance) < 3
    # the app draws the same marks as two layers; a clean frame has none
    seg = finding_segments(list(marks.values()))
    assert len(seg["finding_annotated"]) >= len(bad[cls]) - 1 and len(seg["finding_expected"]) > 0
    assert finding_marks(check_frame(ann), ann, (960, 540), model) == []


def _detections(cam, ids):
    from pnlviz.data import Predictions

    xyz = load_field_model().keypoint_xyz(ids, pnlcalib=True)
    uv = cam.project(xyz)
    return Predictions(keypoints={int(i): (float(u / 960), float(v / 540), 0.9) for i, (u, v) in zip(ids, uv)})


def test_detections_that_disagree_with_the_annotation_are_found(left):
    cam, ann = left
    qa0 = check_frame(ann)
    ids = [int(i) for i in (1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16) if i in _annotated_ids(ann)]
    assert len(ids) >= 4
    agree = check_frame(ann, detections=_detections(cam, ids))
    assert [f for f in agree.findings if f.kind == "detection_disagreement"] == []
    det = _detections(cam, ids)
    x, y, p = det.keypoints[ids[0]]
    det.keypoints[ids[0]] = (x + 40 / 960, y, p)
    qa = check_frame(ann, detections=det)
    f = only(qa, "detection_disagreement")
    assert f.keypoint == ids[0] and f.evidence["distance_px"] > 30
    assert f.evidence["annotation_to_camera_px"] < f.evidence["detection_to_camera_px"]
    assert "backs the annotation" in f.message and qa.score > qa0.score + 1


def _annotated_ids(ann):
    from pnlviz.calib.inputs import observations_from_annotation

    return set(observations_from_annotation(ann, 960, 540)[0].kp_ids.tolist())


def test_a_frame_without_a_camera_says_so():
    qa = check_frame({"Middle line": np.array([[0.5, 0.1], [0.5, 0.9]])})
    assert qa.kinds == ["no_camera"] and qa.camera is None and qa.score == 1.0


def test_the_score_is_the_worst_finding_plus_a_quarter_of_the_others():
    from pnlviz.calib.qa import Finding

    fs = [Finding("off_projection", "", 2.0), Finding("missing_class", "", 4.0)]
    assert frame_score(fs) == pytest.approx(4.5)
    assert frame_score([], 0.4) == pytest.approx(0.4) and frame_score([], 3.0) == pytest.approx(0.99)


def test_fixes_are_applied_as_data_without_touching_the_input():
    ann = {"A": np.array([[0.1, 0.1], [0.2, 0.2], [0.3, 0.3]]), "B": np.array([[0.5, 0.5], [0.6, 0.6]])}
    out = apply_fix(ann, {"op": "rename", "class": "A", "to": "B"})
    assert sorted(out) == ["B"] and len(out["B"]) == 5 and len(ann["A"]) == 3
    out = apply_fix(ann, {"op": "drop_points", "class": "A", "points": [0, 2]})
    assert out["A"].tolist() == [[0.2, 0.2]]
    assert "B" not in apply_fix(ann, {"op": "drop_points", "class": "B", "points": [0, 1]})
    with pytest.raises(ValueError, match="no class"):
        apply_fix(ann, {"op": "rename", "class": "C", "to": "A"})
    with pytest.raises(ValueError, match="points for the"):
        apply_fix(ann, {"op": "move_points", "class": "A", "points": [[0, 0]]})


# ----------------------------------------------------------------------------- the command and the API
def _dataset(folder, frames):
    import json

    from pnlviz.synth import annotation_to_json

    folder.mkdir()
    for stem, ann in frames.items():
        (folder / f"{stem}.json").write_text(json.dumps(annotation_to_json(ann)))
    return folder


def test_pnlviz_qa_writes_one_line_per_frame_most_suspect_first_then_a_summary(tmp_path, left, capsys):
    import json

    from pnlviz.cli import main

    _, ann = left
    bad = dict(ann)
    bad["Small rect. right main"] = bad.pop("Small rect. left main")
    data = _dataset(tmp_path / "d", {"00001": ann, "00002": bad, "00003": synthetic(2)[1]})
    out = tmp_path / "qa.jsonl"
    assert main(["qa", "--data", str(data), "--out", str(out), "--no-progress"]) == 0
    lines = [json.loads(t) for t in out.read_text().splitlines()]
    assert [line.get("stem") for line in lines][:1] == ["00002"] and len(lines) == 4
    assert lines[0]["findings"][0]["kind"] == "wrong_class" and lines[0]["findings"][0]["fix"]["to"] == \
        "Small rect. left main"
    scores = [line["score"] for line in lines[:3]]
    assert scores == sorted(scores, reverse=True)
    assert lines[-1]["summary"]["judged"] == 3 and lines[-1]["summary"]["flagged"] == 1
    assert "00002" in capsys.readouterr().out
    # resumed: nothing judged again, the same lines
    assert main(["qa", "--data", str(data), "--out", str(out), "--no-progress", "--resume"]) == 0
    assert "resuming: 3 of 3" in capsys.readouterr().out
    again = [json.loads(t) for t in out.read_text().splitlines()]
    assert [line.get("stem") for line in again[:3]] == [line["stem"] for line in lines[:3]]


def test_the_python_api_judges_a_dataset_or_one_frame(tmp_path, left):
    import pnlviz

    _, ann = left
    bad = {k: v for k, v in ann.items() if k != "Big rect. left bottom"}
    data = _dataset(tmp_path / "d", {"a": ann, "b": bad})
    ranked = pnlviz.qa(data)
    assert [r["stem"] for r in ranked] == ["b", "a"]
    assert ranked[0]["findings"][0]["class"] == "Big rect. left bottom"
    one = pnlviz.qa({k: v * SCALE for k, v in bad.items()}, image_size=(960, 540))
    assert one["findings"][0]["kind"] == "missing_class" and one["score"] == ranked[0]["score"]
    with pytest.raises(pnlviz.ArgumentError, match="lines"):
        pnlviz.qa({"Nope": [[0, 0], [1, 1]]}, image_size=(960, 540))


# ----------------------------------------------------------------------------- the app's suspects
def test_the_app_filters_and_sorts_frames_by_the_same_scores(left):
    from types import SimpleNamespace

    from pnlviz.app.frameorder import sort_key_text, visible_order
    from pnlviz.app.modes import Filter, Sort
    from pnlviz.app.triage import FrameSummary, suspect_score
    from pnlviz.calib.frame import FrameInputs, calibrate_frame

    _, ann = left
    bad = dict(ann)
    bad["Small rect. right main"] = bad.pop("Small rect. left main")
    scores = {}
    for stem, a in (("clean", ann), ("bad", bad)):
        fc = calibrate_frame(FrameInputs((960, 540), a))  # the app's view of the frame: its calibration
        view = SimpleNamespace(annotation=a, origin="annotation", result=fc.result, observations=fc.observations,
                               size=(960, 540), detections=None)
        scores[stem] = suspect_score(view)
    assert scores["clean"][0] < 1 and scores["clean"][1] is None
    assert scores["bad"][0] == pytest.approx(check_frame(bad).score) and "Small rect. right main" in scores["bad"][1]
    assert suspect_score(SimpleNamespace(annotation=None, origin="detections", result=None)) == (None, None)

    def summary(stem, suspect, note=None):
        return FrameSummary(stem, True, None, 1.0, 1.0, 0.9, "", suspect, note)

    stems = ["a", "b", "c", "d"]
    summaries = {"a": summary("a", scores["clean"][0]), "b": summary("b", scores["bad"][0], scores["bad"][1]),
                 "c": summary("c", None)}  # c: not judged (another source); d: not calibrated yet
    order = visible_order(stems, summaries, lambda s: None, Filter.SUSPECTS, Sort.INDEX)
    assert [stems[i] for i in order] == ["b"]
    order = visible_order(stems, summaries, lambda s: None, Filter.ALL, Sort.SUSPECT)
    assert [stems[i] for i in order] == ["b", "a", "c", "d"]
    assert sort_key_text(Sort.SUSPECT, summaries["b"]) == f"suspect score {scores['bad'][0]:.2f}: {scores['bad'][1]}"
    assert "not judged" in sort_key_text(Sort.SUSPECT, summaries["c"])


def test_the_app_applies_a_suggested_fix_as_an_undoable_edit(tmp_path, left):
    from pnlviz.app.state import AppState
    from pnlviz.app.triage import fix_frame

    _, ann = left
    bad = dict(ann)
    bad["Small rect. right main"] = bad.pop("Small rect. left main")
    data = _dataset(tmp_path / "d", {"00001": bad, "00002": ann})
    st = AppState(data, edits=tmp_path / "d.edits", source="annotation")
    try:
        assert fix_frame(st, "00002") is None  # a clean frame: nothing to fix, nothing written
        assert st.edits.history("00002") == (0, 0)
        finding = fix_frame(st, "00001")
        assert finding.kind == "wrong_class" and finding.fix["to"] == "Small rect. left main"
        fixed = st.view("00001").annotation
        assert "Small rect. left main" in fixed and "Small rect. right main" not in fixed
        assert st.edits.review("00001") == "corrected" and st.edits.history("00001")[0] == 1
        assert st.undo("00001")
        assert "Small rect. right main" in st.view("00001").annotation
    finally:
        st.close()


def test_a_frame_the_app_could_not_calibrate_is_a_suspect_without_a_camera():
    from types import SimpleNamespace

    from pnlviz.app.triage import suspect_score
    from pnlviz.calib.frame import FrameInputs, calibrate_frame

    ann = {"Middle line": np.array([[0.5, 0.1], [0.5, 0.9]]), "Side line top": np.array([[0.1, 0.1], [0.9, 0.1]])}
    fc = calibrate_frame(FrameInputs((960, 540), ann))
    assert not fc.ok and fc.result is not None
    view = SimpleNamespace(annotation=ann, origin="annotation", result=fc.result, observations=fc.observations,
                           size=(960, 540), detections=None)
    score, note = suspect_score(view)
    assert score == 1.0 and note.startswith("the annotation gives no camera")


def test_the_apps_suspects_are_pnlviz_qas_findings_on_the_same_folder(tmp_path):
    """One judge: the background pass's suspect score and worst finding of every frame are what
    `pnlviz qa` writes for the same folder, frames that no longer calibrate included (a class
    renamed across the pitch breaks frame 00003's calibration: qa finds the class by leaving each
    out, and so does the app, instead of "no camera")."""
    import json
    import threading

    from pnlviz.app.state import AppState
    from pnlviz.calib.frame import FrameInputs, calibrate_frame
    from pnlviz.commands import main

    _, clean = synthetic(7)
    wrong = dict(clean)
    wrong["Small rect. right main"] = wrong.pop("Small rect. left main")
    _, other = synthetic(26)  # six classes: renamed, one leaves too few for a camera, from lines or priors
    broken = dict(other)
    broken["Big rect. left main"] = broken.pop("Big rect. right main")
    _, sparse = synthetic(2)
    sparse = dict(sparse)
    sparse["Side line bottom"] = sparse.pop("Side line top")
    frames = {"00001": clean, "00002": wrong, "00003": broken, "00004": sparse}
    assert not calibrate_frame(FrameInputs((960, 540), broken)).ok  # the frame no longer calibrates
    data = _dataset(tmp_path / "d", frames)
    out = tmp_path / "qa.jsonl"
    assert main(["qa", "--data", str(data), "--out", str(out), "--no-progress"]) == 0
    lines = [json.loads(line) for line in out.read_text().splitlines()]
    qa = {line["stem"]: line for line in lines if "stem" in line}
    st = AppState(data, edits=tmp_path / "d.edits", source="annotation")
    try:
        st.triage.run(threading.Event(), lambda text: None)
        summaries = st.triage.summaries()
        app = {stem: (s.suspect, s.suspect_note) for stem, s in summaries.items()}
    finally:
        st.close()
    assert set(app) == set(qa) == set(frames)
    for stem, line in qa.items():
        worst = line["findings"][0]["message"] if line["findings"] else None
        assert app[stem] == (pytest.approx(line["score"], abs=1e-3), worst), stem
    assert qa["00003"]["score"] >= 10 and qa["00003"]["findings"][0]["kind"] == "wrong_class"
    assert [s for s, _ in sorted(app.items(), key=lambda kv: -kv[1][0])][:2] == \
        [line["stem"] for line in lines if "stem" in line][:2]  # the same order, most suspect first


def test_a_detected_line_off_the_annotated_one_is_found_with_its_distance(left):
    """The line check: a detected line whose extremities sit 30 px across the annotated line is a
    disagreement of that class, its distance the farthest point's; on the line, nothing."""
    from pnlviz.data import Predictions
    from pnlviz.field.names import CLASS_TO_LINE_ID

    cam, ann = left
    name = "Big rect. left main"
    assert name in ann
    pts = np.asarray(ann[name], float) * [959, 539]
    a, b = pts[0], pts[-1]
    normal = np.array([-(b - a)[1], (b - a)[0]]) / np.hypot(*(b - a))

    def with_line(shift):
        p, q = (a + shift * normal) / [959, 539], (b + shift * normal) / [959, 539]
        return Predictions(keypoints={}, lines={CLASS_TO_LINE_ID[name]: (p[0], p[1], 0.9, q[0], q[1], 0.9)})

    on = check_frame(ann, detections=with_line(0.0))
    assert [f for f in on.findings if f.kind == "detection_disagreement"] == []
    off = check_frame(ann, detections=with_line(30.0))
    f = only(off, "detection_disagreement")
    assert f.cls == name and 25 < f.evidence["distance_px"] < 35
    said = re.search(r"its detected points lie up to (\d+) px from the annotated line", f.message)
    assert said and abs(int(said.group(1)) - f.evidence["distance_px"]) <= 1
