"""Nothing overwritten, nothing read as the wrong thing (issue #32): no command writes over or
under what it reads; an edits folder belongs to the dataset it was made for; ``--edits`` that is
not an edits folder is an error, never "no edits"."""

import hashlib
import os
import shutil

import pytest

from pnlviz import EXAMPLES_DIR
from pnlviz.cli import main


def _tree(root):
    """Every file under ``root`` with a digest of its bytes."""
    return {str(p.relative_to(root)): hashlib.sha1(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


def _frames(dst, pairs):
    """Frames of the bundled sample copied as ``dst/<name>`` (``pairs``: (sample stem, name))."""
    dst.mkdir(parents=True)
    for src, name in pairs:
        for ext in (".jpg", ".json"):
            shutil.copy(EXAMPLES_DIR / "sample" / f"{src}{ext}", dst / f"{name}{ext}")
    return dst


@pytest.mark.parametrize("inner", ["annotations", "keypoints"])
def test_export_never_writes_over_or_under_its_own_dataset(tmp_path, capsys, inner):
    """``export --data X/annotations --out X --all`` used to replace all 6 of X's annotation files
    with its own (``X/keypoints`` with label files): refused before any work, one line naming both
    paths, every file of X as it was."""
    x = tmp_path / "X"
    _frames(x / inner, [(f"0000{i}", f"0000{i}") for i in range(6)])
    before = _tree(tmp_path)
    assert main(["export", "--data", str(x / inner), "--out", str(x), "--all", "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(x) in err[0] and str(x / inner) in err[0] and "holds the dataset" in err[0]
    # and inside it
    assert main(["export", "--data", str(x / inner), "--out", str(x / inner / "out"), "--all", "--no-progress"]) == 2
    assert "inside the dataset" in capsys.readouterr().err
    assert _tree(tmp_path) == before


def test_labels_refuse_an_output_folder_above_their_dataset(tmp_path, capsys):
    x = tmp_path / "X"
    data = _frames(x / "data", [("00000", "00000"), ("00001", "00001")])
    before = _tree(tmp_path)
    assert main(["labels", "--data", str(data), "--out", str(x)]) == 2
    assert "holds the dataset" in capsys.readouterr().err
    assert _tree(tmp_path) == before


@pytest.fixture()
def two_datasets(tmp_path):
    """Datasets A and B with the same stems but other pictures, and A's edits folder (a review
    and a moved point, written by the app)."""
    from pnlviz.app.state import AppState

    a = _frames(tmp_path / "A", [("00000", "00000"), ("00001", "00001"), ("00002", "00002")])
    b = _frames(tmp_path / "B", [("00003", "00000"), ("00004", "00001"), ("00005", "00002")])
    st = AppState(a, edits=tmp_path / "A.edits")
    try:
        st.set_review("00000", "accepted")
        st.move_keypoint("00001", 5, 100.0, 100.0)
    finally:
        st.close()
    return a, b, tmp_path / "A.edits"


def test_an_edits_folder_of_another_dataset_is_refused_and_can_be_adopted(two_datasets, tmp_path, capsys):
    """A's edits used to be exported as reviewed labels of B's pictures (same stems). Now export,
    qa, calibrate and the app refuse them with the mismatches listed; --force-edits adopts the
    folder; A with its own folder goes on as before."""
    from pnlviz.app.state import AppState
    from pnlviz.data.edits import EditsFolderError

    a, b, edits = two_datasets
    before = _tree(edits)
    out = tmp_path / "out"
    assert main(["export", "--data", str(b), "--edits", str(edits), "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "holds edits of another dataset" in err and "00000" in err and "00001" in err and str(a) in err
    assert not out.exists()
    assert main(["qa", "--data", str(b), "--edits", str(edits), "--out", str(tmp_path / "q.jsonl"),
                 "--no-progress"]) == 2
    assert main(["calibrate", "--data", str(b), "--edits", str(edits), "--out", str(tmp_path / "c.zip"),
                 "--no-progress"]) == 2
    assert "another dataset" in capsys.readouterr().err
    with pytest.raises(EditsFolderError, match="another dataset"):
        AppState(b, edits=edits)
    assert _tree(edits) == before  # refused: nothing read into B, nothing changed in the folder
    assert main(["export", "--data", str(b), "--edits", str(edits), "--out", str(out), "--no-progress",
                 "--force-edits"]) == 0
    assert "adopted with --force-edits" in capsys.readouterr().err
    assert main(["export", "--data", str(a), "--edits", str(edits), "--out", str(tmp_path / "a_out"),
                 "--no-progress"]) == 0
    assert sorted(p.stem for p in (tmp_path / "a_out" / "annotations").glob("*.json")) == ["00000", "00001"]
    # the app adopts it too, and its export button exports what it shows
    from pnlviz.app.export import export_zip_bytes

    st = AppState(b, edits=edits, force_edits=True)
    try:
        assert export_zip_bytes(st)
        st.move_keypoint("00002", 5, 90.0, 90.0)  # written again: the record is now B's
    finally:
        st.close()
    with pytest.raises(EditsFolderError, match="00000"):  # 00000 and 00001 are still A's records
        AppState(b, edits=edits)


@pytest.mark.parametrize("kind", ["typo", "file", "fifo", "dev_zero", "empty_folder"])
def test_edits_that_is_not_an_edits_folder_is_an_error(two_datasets, tmp_path, capsys, kind):
    """``--edits`` that is a typo, a file, a FIFO, /dev/zero or a folder without edits used to
    read as "no edits" (export exit 0): now every command that reads one says what it is, writes
    nothing and exits non-zero."""
    a, _, _ = two_datasets
    path = tmp_path / "edits_arg"
    if kind == "file":
        path.write_text("{}")
    elif kind == "fifo":
        os.mkfifo(path)
    elif kind == "dev_zero":
        path = "/dev/zero"
    elif kind == "empty_folder":
        path.mkdir()
    for command, out in (("export", tmp_path / "e_out"), ("qa", tmp_path / "q.jsonl"),
                         ("calibrate", tmp_path / "c.zip")):
        code = main([command, "--data", str(a), "--edits", str(path), "--out", str(out), "--no-progress"])
        err = capsys.readouterr().err
        assert code != 0 and f"--edits {path}" in err, (command, err)
        assert not os.path.exists(out)


def _in_time(fn, seconds=20.0):
    """``fn()`` run in a thread: its result, or a failure when it has not returned in time (a
    read blocked on a FIFO would hang the test itself)."""
    import threading

    out: dict = {}
    th = threading.Thread(target=lambda: out.setdefault("value", fn()), daemon=True)
    th.start()
    th.join(seconds)
    assert not th.is_alive(), f"{fn} did not return within {seconds} s"
    return out.get("value")


@pytest.mark.parametrize("what", ["fifo", "dev_zero", "damaged", "digits", "folder"])
def test_a_bad_clips_file_is_set_aside_never_read_as_no_cuts_nor_written_over(tmp_path, what):
    """The hand's cuts of a clip live in ``<edits>/clips/<clip>.json``. A FIFO there used to hang
    the tab, a link to /dev/zero was read until MemoryError, a damaged file was read as "no cuts"
    and then written over, "123" was read as cuts 1, 2 and 3. Now each is set aside
    (``.damaged-<time>``) with a warning, without blocking; the hand's next cut is saved anew."""
    import json

    from pnlviz.pipeline.clip import read_cuts, set_cut
    from pnlviz.pipeline.reader import FrameReader

    data = _frames(tmp_path / "clip", [(f"0000{i}", f"m-IMG_{i + 1}") for i in range(4)])
    reader = FrameReader.open(data, edits=tmp_path / "edits", writable=True)
    try:
        path = tmp_path / "edits" / "clips" / "m.json"
        path.parent.mkdir(parents=True)
        damaged = '{"cuts": {"added": [2], "removed": ['  # a write torn half way: the hand's cut is in it
        if what == "fifo":
            os.mkfifo(path)
        elif what == "dev_zero":
            os.symlink("/dev/zero", path)
        elif what == "damaged":
            path.write_text(damaged)
        elif what == "digits":
            path.write_text("123")
        else:
            path.mkdir()
        cuts = _in_time(lambda: read_cuts(reader, "m"))
        assert cuts.added == frozenset() and cuts.removed == frozenset()
        aside = list(path.parent.glob("m.json.damaged-*"))
        assert len(aside) == 1 and not os.path.lexists(path)
        assert any("m.json" in w and "moved aside" in w for w in reader.edits_folder.warnings)
        if what == "damaged":
            assert aside[0].read_text() == damaged  # kept as it was
        from pnlviz.pipeline.clip import clip_solver, dataset_clips

        solver = clip_solver(reader, "m", dataset_clips(reader.stems)["m"])
        set_cut(reader, solver, "m", 2, True)
        assert json.loads(path.read_text()) == {"cuts": {"added": [2], "removed": []}}
        assert len(list(path.parent.glob("m.json.damaged-*"))) == 1
    finally:
        reader.close()


@pytest.mark.parametrize("what", ["fifo", "bad_lines", "not_a_folder"])
def test_the_app_starts_and_draws_whatever_is_in_its_cache(tmp_path, what):
    """A FIFO at ``<edits>/cache/summaries.jsonl`` used to hang the start; one bad line in it
    stopped the first frame from drawing or the server from starting. Now the app starts, the bad
    lines are skipped and counted, the good ones kept, anything not a file set aside."""
    import json

    from pnlviz.app.state import AppState

    data = _frames(tmp_path / "set", [("00000", "00000"), ("00001", "00001")])
    cache = tmp_path / "edits" / "cache"
    summaries = cache / "summaries.jsonl"
    cache.parent.mkdir(parents=True)
    good = {"stem": "00001", "ok": True, "failure": None, "worst": 1.0, "median": 0.5, "jac5": 1.0,
            "token": "x", "suspect": None, "suspect_note": None}
    if what == "fifo":
        cache.mkdir()
        os.mkfifo(summaries)
    elif what == "bad_lines":
        cache.mkdir()
        summaries.write_text("\n".join([json.dumps(good), "{not json", json.dumps({**good, "stem": 7}),
                                        json.dumps({**good, "median": "x", "stem": "00000"}), "[]"]) + "\n")
    else:
        cache.write_text("a file where the cache folder goes")
    st = _in_time(lambda: AppState(data, edits=tmp_path / "edits"))
    try:
        if what == "bad_lines":  # the good line kept, the three bad ones not
            assert st.triage.store.get("00001") is not None
            assert st.triage.store.get("00000") is None
        view = _in_time(lambda: st.view("00000"))
        assert view.result is not None and view.result.ok  # the first frame calibrates and draws
        warnings = " | ".join(st.edits.warnings)
        if what == "bad_lines":
            assert "1 damaged line(s) skipped" in warnings and "3 line(s) that are not frame summaries" in warnings
        else:
            assert "moved aside" in warnings
    finally:
        st.close()


def test_sigterm_ends_the_server_within_five_seconds(tmp_path):
    """``kill`` (SIGTERM) stops ``pnlviz serve`` as Ctrl+C does, and within 5 s whatever it was
    doing (the server used to ignore it after a read hung on a FIFO)."""
    import signal
    import subprocess
    import sys
    import time

    from helpers import free_port

    data = _frames(tmp_path / "set", [("00000", "00000")])
    proc = subprocess.Popen([sys.executable, "-m", "pnlviz", "serve", "--data", str(data), "--no-detect",
                             "--port", str(free_port())], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        deadline = time.time() + 60
        for line in proc.stdout:
            if "pnlviz: open" in line or time.time() > deadline:
                break
        t0 = time.time()
        proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=10)
        assert time.time() - t0 < 5.5 and proc.returncode is not None
    finally:
        if proc.poll() is None:
            proc.kill()


def test_qa_resume_goes_on_past_a_damaged_line_of_its_own_output(tmp_path, capsys):
    """``qa --resume`` used to crash on a damaged line of its own output: now the line is not
    kept (one warning), its frame is judged again, the others are kept as they were."""
    import json

    data = _frames(tmp_path / "set", [(f"0000{i}", f"0000{i}") for i in range(3)])
    out = tmp_path / "qa.jsonl"
    assert main(["qa", "--data", str(data), "--out", str(out), "--no-progress"]) == 0
    lines = [json.loads(t) for t in out.read_text().splitlines()]
    frames = [line for line in lines if "stem" in line]
    damaged = dict(frames[0], score="high")
    out.write_text("\n".join(json.dumps(x) for x in [damaged] + frames[1:]) + "\n{torn\n")
    capsys.readouterr()
    assert main(["qa", "--data", str(data), "--out", str(out), "--resume", "--no-progress"]) == 0
    err = capsys.readouterr().err
    assert "2 damaged line(s) not kept" in err
    again = {x["stem"]: x for x in map(json.loads, out.read_text().splitlines()) if "stem" in x}
    assert sorted(again) == sorted(f["stem"] for f in frames)
    assert again[frames[0]["stem"]]["score"] == frames[0]["score"]  # judged again
    assert all(again[f["stem"]] == f for f in frames[1:])


def test_qa_says_when_it_leaves_out_a_damaged_edit_record(two_datasets, capsys):
    """``export`` warned about a damaged edit record while ``qa`` ignored it without a word."""
    a, _, edits = two_datasets
    (edits / "frames" / "00002.json").write_text("{damaged")
    assert main(["qa", "--data", str(a), "--edits", str(edits), "--out", str(a.parent / "q.jsonl"),
                 "--no-progress"]) == 0
    assert "00002.json: damaged edit record ignored" in capsys.readouterr().err


def test_memory_is_bounded_by_what_a_frame_can_hold(tmp_path, capsys):
    """A 31 MB annotation (under the old 64 MiB cap) took 2.0 GB in qa and 2.55 GB in serve; one
    class of 650,000 points 4.4 GB. Annotation files over 4 MiB and classes over 500 points are
    refused, one line each, the other frames done; the largest annotation still read stays small
    (measured: 120 MB peak for qa, benchmarks/bench_serve_memory.py for the app)."""
    import json

    import numpy as np

    from pnlviz.data.annotations import MAX_POINTS

    data = _frames(tmp_path / "set", [(f"0000{i}", f"0000{i}") for i in range(3)])
    rng = np.random.default_rng(0)
    pts = [{"x": float(x), "y": float(y)} for x, y in rng.random((650_000, 2))]
    (data / "00000.json").write_text(json.dumps({"Side line top": pts}))
    ann = json.loads((data / "00001.json").read_text())
    ann["Middle line"] = [{"x": 0.5, "y": i / (MAX_POINTS + 1)} for i in range(MAX_POINTS + 1)]
    (data / "00001.json").write_text(json.dumps(ann))
    out = tmp_path / "q.jsonl"
    assert main(["qa", "--data", str(data), "--out", str(out), "--no-progress"]) == 0
    said = capsys.readouterr()
    assert "00000.json: file too large" in said.out + said.err and "the limit for this kind of file is 4 MiB" in said.out + said.err
    assert f"'Middle line' has {MAX_POINTS + 1:,} points" in said.out + said.err
    judged = [json.loads(t) for t in out.read_text().splitlines()]
    assert [x["stem"] for x in judged if "score" in x] == ["00002"]


def test_a_video_over_the_pixel_cap_is_refused(tmp_path, monkeypatch):
    """Video frames obey the image pixel cap (a 9000x9000 video was served at 1.45 GB)."""
    cv2 = pytest.importorskip("cv2")
    import numpy as np

    from pnlviz.data import DataError, limits
    from pnlviz.data.video import VideoDataset

    path = tmp_path / "v.mp4"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), 25.0, (320, 240))
    if not writer.isOpened():
        pytest.skip("this OpenCV build cannot write mp4")
    for _ in range(3):
        writer.write(np.zeros((240, 320, 3), np.uint8))
    writer.release()
    assert len(VideoDataset(path)) == 3
    monkeypatch.setattr(limits, "MAX_IMAGE_PIXELS", 320 * 240 - 1)  # as a 9000x9000 video is against 50 MP
    with pytest.raises(DataError, match="image too large: 320x240"):
        VideoDataset(path)


def test_image_to_pitch_gives_no_point_past_the_horizon_nor_where_the_lens_does_not_invert():
    """A pixel 0.25 px below the horizon used to land 141 km away, and with lens distortion a pixel
    far outside the image, where the model folds back, on a wrong ground point: both are NaN now;
    pixels of the pitch are as before (their round trip within 1 mm)."""
    from dataclasses import replace

    import numpy as np

    import pnlviz

    cam = pnlviz.Camera.from_look_at((0.0, 60.0, -18.0), (0.0, 0.0, 0.0), hfov_deg=40, width=1280, height=720)
    # the horizon's row at the image centre column: the limit of the ground's image going away
    far = cam.project(np.array([[0.0, -1e7, 0.0]]))[0]
    assert np.all(np.isnan(cam.image_to_pitch(far + [0.0, 0.25])))
    assert np.all(np.isnan(cam.image_to_pitch(np.array([[640.0, far[1] - 5]]))))  # above it
    ground = np.array([[x, y, 0.0] for x in (-40.0, 0.0, 30.0) for y in (-30.0, 0.0, 30.0)])
    uv = cam.project(ground)
    assert np.allclose(cam.image_to_pitch(uv), ground[:, :2], atol=1e-3)
    lens = replace(cam, radial=np.array([-0.4, 0.0, 0.0, 0.0, 0.0, 0.0]))  # folds back beyond r = 0.91
    grid = np.array([[x, y, 0.0] for x in range(-30, 31, 5) for y in range(-30, 31, 5)], float)
    inside = lens.project(grid)
    seen = lens.in_image(inside)
    ground = grid
    assert seen.sum() >= 4 and np.allclose(lens.image_to_pitch(inside[seen]), ground[seen, :2], atol=1e-3)
    outside = np.array([[640.0 + 2.2 * lens.fx * 0.35, 360.0]])  # past where the distortion turns back
    assert not lens.lens_inverts(outside)[0] and np.all(np.isnan(lens.image_to_pitch(outside)))


@pytest.mark.parametrize("key, value, words", [
    ("x_focal_length", 0, "must be positive"), ("y_focal_length", float("nan"), "must be finite"),
    ("position_meters", [1e308, 0.0, -10.0], "farther than 10 km"), ("principal_point", [480.0], "2 numbers"),
    ("pan_degrees", "left", "a number"), ("radial_distortion", [0.1, float("inf"), 0, 0, 0, 0], "must be finite"),
    ("tilt_degrees", None, "a number")])
def test_from_soccernet_refuses_nonsense_naming_the_key(key, value, words):
    """``Camera.from_soccernet`` accepted focal 0, NaN and a position 1e308 away, and raised a bare
    KeyError for a missing key: now every field is checked, an ArgumentError naming the key."""
    import pnlviz

    d = pnlviz.Camera.from_look_at((0.0, 60.0, -18.0), (0.0, 0.0, 0.0), hfov_deg=40, width=960,
                                   height=540).to_soccernet()
    with pytest.raises(pnlviz.ArgumentError, match=rf"^camera\['{key}'\]: .*{words}"):
        pnlviz.Camera.from_soccernet(dict(d, **{key: value}))
    missing = {k: v for k, v in d.items() if k != key}
    if key not in ("radial_distortion",):  # the lens terms are optional
        with pytest.raises(pnlviz.ArgumentError, match=rf"^camera\['{key}'\]: missing"):
            pnlviz.Camera.from_soccernet(missing)


def test_export_writes_no_empty_label_file_for_a_frame_it_knows_nothing_of(tmp_path, capsys):
    """``export --all`` of an image-only folder without detections wrote an empty label file for
    every unreviewed frame (83 of 93) without a word: now it says how many and why, writes none
    for them, and lists them in the manifest; a reviewed frame without labels is exported empty
    (someone confirmed there is nothing)."""
    import json

    from pnlviz.app.state import AppState

    data = tmp_path / "images"
    data.mkdir()
    for i in range(4):
        shutil.copy(EXAMPLES_DIR / "sample" / f"0000{i}.jpg", data / f"0000{i}.jpg")
    st = AppState(data, edits=tmp_path / "edits")
    try:
        st.set_review("00003", "accepted")
    finally:
        st.close()
    out = tmp_path / "out"
    assert main(["export", "--data", str(data), "--edits", str(tmp_path / "edits"), "--out", str(out), "--all",
                 "--no-progress"]) == 0
    said = capsys.readouterr()
    assert "3 unreviewed frame(s) with nothing to export" in said.err and "exported 1 frames of 4" in said.out
    assert sorted(p.name for p in (out / "keypoints").glob("*.json")) == ["00003.json"]
    frames = json.loads((out / "manifest.json").read_text())["frames"]
    assert [s for s, e in frames.items() if e.get("empty")] == ["00000", "00001", "00002"]
    assert json.loads((out / "keypoints" / "00003.json").read_text())["keypoints"] == {}
