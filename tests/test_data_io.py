"""Tests of pnlviz.data: readers/writers, validation messages, lazy dataset index, round trips."""

from __future__ import annotations

import json
import os
import pickle
import zipfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import pnlviz.data as pdata
import pnlviz.data.dataset as dataset_mod
from pnlviz.data import (
    DataError,
    Predictions,
    annotation_to_json,
    atomic_write_bytes,
    atomic_write_text,
    decode_image,
    from_pixels,
    open_dataset,
    parse_annotation,
    parse_annotation_bytes,
    parse_predictions,
    parse_predictions_bytes,
    predictions_to_json,
    read_annotation,
    read_camera_json,
    read_camera_zip,
    read_homographies,
    read_predictions,
    sort_stems,
    to_pixels,
    write_annotation,
    write_camera_json,
    write_camera_zip,
    write_homographies,
    write_predictions,
)
from pnlviz.field.names import ALL_CLASSES, IGNORED_CLASSES, LINE_ID_TO_CLASS, MODEL_CLASSES
from helpers import needs_shared

SHARED = Path(__file__).resolve().parents[2] / "shared"
DATA = SHARED / "data"
SN22_ZIP = DATA / "sn22_test_subset" / "annotations.zip"
WC14_ZIP = DATA / "wc14_test_half" / "annotations.zip"
WC14_PRED = DATA / "wc14_test_half" / "detections_pnlcalib.zip"
WC14_H = DATA / "wc14_test_half" / "homographies.json"
FRAMES = DATA / "frames"


POST = "Goal left post left "  # the evaluator's spelling, trailing space included

CAMERA = {
    "pan_degrees": -12.5,
    "tilt_degrees": 76.0,
    "roll_degrees": 0.25,
    "position_meters": [0.5, 55.0, -12.0],
    "x_focal_length": 1500.0,
    "y_focal_length": 1500.0,
    "principal_point": [480.0, 270.0],
    "radial_distortion": [0.0] * 6,
    "tangential_distortion": [0.0, 0.0],
    "thin_prism_distortion": [0.0] * 4,
}


def good_annotation_obj() -> dict:
    return {
        "Side line top": [{"x": 0.0, "y": 0.2}, {"x": 1.0, "y": 0.25}],
        POST: [{"x": 0.5, "y": 0.3}, {"x": 0.5, "y": 0.45}],
        "Circle left": [{"x": 0.3, "y": 0.6}, {"x": 0.35, "y": 0.62}, {"x": 0.4, "y": 0.6}],
    }


def write_json(path: Path, obj) -> Path:
    path.write_text(json.dumps(obj))
    return path


def assert_one_line_error(excinfo, *needles: str) -> str:
    msg = str(excinfo.value)
    assert "\n" not in msg and "\r" not in msg, msg
    for needle in needles:
        assert needle in msg, f"{needle!r} not in {msg!r}"
    return msg


# --------------------------------------------------------------------------------------------
# real data


@needs_shared
def test_real_sn22_annotations_all_read():
    with open_dataset(SN22_ZIP) as ds:
        assert len(ds) == 400
        assert list(ds.stems) == sorted(ds.stems, key=int)
        anns = dict(ds.iter_annotations())
        assert ds.skipped == []
        assert len(anns) == 400
        n_post = 0
        for stem, ann in anns.items():
            assert ds.frame(stem).has_annotation and not ds.frame(stem).has_image
            for cls, pts in ann.items():
                assert cls in MODEL_CLASSES
                assert pts.dtype == np.float64 and pts.ndim == 2 and pts.shape[1] == 2 and len(pts) >= 2
            n_post += POST in ann
        assert n_post > 0  # the trailing-space goal post is present in the real data


@needs_shared
def test_real_wc14_annotations_all_read():
    ds = open_dataset(WC14_ZIP)
    assert len(ds) == 93
    assert ds.stems[:3] == ("3", "4", "6")  # numeric order, not "100" < "3"
    skipped = []
    anns = dict(ds.iter_annotations(on_error=lambda s, e: skipped.append(s)))
    assert len(anns) == 93 and skipped == [] and ds.skipped == []
    assert ds.image("3") is None and ds.image_size("3") is None
    assert ds.match_info is None and ds.camera_dict("3") is None


@needs_shared
def test_real_annotations_json_round_trip_exact(tmp_path):
    """Canonical real files come back byte-for-byte equal as JSON objects."""
    with zipfile.ZipFile(SN22_ZIP) as zf:
        names = zf.namelist()[:40]
        for name in names:
            raw = json.loads(zf.read(name))
            ann = parse_annotation(raw, name)
            assert annotation_to_json(ann) == raw
            out = tmp_path / name
            write_annotation(out, ann)
            back = read_annotation(out)
            assert back.keys() == ann.keys()
            for cls in ann:
                np.testing.assert_array_equal(back[cls], ann[cls])


@needs_shared
def test_real_predictions_read_and_round_trip(tmp_path):
    preds = read_predictions(WC14_PRED)
    assert len(preds) == 93
    assert list(preds) == sort_stems(preds)
    for p in preds.values():
        assert all(1 <= k <= 73 for k in p.keypoints)
        assert all(1 <= k <= 23 for k in p.lines)
    # the parsed objects write back to exactly the JSON we read
    with zipfile.ZipFile(WC14_PRED) as zf:
        for name in zf.namelist():
            assert predictions_to_json(preds[name[:-5]]) == json.loads(zf.read(name))
    out = tmp_path / "preds.zip"
    write_predictions(out, preds)
    assert read_predictions(out) == preds
    with zipfile.ZipFile(out) as zf:
        assert all("/" not in n for n in zf.namelist())
    # pixel helpers use x * W (no -1)
    p = preds["3"]
    k, (x, y, conf) = next(iter(p.keypoints.items()))
    assert p.keypoints_px(1280, 720)[k] == (x * 1280, y * 720, conf)
    ids, xy, conf_arr = p.keypoint_arrays(1280, 720)
    assert list(ids) == sorted(p.keypoints) and xy.shape == (len(ids), 2) and conf_arr.shape == (len(ids),)
    lk, line = next(iter(p.lines.items()))
    assert p.lines_px(100, 50)[lk] == (line[0] * 100, line[1] * 50, line[2], line[3] * 100, line[4] * 50, line[5])
    assert lk in LINE_ID_TO_CLASS


@needs_shared
def test_real_homographies(tmp_path):
    hs = read_homographies(WC14_H)
    assert len(hs) == 93
    assert set(hs) == set(open_dataset(WC14_ZIP).stems)
    for h in hs.values():
        assert h.shape == (3, 3) and h.dtype == np.float64 and np.all(np.isfinite(h))
    single = read_homographies(FRAMES / "wc14_trainval_16_homography.json")
    assert list(single) == ["wc14_trainval_16"]
    out = tmp_path / "h.json"
    write_homographies(out, hs)
    back = read_homographies(out)
    assert list(back) == list(hs)
    for s in hs:
        np.testing.assert_array_equal(back[s], hs[s])


@needs_shared
def test_real_frames_folder_images():
    ds = open_dataset(FRAMES)
    assert ds.image_size("messi_sample") == (1073, 603)
    img = ds.image("wc14_trainval_16")
    assert img.shape == (720, 1280, 3) and img.dtype == np.uint8
    assert ds.image_size("wc14_trainval_16") == (1280, 720)
    assert ds.annotation("messi_sample") is None
    # the homography json sits there like an annotation: it is reported, not crashed on
    list(ds.iter_annotations())
    assert [s for s, _ in ds.skipped] == ["wc14_trainval_16_homography"]
    assert "unknown class 'wc14_trainval_16'" in str(ds.skipped[0][1])


# --------------------------------------------------------------------------------------------
# annotations


def test_goal_post_spelling_accepted_both_ways_written_with_space(tmp_path):
    obj = good_annotation_obj()
    with_space = parse_annotation(obj)
    obj_no_space = {(k.strip() if k == POST else k): v for k, v in obj.items()}
    assert "Goal left post left" in obj_no_space
    without = parse_annotation(obj_no_space)
    assert POST in with_space and POST in without
    assert "Goal left post left" not in without
    assert list(annotation_to_json(without)) == list(obj)
    assert POST in annotation_to_json({"Goal left post left": [[0.1, 0.2], [0.1, 0.3]]})
    out = tmp_path / "00001.json"
    write_annotation(out, without)
    assert '"Goal left post left "' in out.read_text()
    assert POST in json.loads(out.read_text())
    with pytest.raises(DataError) as ei:
        parse_annotation({**obj, "Goal left post left": obj[POST]}, "dup.json")
    assert_one_line_error(ei, "dup.json", "appears twice")


def test_unknown_classes_dropped_unless_asked():
    obj = {**good_annotation_obj(), "Goal unknown": [{"x": 0.1, "y": 0.1}], "Line unknown": []}
    assert set(parse_annotation(obj)) == set(good_annotation_obj())
    kept = parse_annotation(obj, keep_unknown=True)
    assert set(kept) == set(good_annotation_obj()) | set(IGNORED_CLASSES)
    assert kept["Line unknown"].shape == (0, 2)


def test_pixel_helpers_use_w_minus_one():
    pts = np.array([[0.0, 0.0], [1.0, 1.0], [0.5, 0.25]])
    px = to_pixels(pts, 1280, 720)
    np.testing.assert_allclose(px, [[0, 0], [1279, 719], [639.5, 179.75]])
    np.testing.assert_allclose(from_pixels(px, 1280, 720), pts)


def test_parse_returns_float64_arrays():
    ann = parse_annotation({"Middle line": [{"x": 0, "y": 1}, {"x": 1, "y": 0}]})
    assert ann["Middle line"].dtype == np.float64
    np.testing.assert_array_equal(ann["Middle line"], [[0, 1], [1, 0]])
    assert parse_annotation({}) == {}


# --------------------------------------------------------------------------------------------
# bad inputs: one-line messages with file name and the specific problem


@pytest.mark.parametrize(
    "text, needles",
    [
        (
            json.dumps({"Big rect left mian": [{"x": 0.1, "y": 0.1}, {"x": 0.2, "y": 0.2}]}),
            ["unknown class 'Big rect left mian'", "did you mean 'Big rect. left main'"],
        ),
        ('{"Side line top": [{"x": 0.1, "y": NaN}, {"x": 0.2, "y": 0.2}]}', ["non-finite", "'Side line top'", "point 0", "y = nan"]),
        ('{"Side line top": [{"x": 0.1, "y": 0.1}, {"x": Infinity, "y": 0.2}]}', ["non-finite", "point 1", "x = inf"]),
        (
            json.dumps({"Middle line": [{"x": 0.1, "y": 0.1}, {"x": 0.2, "y": 7.0}]}),
            ["out of range", "'Middle line'", "point 1", "y = 7", "[-0.5, 1.5]"],
        ),
        (json.dumps({"Middle line": [{"x": 0.1, "y": 0.1}]}), ["line class 'Middle line'", "1 point", "at least 2"]),
        (json.dumps({"Circle left": [{"x": 0.1, "y": 0.1}]}), ["circle class 'Circle left'", "1 point"]),
        (json.dumps({"Circle central": []}), ["circle class 'Circle central'", "0 points"]),
        ('{"Side line top": [{"x": 0.1, "y": 0.1},', ["corrupt JSON", "line 1", "column"]),
        ('{"Side line top": [{"x": 0.1 "y": 0.1}]}', ["corrupt JSON", "Expecting", "line 1, column 30"]),
        ("", ["corrupt JSON"]),
        (json.dumps([1, 2]), ["expected a JSON object mapping class names", "got a list"]),
        (json.dumps({"Middle line": {"x": 1}}), ["'Middle line'", "expected a list of points"]),
        (json.dumps({"Middle line": [{"x": 0.1}, {"x": 0.2, "y": 0.1}]}), ["point 0", 'expected an object with "x" and "y"']),
        (json.dumps({"Middle line": [[0.1, 0.1], [0.2, 0.1]]}), ["point 0", "got a list"]),
        (json.dumps({"Middle line": [{"x": "0.1", "y": 0.1}, {"x": 0.2, "y": 0.1}]}), ['"x" is not a number', "a string"]),
        (json.dumps({"Middle line": [{"x": True, "y": 0.1}, {"x": 0.2, "y": 0.1}]}), ['"x" is not a number', "boolean"]),
    ],
)
def test_bad_annotation_files(tmp_path, text, needles):
    path = tmp_path / "00042.json"
    path.write_text(text)
    with pytest.raises(DataError) as ei:
        read_annotation(path)
    assert_one_line_error(ei, f"{path}: ", *needles)
    assert isinstance(ei.value, ValueError)
    assert ei.value.source == str(path)


def test_unknown_class_lists_at_most_three_matches():
    with pytest.raises(DataError) as ei:
        parse_annotation({"Goal left post": []}, "a.json")
    msg = assert_one_line_error(ei, "a.json: unknown class 'Goal left post'", "did you mean")
    assert 1 <= msg.count("'Goal") - 1 <= 3
    with pytest.raises(DataError) as ei:
        parse_annotation({"zzzzzz": []}, "a.json")
    assert str(ei.value) == "a.json: unknown class 'zzzzzz'"


def test_not_utf8_and_unreadable(tmp_path):
    bad = tmp_path / "x.json"
    bad.write_bytes(b'{"Middle line": "\xff\xfe"}')
    with pytest.raises(DataError) as ei:
        read_annotation(bad)
    assert_one_line_error(ei, str(bad), "corrupt JSON")
    with pytest.raises(DataError) as ei:
        read_annotation(tmp_path / "missing.json")
    assert_one_line_error(ei, "missing.json", "cannot read file")


def test_data_error_pickles_and_stays_one_line():
    err = DataError("a\nb.json", "line one\nline two")
    assert str(err) == "a b.json: line one line two"
    back = pickle.loads(pickle.dumps(err))
    assert str(back) == str(err) and back.source == err.source and back.problem == err.problem


def test_corrupt_image_bytes(tmp_path):
    d = tmp_path / "ds"
    d.mkdir()
    (d / "00001.jpg").write_bytes(b"\xff\xd8\xff\xe0 this is not really a jpeg" * 10)
    (d / "00002.png").write_bytes(b"")
    ds = open_dataset(d)
    for stem, name in (("00001", "00001.jpg"), ("00002", "00002.png")):
        with pytest.raises(DataError) as ei:
            ds.image(stem)
        assert_one_line_error(ei, str(d / name), "corrupt image")
        with pytest.raises(DataError) as ei:
            ds.image_size(stem)
        assert_one_line_error(ei, name, "corrupt image")
    with pytest.raises(DataError) as ei:
        decode_image(b"garbage", "mem.zip:1.png")
    assert_one_line_error(ei, "mem.zip:1.png: corrupt image")


def test_zip_member_errors_name_archive_and_member(tmp_path):
    zpath = tmp_path / "ds.zip"
    with zipfile.ZipFile(zpath, "w") as zf:
        zf.writestr("00001.json", json.dumps(good_annotation_obj()))
        zf.writestr("00002.json", '{"Side line top": [')
        zf.writestr("00003.png", b"not a png")
    ds = open_dataset(zpath)
    with pytest.raises(DataError) as ei:
        ds.annotation("00002")
    assert_one_line_error(ei, f"{zpath}:00002.json: corrupt JSON")
    with pytest.raises(DataError) as ei:
        ds.image("00003")
    assert_one_line_error(ei, f"{zpath}:00003.png: corrupt image")


def test_not_a_dataset(tmp_path):
    with pytest.raises(DataError) as ei:
        open_dataset(tmp_path / "nope")
    assert_one_line_error(ei, "nope", "no such file or folder")
    f = tmp_path / "file.zip"
    f.write_bytes(b"PK but not a zip")
    with pytest.raises(DataError) as ei:
        open_dataset(f)
    assert_one_line_error(ei, "file.zip", "zip")


# --------------------------------------------------------------------------------------------
# dataset


def make_frame_png(path: Path, w: int = 32, h: int = 18) -> None:
    import cv2

    img = np.zeros((h, w, 3), np.uint8)
    img[:, : w // 2] = (255, 0, 0)
    ok, buf = cv2.imencode(".png", img)
    assert ok
    path.write_bytes(buf.tobytes())


def test_dataset_open_is_lazy_on_2000_frames(tmp_path, monkeypatch):
    d = tmp_path / "big"
    d.mkdir()
    for i in range(2000):
        (d / f"{i:05d}.json").write_text("{}")
    calls = {"parse": 0, "read": 0}
    real_parse = dataset_mod.parse_annotation_bytes
    real_read = dataset_mod.Dataset._read

    def counting_parse(*a, **k):
        calls["parse"] += 1
        return real_parse(*a, **k)

    def counting_read(self, name):
        calls["read"] += 1
        return real_read(self, name)

    monkeypatch.setattr(dataset_mod, "parse_annotation_bytes", counting_parse)
    monkeypatch.setattr(dataset_mod.Dataset, "_read", counting_read)
    ds = open_dataset(d)
    assert calls == {"parse": 0, "read": 0}
    assert len(ds) == 2000 and ds.stems[0] == "00000" and ds.stems[-1] == "01999"
    assert ds.annotation("01234") == {}
    assert calls["parse"] == 1
    ds.annotation("01234")
    assert calls["parse"] == 1  # cached

    # same for a zip
    zpath = tmp_path / "big.zip"
    with zipfile.ZipFile(zpath, "w") as zf:
        for i in range(2000):
            zf.writestr(f"test/{i}.json", "{}")
    calls.update(parse=0, read=0)
    zds = open_dataset(zpath)
    assert calls == {"parse": 0, "read": 0}
    assert len(zds) == 2000 and zds.stems[:3] == ("0", "1", "2") and zds.stems[-1] == "1999"


def test_dataset_folder_layout(tmp_path):
    d = tmp_path / "ds"
    (d / "cameras").mkdir(parents=True)
    write_json(d / "00002.json", good_annotation_obj())  # annotation without image
    make_frame_png(d / "00010.png")  # image without annotation
    make_frame_png(d / "00001.png", 40, 20)
    write_json(d / "00001.json", {"Middle line": [{"x": 0.5, "y": 0}, {"x": 0.5, "y": 1}]})
    write_json(d / "match_info.json", {"teams": ["a", "b"]})
    write_json(d / "cameras" / "camera_00001.json", CAMERA)
    (d / "notes.txt").write_text("not a frame")
    ds = open_dataset(d)
    assert ds.stems == ("00001", "00002", "00010")
    assert "match_info" not in ds
    assert ds.match_info == {"teams": ["a", "b"]}
    f1, f2, f10 = (ds.frame(s) for s in ds.stems)
    assert f1.has_image and f1.has_annotation and f1.image_path == str(d / "00001.png")
    assert not f2.has_image and f2.has_annotation and f2.image_path is None
    assert f10.has_image and not f10.has_annotation
    assert ds.image_size("00001") == (40, 20)
    img = ds.image("00010")
    assert img.shape == (18, 32, 3) and img.dtype == np.uint8 and tuple(img[0, 0]) == (255, 0, 0)
    assert ds.image("00002") is None and ds.annotation("00010") is None
    assert ds.camera_dict("00001") == CAMERA and ds.camera_dict("00002") is None
    assert set(ds.annotation("00002")) == set(parse_annotation(good_annotation_obj()))
    with pytest.raises(KeyError):
        ds.frame("99999")


def test_dataset_annotation_cache_returns_copies(tmp_path):
    d = tmp_path / "ds"
    d.mkdir()
    write_json(d / "1.json", good_annotation_obj())
    ds = open_dataset(d, cache_size=2)
    a = ds.annotation("1")
    a["Side line top"][0, 0] = 99.0
    del a["Circle left"]
    b = ds.annotation("1")
    assert b["Side line top"][0, 0] == 0.0 and "Circle left" in b


def test_dataset_zip_nested_folder_and_cameras(tmp_path):
    zpath = tmp_path / "ds.zip"
    png = tmp_path / "f.png"
    make_frame_png(png)
    with zipfile.ZipFile(zpath, "w") as zf:
        zf.writestr("test/", "")
        zf.writestr("test/00001.json", json.dumps(good_annotation_obj()))
        zf.writestr("test/00001.png", png.read_bytes())
        zf.writestr("test/16.json", json.dumps({}))
        zf.writestr("test/2.jpg", png.read_bytes())  # png bytes under a .jpg name still decode
        zf.writestr("test/match_info.json", json.dumps({"a": 1}))
        zf.writestr("test/cameras/camera_00001.json", json.dumps(CAMERA))
        zf.writestr("__MACOSX/test/._00001.json", b"\x00junk")
    ds = open_dataset(zpath)
    assert ds.stems == ("00001", "2", "16")
    assert ds.frame("00001").image_path == "test/00001.png"
    assert ds.frame("00001").annotation_path == "test/00001.json"
    assert ds.image("2").shape == (18, 32, 3)
    assert ds.image_size("00001") == (32, 18)
    assert ds.match_info == {"a": 1}
    assert ds.camera_dict("00001") == CAMERA and ds.camera_dict("16") is None
    assert set(ds.annotation("00001")) == {"Side line top", POST, "Circle left"}
    # a dataset can go to a worker process
    back = pickle.loads(pickle.dumps(ds))
    assert back.stems == ds.stems and set(back.annotation("00001")) == set(ds.annotation("00001"))
    ds.close()
    assert ds.annotation("16") == {}  # reopens after close


def test_iter_annotations_skips_and_reports(tmp_path):
    d = tmp_path / "ds"
    d.mkdir()
    write_json(d / "1.json", good_annotation_obj())
    write_json(d / "2.json", {"Middle line": [{"x": 0.1, "y": 0.1}]})
    (d / "3.json").write_text("{oops")
    write_json(d / "4.json", {"Side line top": [{"x": 0.0, "y": 0.1}, {"x": 0.5, "y": 0.1}]})
    write_json(d / "5.json", {"Bad class": []})
    make_frame_png(d / "6.png")  # no annotation: neither yielded nor skipped
    ds = open_dataset(d)
    seen = []
    got = [s for s, _ in ds.iter_annotations(on_error=lambda s, e: seen.append((s, str(e))))]
    assert got == ["1", "4"]
    assert [s for s, _ in ds.skipped] == ["2", "3", "5"]
    assert all(isinstance(e, DataError) for _, e in ds.skipped)
    assert [s for s, _ in seen] == ["2", "3", "5"]
    assert "2.json: line class 'Middle line' has 1 point" in seen[0][1]
    assert "3.json: corrupt JSON" in seen[1][1]
    assert "5.json: unknown class 'Bad class'" in seen[2][1]


def test_natural_sort():
    assert sort_stems(["10", "2", "1", "00003"]) == ["1", "2", "00003", "10"]
    assert sort_stems(["frame10", "frame2", "Frame1", "a"]) == ["a", "Frame1", "frame2", "frame10"]


def test_nested_single_folder_on_disk(tmp_path):
    inner = tmp_path / "outer" / "test"
    inner.mkdir(parents=True)
    write_json(inner / "7.json", good_annotation_obj())
    ds = open_dataset(tmp_path / "outer")
    assert ds.stems == ("7",)


# --------------------------------------------------------------------------------------------
# atomic writes


def test_atomic_writes(tmp_path):
    p = tmp_path / "sub" / "a.txt"
    atomic_write_text(p, "hello\n")
    assert p.read_text() == "hello\n"
    atomic_write_bytes(p, b"\x00\x01")
    assert p.read_bytes() == b"\x00\x01"
    with pytest.raises(RuntimeError):
        with pdata.atomic_open(p, "wb") as f:
            f.write(b"partial")
            raise RuntimeError("boom")
    assert p.read_bytes() == b"\x00\x01"
    assert sorted(os.listdir(p.parent)) == ["a.txt"]  # no temp files left behind


# --------------------------------------------------------------------------------------------
# cameras


def test_camera_json_and_zip_round_trip(tmp_path):
    p = tmp_path / "camera_1.json"
    write_camera_json(p, {**CAMERA, "rotation_matrix": np.eye(3), "x_focal_length": np.float32(1500.0)})
    cam = read_camera_json(p)
    assert cam["rotation_matrix"] == np.eye(3).tolist() and cam["x_focal_length"] == 1500.0
    cams = {"10": cam, "2": CAMERA, "00001": {**CAMERA, "pan_degrees": 1.0 / 3.0}}
    z = tmp_path / "cameras.zip"
    write_camera_zip(z, cams)
    with zipfile.ZipFile(z) as zf:
        assert zf.namelist() == ["camera_00001.json", "camera_2.json", "camera_10.json"]
    back = read_camera_zip(z)
    assert back == cams and list(back) == ["00001", "2", "10"]
    # one nested folder is accepted too
    nested = tmp_path / "nested.zip"
    with zipfile.ZipFile(nested, "w") as zf:
        zf.writestr("preds/camera_5.json", json.dumps(CAMERA))
        zf.writestr("preds/readme.txt", "x")
    assert read_camera_zip(nested) == {"5": CAMERA}


@pytest.mark.parametrize("missing", list(CAMERA))
def test_camera_missing_key(tmp_path, missing):
    p = tmp_path / "camera_3.json"
    write_json(p, {k: v for k, v in CAMERA.items() if k != missing})
    with pytest.raises(DataError) as ei:
        read_camera_json(p)
    assert_one_line_error(ei, f"{p}: camera is missing key {missing!r}")


def test_camera_bad_values(tmp_path):
    z = tmp_path / "c.zip"
    with zipfile.ZipFile(z, "w") as zf:
        zf.writestr("camera_1.json", json.dumps({**CAMERA, "radial_distortion": [0.0] * 3}))
    with pytest.raises(DataError) as ei:
        read_camera_zip(z)
    assert_one_line_error(ei, f"{z}:camera_1.json", "'radial_distortion'", "6 numbers")
    with pytest.raises(DataError) as ei:
        write_camera_zip(tmp_path / "o.zip", {"1": {**CAMERA, "tilt_degrees": float("nan")}})
    assert_one_line_error(ei, "camera_1.json", "'tilt_degrees'", "not finite")
    assert not (tmp_path / "o.zip").exists()


# --------------------------------------------------------------------------------------------
# predictions and homographies: bad inputs


@pytest.mark.parametrize(
    "obj, needles",
    [
        ({"kp": {"74": {"x": 0.1, "y": 0.1, "p": 0.5}}, "lines": {}}, ["keypoint id 74 out of range", "1..73"]),
        ({"kp": {"0": {"x": 0.1, "y": 0.1, "p": 0.5}}, "lines": {}}, ["keypoint id 0 out of range"]),
        ({"kp": {}, "lines": {"24": {}}}, ["line id 24 out of range", "1..23"]),
        ({"kp": {"abc": {}}, "lines": {}}, ["keypoint id must be an integer", "'abc'"]),
        ({"kp": {"3": {"x": 0.1, "y": 0.1}}, "lines": {}}, ['"kp" id 3: missing "p"']),
        ({"kp": {"3": {"x": 0.1, "y": 0.1, "p": "hi"}}, "lines": {}}, ['"p" is not a number']),
        ({"kp": {"3": {"x": float("nan"), "y": 0.1, "p": 1}}, "lines": {}}, ["non-finite", "x = nan"]),
        ({"kp": {"3": {"x": 640.0, "y": 0.1, "p": 1}}, "lines": {}}, ["out of range", "x = 640"]),
        ({"kp": {}}, ['missing "lines"']),
        ({"kp": [], "lines": {}}, ['"kp" must be an object']),
        ([], ['expected a JSON object with "kp" and "lines"']),
    ],
)
def test_bad_predictions(tmp_path, obj, needles):
    z = tmp_path / "preds.zip"
    with zipfile.ZipFile(z, "w") as zf:
        zf.writestr("12.json", json.dumps(obj))
    with pytest.raises(DataError) as ei:
        read_predictions(z)
    assert_one_line_error(ei, f"{z}:12.json: ", *needles)


def test_predictions_folder_and_nested_zip(tmp_path):
    pred = Predictions(keypoints={1: (0.1, 0.2, 0.9)}, lines={23: (0.0, 0.5, 0.8, 1.0, 0.5, 0.7)})
    (tmp_path / "f").mkdir()
    write_json(tmp_path / "f" / "5.json", pred.to_json())
    assert read_predictions(tmp_path / "f") == {"5": pred}
    z = tmp_path / "n.zip"
    with zipfile.ZipFile(z, "w") as zf:
        zf.writestr("out/5.json", json.dumps(pred.to_json()))
    assert read_predictions(z) == {"5": pred}
    with pytest.raises(DataError) as ei:
        write_predictions(tmp_path / "bad.zip", {"1": Predictions(keypoints={80: (0.1, 0.1, 1.0)})})
    assert_one_line_error(ei, "bad.zip:1.json", "keypoint id 80")


def test_bad_homographies(tmp_path):
    p = tmp_path / "h.json"
    write_json(p, {"1": [[1, 0, 0], [0, 1, 0]]})
    with pytest.raises(DataError) as ei:
        read_homographies(p)
    assert_one_line_error(ei, str(p), "frame '1'", "3x3")
    p.write_text('{"1": [[1, 0, 0], [0, 1, 0], [0, 0, NaN]]}')
    with pytest.raises(DataError) as ei:
        read_homographies(p)
    assert_one_line_error(ei, str(p), "[2][2]", "not finite")


# --------------------------------------------------------------------------------------------
# property tests

PROP = settings(max_examples=100, deadline=None, database=None, suppress_health_check=[HealthCheck.too_slow])

coord = st.floats(min_value=-0.5, max_value=1.5, allow_nan=False, allow_infinity=False)
points = st.lists(st.tuples(coord, coord), min_size=2, max_size=8)
spellings = st.sampled_from(list(ALL_CLASSES) + ["Goal left post left"])


@PROP
@given(st.dictionaries(spellings, points, max_size=10))
def test_property_annotation_round_trip_exact(raw):
    ann = {k: np.array(v, dtype=np.float64).reshape(-1, 2) for k, v in raw.items()}
    if POST in ann and "Goal left post left" in ann:
        del ann["Goal left post left"]
    text = json.dumps(annotation_to_json(ann))
    back = parse_annotation_bytes(text, "prop.json", keep_unknown=True)
    assert len(back) == len(ann)
    for name, pts in ann.items():
        cls = POST if name.strip() == POST.strip() else name
        np.testing.assert_array_equal(back[cls], pts)
    assert "Goal left post left" not in json.loads(text)


kp_entry = st.fixed_dictionaries({"x": coord, "y": coord, "p": st.floats(0, 1)})
line_entry = st.fixed_dictionaries({k: (st.floats(0, 1) if k.startswith("p") else coord) for k in ("x_1", "y_1", "p_1", "x_2", "y_2", "p_2")})


@PROP
@given(
    st.dictionaries(st.integers(1, 73).map(str), kp_entry, max_size=20),
    st.dictionaries(st.integers(1, 23).map(str), line_entry, max_size=10),
)
def test_property_predictions_round_trip_exact(kp, lines):
    obj = {"kp": kp, "lines": lines}
    pred = parse_predictions_bytes(json.dumps(obj), "p.json")
    assert predictions_to_json(pred) == obj
    assert parse_predictions(json.loads(json.dumps(pred.to_json()))) == pred


json_scalars = (
    st.none()
    | st.booleans()
    | st.integers(min_value=-(10**400), max_value=10**400)
    | st.floats()
    | st.text(max_size=12)
)
json_values = st.recursive(
    json_scalars,
    lambda children: st.lists(children, max_size=4) | st.dictionaries(st.text(max_size=8), children, max_size=4),
    max_leaves=20,
)
near_point = st.dictionaries(st.sampled_from(["x", "y", "z"]), json_values, max_size=3)
near_annotation = st.dictionaries(
    spellings | st.text(max_size=20),
    st.lists(near_point | json_values, max_size=4) | json_values,
    max_size=4,
)
near_entry = st.dictionaries(st.sampled_from(["x", "y", "p", "x_1", "y_1", "p_1", "x_2", "y_2", "p_2"]), json_values, max_size=6)
near_ids = st.integers(-3, 80).map(str) | st.text(max_size=3) | st.integers(-3, 80)
near_predictions = st.fixed_dictionaries(
    {"kp": st.dictionaries(near_ids, near_entry | json_values, max_size=4) | json_values,
     "lines": st.dictionaries(near_ids, near_entry | json_values, max_size=4) | json_values}
) | json_values


def only_data_error(fn, *args) -> None:
    try:
        fn(*args)
    except DataError as e:
        assert "\n" not in str(e)
        assert str(e).startswith("g.json: ")


@PROP
@given(json_values | near_annotation)
def test_property_garbage_annotation_only_data_error(obj):
    only_data_error(parse_annotation, obj, "g.json")
    only_data_error(lambda o, s: parse_annotation(o, s, keep_unknown=True), obj, "g.json")


@PROP
@given(near_predictions)
def test_property_garbage_predictions_only_data_error(obj):
    only_data_error(parse_predictions, obj, "g.json")


@PROP
@given(st.binary(max_size=200) | st.text(max_size=200).map(str.encode))
def test_property_random_bytes_only_data_error(data):
    only_data_error(parse_annotation_bytes, data, "g.json")
    only_data_error(parse_predictions_bytes, data, "g.json")
    only_data_error(pdata.cameras.parse_camera_bytes, data, "g.json")
    only_data_error(decode_image, data, "g.json")


@PROP
@given(json_values)
def test_property_garbage_homographies_only_data_error(obj):
    only_data_error(pdata.parse_homographies, obj, "g.json")
    only_data_error(pdata.validate_camera_dict, obj, "g.json")
