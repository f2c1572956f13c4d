"""The frames' one path for every caller (pnlviz.pipeline): `pnlviz calibrate` reads a frame as the
app does (its --source and --edits included), export runs without the app, and the batch runner's
worker-side state and Ctrl+C."""

import json
import shutil
import zipfile

import numpy as np
import pytest

from pnlviz import EXAMPLES_DIR
from pnlviz.cli import main

STEMS = ("3", "4", "6", "8", "9", "10")


@pytest.fixture()
def wc14(tmp_path, shared_dir):
    """Six WC14 annotations (no images) with the published network's detections of the same frames,
    and an edits folder that moves a keypoint of one frame and hides one of another."""
    from pnlviz.app.state import AppState

    half = shared_dir / "data" / "wc14_test_half"
    data = tmp_path / "set"
    data.mkdir()
    with zipfile.ZipFile(half / "annotations.zip") as z:
        for stem in STEMS:
            (data / f"{stem}.json").write_bytes(z.read(f"{stem}.json"))
    preds = tmp_path / "preds.zip"
    with zipfile.ZipFile(half / "detections_pnlcalib.zip") as z, zipfile.ZipFile(preds, "w") as out:
        for stem in STEMS:
            out.writestr(f"{stem}.json", z.read(f"{stem}.json"))
    edits = tmp_path / "edits"
    with AppState(data, detections=preds, edits=edits) as st:
        obs = st.view("4").observations
        kid, (x, y) = int(obs.kp_ids[0]), obs.kp_xy[0]
        st.move_keypoint("4", kid, x + 6.0, y - 4.0)
        st.hide_keypoint("8", int(st.view("8").observations.kp_ids[1]))
    return data, preds, edits


def _cameras(path) -> dict:
    with zipfile.ZipFile(path) as z:
        return {n[len("camera_"):-len(".json")]: json.loads(z.read(n)) for n in z.namelist()}


def _calibrate(tmp_path, data, preds, name, *extra) -> tuple[dict, list[dict]]:
    out, report = tmp_path / f"{name}.zip", tmp_path / f"{name}.jsonl"
    assert main(["calibrate", "--data", str(data), "--detections", str(preds), "--out", str(out), "--report",
                 str(report), "--no-progress", *extra]) == 0
    return _cameras(out), [json.loads(line) for line in report.read_text().splitlines()]


def test_the_command_calibrates_a_frame_as_the_app_does_for_every_source(wc14, tmp_path):
    from pnlviz.app.state import AppState, Settings

    data, preds, edits = wc14
    with AppState(data, detections=preds, edits=edits, writable=False) as st:
        for source in ("annotation", "detections", "both"):
            cams, reports = _calibrate(tmp_path, data, preds, source, "--source", source, "--edits", str(edits))
            assert {r["origin"] for r in reports} == {source}
            app = {s: st.view(s, Settings(source=source)) for s in STEMS}
            assert set(cams) == {s for s, v in app.items() if v.result is not None and v.result.ok} and len(cams) >= 5
            for stem, cam in cams.items():
                assert cam == app[stem].result.camera.scaled(960, 540).to_soccernet(), (source, stem)


def test_both_sources_differ_from_detections_and_edits_apply_only_when_given(wc14, tmp_path):
    data, preds, edits = wc14
    default, _ = _calibrate(tmp_path, data, preds, "default")
    det, det_reports = _calibrate(tmp_path, data, preds, "det", "--source", "detections")
    both, both_reports = _calibrate(tmp_path, data, preds, "both", "--source", "both")
    assert default == det  # the detections are the source unless told
    more = [a["keypoints"] - b["keypoints"] for a, b in zip(both_reports, det_reports)]
    assert all(n >= 0 for n in more) and sum(n > 0 for n in more) >= 3  # the annotation adds observations
    changed = [s for s in det if s in both and not np.allclose(det[s]["position_meters"], both[s]["position_meters"])]
    assert len(changed) >= 3
    edited, reports = _calibrate(tmp_path, data, preds, "edited", "--source", "detections", "--edits", str(edits))
    assert edited["4"] != det["4"] and edited["8"] != det["8"]  # the moved and the hidden keypoint
    assert all(edited[s] == det[s] for s in det if s not in ("4", "8"))
    by_stem = {r["stem"]: r for r in reports}
    assert by_stem["8"]["keypoints"] == next(r for r in det_reports if r["stem"] == "8")["keypoints"] - 1


def test_calibrate_refuses_a_source_it_cannot_use(wc14, tmp_path, capsys):
    data, _, edits = wc14
    out = tmp_path / "c.zip"
    assert main(["calibrate", "--data", str(data), "--source", "detections", "--out", str(out)]) == 2
    assert "--source detections needs --detections" in capsys.readouterr().err
    assert main(["calibrate", "--data", str(data), "--edits", str(tmp_path / "nope"), "--out", str(out)]) == 2
    assert "nope: does not exist" in capsys.readouterr().err
    assert main(["calibrate", "--data", str(data), "--edits", str(edits), "--out", str(edits / "c.zip")]) == 2


def test_export_needs_no_app_and_the_button_writes_what_the_command_writes(tmp_path):
    """A FrameReader alone exports what the app's button downloads and `pnlviz export` writes,
    edits included, member for member (the manifest's date aside)."""
    from pnlviz.app.export import export_zip_bytes
    from pnlviz.app.state import AppState
    from pnlviz.pipeline import FrameReader
    from pnlviz.pipeline.export import read_export_zip, write_export

    data = tmp_path / "set"
    data.mkdir()
    for stem in ("00000", "00001", "00002", "00003"):
        for ext in ("jpg", "json"):
            shutil.copy(EXAMPLES_DIR / "sample" / f"{stem}.{ext}", data / f"{stem}.{ext}")
    edits = tmp_path / "edits"
    with AppState(data, edits=edits) as st:
        for stem in ("00000", "00001", "00003"):
            st.set_review(stem, "accepted")
        kid = int(st.view("00001").observations.kp_ids[0])
        st.move_keypoint("00001", kid, 300.0, 200.0)
        name = next(iter(st.reader.annotation("00003")))
        st.move_line_point("00003", name, 0, 120.0, 80.0)
        (tmp_path / "button.zip").write_bytes(export_zip_bytes(st))
    assert main(["export", "--data", str(data), "--edits", str(edits), "--out", str(tmp_path / "cli.zip"),
                 "--no-progress"]) == 0
    with FrameReader.open(data, edits=edits) as reader:
        frames = write_export(reader, tmp_path / "engine.zip")
    assert set(frames) == {"00000", "00001", "00002", "00003"} - {"00002"}
    button = read_export_zip(tmp_path / "button.zip")
    assert button == read_export_zip(tmp_path / "cli.zip") == read_export_zip(tmp_path / "engine.zip")
    members, manifest = button
    kps = json.loads(members["keypoints/00001.json"])["keypoints"][str(kid)]
    assert (kps["x"], kps["y"]) == (300.0, 200.0) and manifest["frames"]["00003"]["annotation_edited"]


def test_worker_state_is_built_once_per_key_and_the_old_one_closed():
    from dataclasses import dataclass

    from pnlviz.commands.batch import BatchJob, run_chunk

    built, closed = [], []

    class State:
        def __init__(self, name):
            self.name = name
            built.append(name)

        def close(self):
            closed.append(self.name)

    @dataclass
    class Job(BatchJob):
        weights: str

        def state_key(self):
            return self.run, self.weights

        def open_state(self):
            return State(self.weights)

        def run_chunk(self, state, items):
            return [(state.name, item) for item in items]

    job = Job("a")
    assert run_chunk(job, [1, 2]) == [("a", 1), ("a", 2)] and run_chunk(job, [3]) == [("a", 3)]
    assert built == ["a"]  # once for the run
    assert run_chunk(Job("b", run=job.run), [4]) == [("b", 4)] and closed == ["a"]  # new weights: built again
    assert run_chunk(Job("b"), [5]) == [("b", 5)] and built == ["a", "b", "b"]  # a new run: built again
    assert closed == ["a", "b"]


def test_labels_interrupted_keeps_the_frames_done(tmp_path, monkeypatch, capsys):
    import pnlviz.commands.labels as labels_cli

    data = tmp_path / "d"
    data.mkdir()
    for stem in ("00000", "00001", "00002", "00003"):
        shutil.copy(EXAMPLES_DIR / "sample" / f"{stem}.json", data / f"{stem}.json")
    real = labels_cli.label_frame

    def fake(ds, stem, *a):
        if stem == "00002":
            raise KeyboardInterrupt
        return real(ds, stem, *a)

    monkeypatch.setattr(labels_cli, "label_frame", fake)
    out = tmp_path / "labels"
    assert main(["labels", "--data", str(data), "--out", str(out)]) == 130
    assert f"interrupted: kept 2 of 4 frames in {out}" in capsys.readouterr().err
    assert sorted(p.name for p in out.glob("*.json")) == ["00000.json", "00001.json"]


def test_every_failure_code_of_the_engine_has_words_in_the_summary():
    from pnlviz.calib.calibrate import FAILURE_CODES
    from pnlviz.commands.calibrate import failure_words

    words = failure_words()
    assert all(words.get(code, code) != code for code in FAILURE_CODES)
    assert len(set(words.values())) == len(words)
