"""Datasets as SoccerNet ships them: split folders, split zips, a zip of split folders. Every
command keeps the split in its outputs (``<split>/<stem>``), and reads its outputs back."""

import json
import pickle
import shutil
import urllib.request
import zipfile

import numpy as np
import pytest

from pnlviz import EXAMPLES_DIR
from pnlviz.cli import main
from pnlviz.data import DataError, SplitDataset, open_dataset, read_cameras, read_predictions, write_predictions
from pnlviz.data.layout import keyed_members
from pnlviz.data.predictions import Predictions

SAMPLE = EXAMPLES_DIR / "sample"
TRAIN, VALID = ("00000", "00001", "00002"), ("00003", "00004")


def _copy(stems, folder):
    folder.mkdir(parents=True)
    for stem in stems:
        for ext in (".jpg", ".json"):
            shutil.copy(SAMPLE / f"{stem}{ext}", folder / f"{stem}{ext}")


def _zip(folder, out, prefix=""):
    with zipfile.ZipFile(out, "w") as zf:
        for p in sorted(folder.rglob("*")):
            if p.is_file():
                zf.write(p, prefix + p.relative_to(folder).as_posix())


@pytest.fixture()
def layouts(tmp_path):
    """The three layouts of the same five frames: split folders, split zips, one zip of split folders."""
    folders = tmp_path / "sn23"
    _copy(TRAIN, folders / "train")
    _copy(VALID, folders / "valid")
    zips = tmp_path / "zips"
    zips.mkdir()
    _zip(folders / "train", zips / "train.zip")
    _zip(folders / "valid", zips / "valid.zip")
    whole = tmp_path / "sn23.zip"
    _zip(folders, whole, prefix="sn23/")
    return {"folders": folders, "zips": zips, "zip": whole}


EXPECTED = [f"train/{s}" for s in TRAIN] + [f"valid/{s}" for s in VALID]


@pytest.mark.parametrize("layout", ["folders", "zips", "zip"])
def test_each_layout_is_one_dataset_with_split_stems(layouts, layout):
    ds = open_dataset(layouts[layout])
    assert isinstance(ds, SplitDataset) and ds.splits == ("train", "valid")
    assert list(ds.stems) == EXPECTED and not ds.rejected
    plain = open_dataset(SAMPLE)
    for stem in ("train/00001", "valid/00004"):
        base = stem.split("/")[1]
        assert ds.frame(stem).stem == stem and ds.frame(stem).has_image
        assert np.array_equal(ds.image(stem), plain.image(base))
        assert ds.image_size(stem) == plain.image_size(base)
        assert ds.annotation(stem).keys() == plain.annotation(base).keys()
    assert [s for s, _ in ds.iter_annotations()] == EXPECTED
    again = pickle.loads(pickle.dumps(ds))  # the batch runner's workers get it pickled
    assert np.array_equal(again.image("valid/00003"), plain.image("00003"))
    with pytest.raises(KeyError):
        ds.frame("00001")  # a stem without its split is not a frame of a dataset in splits


def test_each_split_keeps_its_ground_truth_cameras(tmp_path):
    """Synthetic splits carry cameras/camera_<stem>.json: they are the split's, not a split."""
    from pnlviz.synth.writer import write_frame

    root = tmp_path / "synth"
    stems = {split: write_frame(root / split, 1, seed, (320, 180)) for split, seed in (("train", 1), ("valid", 2))}
    whole = tmp_path / "synth.zip"
    _zip(root, whole, prefix="synth/")
    expected = [f"{split}/{stem}" for split, stem in stems.items()]
    for data in (root, whole):
        ds = open_dataset(data)
        assert ds.splits == ("train", "valid") and list(ds.stems) == expected
        assert list(ds.camera_stems()) == expected
        camera = root / "valid" / "cameras" / f"camera_{stems['valid']}.json"
        assert ds.camera_dict(expected[1]) == json.loads(camera.read_text())


def test_what_is_not_a_split(tmp_path, layouts):
    # one subfolder alone is a plain dataset, as before
    one = tmp_path / "one"
    _copy(TRAIN, one / "train")
    ds = open_dataset(one)
    assert ds.splits == () and list(ds.stems) == list(TRAIN)
    # a subfolder without frames is left out; a split twice (folder and zip): the folder wins, said
    mixed = tmp_path / "mixed"
    shutil.copytree(layouts["folders"], mixed)
    (mixed / "docs").mkdir()
    (mixed / "docs" / "readme.txt").write_text("not frames")
    shutil.copy(layouts["zips"] / "valid.zip", mixed / "valid.zip")
    (mixed / "test.zip").write_bytes(b"not a zip")
    ds = open_dataset(mixed)
    assert ds.splits == ("train", "valid") and list(ds.stems) == EXPECTED
    problems = [str(e) for e in ds.rejected]
    assert any("valid.zip" in p and "another split named 'valid'" in p for p in problems)
    assert any("test.zip" in p and "split 'test' cannot be read" in p for p in problems)


def test_outputs_are_read_back_by_split():
    by_folder = {"": [("a", "a.json")], "valid/": [("1", "valid/1.json")]}
    assert keyed_members(by_folder)[0] == [("a", "a.json")]  # top level wins, as before
    assert keyed_members(by_folder)[1] is not None  # and says what it left out
    assert keyed_members(by_folder, splits=("valid",))[0] == [("a", "a.json"), ("valid/1", "valid/1.json")]
    assert keyed_members({"preds/": [("1", "preds/1.json")]})[0] == [("1", "preds/1.json")]  # a zipped folder
    two = {"w/train/": [("1", "w/train/1.json")], "w/valid/": [("1", "w/valid/1.json")]}
    assert keyed_members(two)[0] == [("train/1", "w/train/1.json"), ("valid/1", "w/valid/1.json")]
    # one split's output alone: named by the dataset's splits
    assert keyed_members({"valid/": [("1", "valid/1.json")]}, splits=("train", "valid"))[0] == [("valid/1", "valid/1.json")]


def test_prediction_zips_keep_the_split(tmp_path):
    pred = Predictions(keypoints={1: (0.5, 0.5, 0.9)}, lines={})
    out = tmp_path / "preds.zip"
    write_predictions(out, {"train/00001": pred, "valid/00003": pred})
    assert sorted(zipfile.ZipFile(out).namelist()) == ["train/00001.json", "valid/00003.json"]
    assert list(read_predictions(out)) == ["train/00001", "valid/00003"]
    only_valid = tmp_path / "valid_only.zip"
    write_predictions(only_valid, {"valid/00003": pred})
    assert list(read_predictions(only_valid)) == ["00003"]  # alone, a folder is a zipped folder...
    assert list(read_predictions(only_valid, splits=("train", "valid"))) == ["valid/00003"]  # ...unless a split


def test_commands_keep_the_split_in_every_output(layouts, tmp_path, capsys):
    data = layouts["zips"]
    assert main(["validate", "--data", str(data)]) == 0
    out = capsys.readouterr().out
    assert "5 frames" in out and "split train: 3 frames (train.zip)" in out and "split valid: 2 frames" in out

    cams = tmp_path / "cams.zip"
    assert main(["calibrate", "--data", str(data), "--out", str(cams), "--no-progress"]) == 0
    names = sorted(zipfile.ZipFile(cams).namelist())
    assert names == [f"{s.split('/')[0]}/camera_{s.split('/')[1]}.json" for s in EXPECTED]
    # split folders: the same frames, the same names
    assert main(["validate", "--data", str(layouts["folders"])]) == 0
    assert "split train: 3 frames" in capsys.readouterr().out
    from_folders = tmp_path / "cams_folders.zip"
    assert main(["calibrate", "--data", str(layouts["folders"]), "--out", str(from_folders), "--no-progress"]) == 0
    assert sorted(zipfile.ZipFile(from_folders).namelist()) == names
    capsys.readouterr()
    assert main(["eval", "--gt", str(layouts["zip"]), "--pred", str(cams), "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "frames 5, calibrated 5" in out
    assert "split train: frames 3, CR 1.0000" in out and "split valid: frames 2, CR 1.0000" in out

    labels = tmp_path / "labels"
    assert main(["labels", "--data", str(layouts["folders"]), "--out", str(labels)]) == 0
    assert sorted(p.relative_to(labels).as_posix() for p in labels.rglob("*.json")) == [f"{s}.json" for s in EXPECTED]
    capsys.readouterr()
    assert main(["labels", "--data", str(layouts["folders"]), "--out", str(labels), "--resume"]) == 0  # all done
    assert "5 frames already labelled" in capsys.readouterr().out


def test_detect_keeps_the_split_of_split_folders(layouts, tmp_path):
    pytest.importorskip("torch")
    preds = tmp_path / "preds.zip"
    assert main(["detect", "--data", str(layouts["folders"]), "--out", str(preds), "--threads", "1",
                 "--no-progress"]) == 0
    assert sorted(zipfile.ZipFile(preds).namelist()) == sorted(f"{s}.json" for s in EXPECTED)
    assert sorted(read_predictions(preds, splits=("train", "valid"))) == sorted(EXPECTED)


def test_export_keeps_the_split_and_gives_each_frame_its_homography(layouts, tmp_path):
    out = tmp_path / "export"
    assert main(["export", "--data", str(layouts["zip"]), "--out", str(out),
                 "--all", "--no-progress"]) == 0
    assert (out / "annotations" / "valid" / "00004.json").is_file()
    assert (out / "cameras" / "train" / "camera_00001.json").is_file()
    manifest = json.loads((out / "manifest.json").read_text())
    assert list(manifest["frames"]) == EXPECTED
    homographies = json.loads((out / "homographies.json").read_text())
    assert list(homographies) == EXPECTED
    # the homography maps the pitch (metres) to the frame's pixels: through it, each exported
    # ground keypoint lands where its label is (the sample's cameras have little distortion)
    from pnlviz import keypoints

    world = keypoints()
    kp = json.loads((out / "keypoints" / "valid" / "00004.json").read_text())
    H = np.array(kp["homography"])
    assert np.allclose(H, homographies["valid/00004"])
    ground = [(int(k), v) for k, v in kp["keypoints"].items() if v["visible"] and abs(world[int(k)][2]) < 1e-9]
    assert len(ground) >= 4
    err = []
    for kid, v in ground:
        x, y, _ = world[kid]
        p = H @ np.array([x, y, 1.0])
        err.append(np.hypot(p[0] / p[2] - v["x"], p[1] / p[2] - v["y"]))
    assert np.median(err) < 3.0, err
    cams, problems = read_cameras(out / "cameras", splits=("train", "valid"))
    assert list(cams) == EXPECTED and not problems


def test_serve_opens_split_zips_and_filters_by_split(layouts, serve):
    app = serve(layouts["zips"])
    with urllib.request.urlopen(app.url, timeout=30) as r:
        assert r.status == 200
    tab = app.session()
    p = tab.panels
    assert p.split is not None and p.split.options == ("all", "train", "valid")
    tab.goto(app.state.find("valid/00003"))
    assert "valid/00003" in p.title.content
    p.split.value = "train"
    tab.flush()
    assert [app.state.stems[i] for i in tab.frames.order] == [f"train/{s}" for s in TRAIN]
    assert "train/00000" in p.title.content and "1/3 of 'split train'" in p.title.content
    tab.editor.review("accepted")
    tab.flush()
    edits = app.state.edits.root / "frames" / "train" / "00000.json"
    assert json.loads(edits.read_text())["review"] == "accepted"


def test_serve_opens_split_folders(layouts, serve):
    app = serve(layouts["folders"])
    tab = app.session()
    assert tab.panels.split is not None and tab.stem in EXPECTED


def test_a_dataset_without_frames_says_where_frames_may_be(tmp_path):
    (tmp_path / "empty" / "a").mkdir(parents=True)
    (tmp_path / "empty" / "b").mkdir()
    ds = open_dataset(tmp_path / "empty")
    with pytest.raises(DataError, match="split folders or zips"):
        ds.require_frames()
