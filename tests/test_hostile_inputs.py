"""Hostile inputs, round two (scripts/hostile.py runs them all against the command line): files
that are not files, outputs that are not files, write failures, impossible values, training that
fails, and the smaller ones. Every FIFO test runs under an alarm: a hang fails, it never blocks."""

from __future__ import annotations

import contextlib
import errno
import json
import logging
import math
import os
import shutil
import signal
import stat
import zipfile
from pathlib import Path

import numpy as np
import pytest

from pnlviz import EXAMPLES_DIR
from pnlviz.commands import main
from pnlviz.data import DataError, OutputError, open_dataset
from pnlviz.data.atomic import atomic_write_text
from pnlviz.data.cameras import validate_camera_dict
from pnlviz.data.errors import escape_controls

SAMPLE = EXAMPLES_DIR / "sample"


@contextlib.contextmanager
def no_hang(seconds: int = 10):
    """Fail instead of blocking (a FIFO opened for reading blocks until a writer comes)."""
    def alarm(signum, frame):
        raise AssertionError(f"blocked for {seconds} s")
    old = signal.signal(signal.SIGALRM, alarm)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


def sample_copy(dst: Path, stems=("00000", "00001", "00002")) -> Path:
    dst.mkdir(parents=True, exist_ok=True)
    for stem in stems:
        for suffix in (".json", ".jpg"):
            shutil.copy(SAMPLE / f"{stem}{suffix}", dst / f"{stem}{suffix}")
    return dst


def camera() -> dict:
    return json.loads((SAMPLE / "cameras" / "camera_00000.json").read_text())


# ------------------------------------------------------------------------------ not regular files
def test_a_fifo_or_a_device_is_refused_before_it_is_read(tmp_path):
    from pnlviz.data.reading import read_file

    fifo = tmp_path / "a.json"
    os.mkfifo(fifo)
    with no_hang(), pytest.raises(DataError, match="FIFO"):
        read_file(fifo)
    with no_hang(), pytest.raises(DataError, match="character device"):
        read_file("/dev/zero")
    with no_hang(), pytest.raises(DataError, match="FIFO"):
        open_dataset(fifo)


def test_a_cameras_zip_given_as_the_data_says_what_it_is(tmp_path, capsys):
    """pnlviz's own cameras (calibrate's output) given to --data read as 32 broken annotations
    ("unknown class 'pan_degrees'"), and a folder holding that zip alone as a dataset in splits."""
    cams = tmp_path / "out" / "cams.zip"
    cams.parent.mkdir()
    assert main(["calibrate", "--data", str(SAMPLE), "--out", str(cams), "--no-progress"]) == 0
    capsys.readouterr()
    for given in (cams, cams.parent):
        with pytest.raises(DataError, match=r"holds cameras \(camera_<stem>\.json"):
            open_dataset(given)
        assert main(["validate", "--data", str(given)]) != 0
        err = capsys.readouterr().err
        assert "holds cameras" in err and "pan_degrees" not in err
    assert len(open_dataset(SAMPLE)) == 33  # a dataset with its cameras/ beside the frames still opens


def test_a_symlink_loop_and_a_fifo_in_a_dataset_are_skipped_with_a_line(tmp_path):
    d = sample_copy(tmp_path / "d")
    os.symlink("b.json", d / "a.json")
    os.symlink("a.json", d / "b.json")
    os.symlink(".", d / "sub")
    os.mkfifo(d / "00009.json")
    with no_hang():
        ds = open_dataset(d)
        problems = [str(e) for e in ds.rejected]
        assert any("a.json" in p and "symbolic link loop" in p for p in problems)
        with pytest.raises(DataError, match="FIFO"):
            ds.annotation("00009")
        assert ds.annotation("00001")


def test_edit_records_that_are_devices_or_fifos_are_not_read(tmp_path):
    from pnlviz.data.edits import EditsStore

    frames = tmp_path / "edits" / "frames"
    frames.mkdir(parents=True)
    os.symlink("/dev/zero", frames / "00001.json")
    os.mkfifo(frames / "00002.json")
    with no_hang():
        store = EditsStore(tmp_path / "edits", writable=False)
    assert len(store.warnings) == 2 and "character device" in store.warnings[0] and "FIFO" in store.warnings[1]
    assert store.get("00001") == {} and store.get("00002") == {}


def test_a_fifo_sidecar_is_refused_not_ignored(tmp_path):
    from pnlviz.data import read_predictions_info

    os.mkfifo(tmp_path / "p.json")
    with no_hang(), pytest.raises(DataError, match="FIFO"):
        read_predictions_info(tmp_path / "p.zip")
    assert read_predictions_info(tmp_path / "none.zip") == {}


# ------------------------------------------------------------------------------ outputs
def test_outputs_that_are_not_regular_files_are_never_replaced(tmp_path):
    from pnlviz.data import check_output

    fifo = tmp_path / "out.csv"
    os.mkfifo(fifo)
    victim = tmp_path / "victim.txt"
    victim.write_text("keep")
    link = tmp_path / "link.csv"
    os.symlink(victim, link)
    for target in (fifo, link):
        with pytest.raises(OutputError, match="not a regular file"):
            check_output(target)
        with no_hang(), pytest.raises(OutputError):
            atomic_write_text(target, "x")
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode) and os.path.islink(link) and victim.read_text() == "keep"
    with pytest.raises(OutputError, match="not a regular file"):
        check_output("/dev/stdout", what="--csv")
    with pytest.raises(OutputError, match="not a folder"):
        check_output(victim, folder=True)
    assert not list(tmp_path.glob(".*.tmp"))


@pytest.mark.skipif(os.geteuid() != 0, reason="making a device node needs root")
def test_a_device_node_at_the_output_survives(tmp_path):
    node = tmp_path / "out.csv"
    os.mknod(node, 0o666 | stat.S_IFCHR, os.makedev(1, 3))  # like /dev/null
    with pytest.raises(OutputError, match="character device"):
        atomic_write_text(node, "x")
    assert stat.S_ISCHR(os.lstat(node).st_mode)


def test_an_unwritable_folder_is_refused_before_the_work(tmp_path, monkeypatch):
    from pnlviz.data import check_output

    monkeypatch.setattr(os, "access", lambda path, mode: False)
    with pytest.raises(OutputError, match="cannot write in"):
        check_output(tmp_path / "new" / "out.zip")


def test_a_write_failure_is_one_line_naming_the_output(tmp_path, monkeypatch, capsys):
    import tempfile

    from pnlviz.data.zipwriter import ZipStream

    def denied(*a, **k):
        raise PermissionError(errno.EACCES, "Permission denied")
    monkeypatch.setattr(tempfile, "mkstemp", denied)
    out = tmp_path / "sheet.png"
    assert main(["sheet", "--data", str(SAMPLE), "--out", str(out), "-n", "1"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"error: {out}: Permission denied"]
    with pytest.raises(PermissionError) as info:
        ZipStream(tmp_path / "d.zip")
    assert info.value.filename == str(tmp_path / "d.zip")
    monkeypatch.undo()

    def full(self, data):
        raise OSError(errno.ENOSPC, "No space left on device")
    with pytest.raises(OSError) as info, ZipStream(tmp_path / "c.zip") as zs:
        monkeypatch.setattr(zs._zip, "writestr", lambda *a, **k: full(None, None))
        zs.add("camera_1.json", "{}")
    assert info.value.filename == str(tmp_path / "c.zip") and info.value.errno == errno.ENOSPC


# ------------------------------------------------------------------------------ impossible values
@pytest.mark.parametrize("change, field", [
    ({"x_focal_length": 0.0}, "x_focal_length"), ({"y_focal_length": -900.0}, "y_focal_length"),
    ({"x_focal_length": 1e308}, "x_focal_length"), ({"position_meters": [1e308, 0, -10]}, "position_meters"),
    ({"radial_distortion": [1e12, 0, 0, 0, 0, 0]}, "radial_distortion"), ({"pan_degrees": 1e300}, "pan_degrees"),
    ({"principal_point": [0.0, 0.0]}, "principal_point"), ({"tilt_degrees": math.inf}, "tilt_degrees"),
])
def test_impossible_cameras_are_refused_naming_the_field(change, field):
    with pytest.raises(DataError, match=field):
        validate_camera_dict({**camera(), **change}, "cam.json")
    validate_camera_dict(camera(), "cam.json")  # the sample's camera is possible


def test_an_impossible_camera_is_named_by_every_reader(tmp_path, capsys):
    d = sample_copy(tmp_path / "d")
    (d / "cameras").mkdir()
    for stem in ("00000", "00001"):
        shutil.copy(SAMPLE / "cameras" / f"camera_{stem}.json", d / "cameras")
    (d / "cameras" / "camera_00001.json").write_text(json.dumps({**camera(), "principal_point": [0, 0]}))
    assert main(["validate", "--data", str(d)]) == 1
    printed = capsys.readouterr()
    assert "camera_00001.json: camera key 'principal_point' = 0 is impossible" in printed.out + printed.err
    assert main(["sheet", "--data", str(d), "--out", str(tmp_path / "s.png"), "-n", "2"]) == 0
    printed = capsys.readouterr()
    assert "camera_00001.json: camera key 'principal_point'" in printed.out + printed.err


@pytest.mark.parametrize("p", [-5.0, 1e308, float("nan"), 1.5])
def test_detection_probabilities_outside_0_1_are_refused(p):
    from pnlviz.data.predictions import parse_predictions

    with pytest.raises(DataError, match="probability"):
        parse_predictions({"kp": {"3": {"x": 0.1, "y": 0.5, "p": p}}, "lines": {}}, "p.json")
    assert parse_predictions({"kp": {"3": {"x": 0.1, "y": 0.5, "p": 1.0}}, "lines": {}}, "p.json").keypoints


@pytest.mark.parametrize("settings, match", [
    ({"alpha": 7.5}, "'alpha'"), ({"refine_k1": "maybe"}, "'refine_k1' must be true or false"),
    ({"no_such": 1}, "unknown calibration setting"), ({"final_loss": "l0"}, "'final_loss'"),
    ({"ransac_thresholds": [5, "x"]}, "'ransac_thresholds'"), ({"min_points": 2.5}, "'min_points'"),
    ({"max_rms": float("nan")}, "'max_rms'"), ({"class_tolerance_px": -1.0}, "'class_tolerance_px'"),
])
def test_detector_settings_are_checked_by_name_type_and_range(settings, match):
    from pnlviz.pipeline.settings import check_settings

    with pytest.raises(DataError, match=match):
        check_settings(settings, "preds.json")
    shipped = json.loads((EXAMPLES_DIR.parent / "assets" / "models" / "light.json").read_text())
    assert check_settings(shipped.get("calibration", {}), "light.json") == shipped.get("calibration", {})
    assert check_settings({"class_tolerance_px": 0.0}, "preds.json") == {"class_tolerance_px": 0.0}  # 0: off


def test_a_bad_sidecar_is_one_line_in_calibrate_and_export(tmp_path, capsys):
    from pnlviz.data.predictions import predictions_info_path

    preds = tmp_path / "p.zip"
    with zipfile.ZipFile(preds, "w") as zf:
        zf.writestr("00000.json", json.dumps({"kp": {}, "lines": {}}))
    predictions_info_path(preds).write_text(json.dumps({"calibration": {"alpha": 7.5, "refine_k1": "maybe"}}))
    d = sample_copy(tmp_path / "d", stems=("00000",))
    (tmp_path / "e" / "frames").mkdir(parents=True)  # an (empty) edits folder
    assert main(["calibrate", "--data", str(d), "--detections", str(preds), "--out", str(tmp_path / "c.zip"),
                 "--no-progress"]) == 2
    assert main(["export", "--data", str(d), "--detections", str(preds), "--out", str(tmp_path / "x"),
                 "--edits", str(tmp_path / "e"), "--no-progress"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and all("p.json: calibration setting 'alpha'" in line for line in err)
    assert not (tmp_path / "c.zip").exists()


def test_a_1x1_image_is_refused_by_the_rule_calibrate_uses():
    from pnlviz.calib.frame import FrameInputs
    from pnlviz.data.imagesize import check_pixels
    from pnlviz.data.limits import MIN_IMAGE_SIDE

    with pytest.raises(DataError, match="too small"):
        check_pixels(MIN_IMAGE_SIDE - 1, 100, "tiny.png")
    check_pixels(MIN_IMAGE_SIDE, MIN_IMAGE_SIDE, "small.png")
    with pytest.raises(ValueError):
        FrameInputs(size=(MIN_IMAGE_SIDE - 1, MIN_IMAGE_SIDE - 1))
    FrameInputs(size=(MIN_IMAGE_SIDE, MIN_IMAGE_SIDE))


# ------------------------------------------------------------------------------ training
@pytest.mark.parametrize("change, match", [
    ({"sigma": 0.0}, "sigma"), ({"input_size": [0, 0]}, "input_size"), ({"lr": "fast"}, "lr"),
    ({"epochs": -1}, "epochs"), ({"batch_size": 0}, "batch_size"), ({"kp_threshold": math.nan}, "kp_threshold"),
])
def test_training_configs_are_checked_by_type_and_range(change, match):
    from pnlviz.detect.train_config import TrainConfig

    base = json.loads((EXAMPLES_DIR.parent / "assets" / "models" / "light_config.json").read_text())
    TrainConfig.from_dict(base)
    with pytest.raises(ValueError, match=match):
        TrainConfig.from_dict({**base, **change})


def test_a_non_finite_loss_stops_training_without_a_checkpoint(tmp_path, monkeypatch):
    pytest.importorskip("torch")
    import torch

    from pnlviz.detect import train as train_mod
    from pnlviz.detect.train_config import TrainConfig

    cfg = TrainConfig.from_dict({"data": {"seed": 1, "frames": 2, "size": [64, 48]}, "input_size": [64, 48],
                                 "epochs": 1, "batch_size": 2, "threads": 1, "augment": {}})
    monkeypatch.setattr(train_mod, "loss_fn", lambda net, x, *a: (net(x)[0].sum() * torch.tensor(float("nan"))))
    out = tmp_path / "m.pt"
    with pytest.raises(ValueError, match="training diverged.*no checkpoint"):
        train_mod.train(cfg, out, progress=False, log=None)
    assert not out.exists()
    assert np.nextafter(0.0, 1.0) > 0  # the stopped run left subnormal numbers on (it flushes them while it runs)


@pytest.mark.parametrize("extra, match", [(["--minutes", "nan"], "--minutes"), (["--minutes", "inf"], "--minutes"),
                                          (["--data", str(SAMPLE), "--data-weight", "nan"], "--data-weight")])
def test_train_options_out_of_range_are_refused(tmp_path, capsys, extra, match):
    assert main(["train", "--out", str(tmp_path / "m.pt"), "--no-progress", *extra]) == 2
    assert match in capsys.readouterr().err
    assert not (tmp_path / "m.pt").exists()


def test_labels_for_training_must_be_a_complete_export(tmp_path):
    from pnlviz.detect.train_data import ExportedFrames

    garbage = tmp_path / "garbage.zip"
    garbage.write_bytes(os.urandom(2000))
    with pytest.raises(DataError, match="not a pnlviz export"):
        ExportedFrames(garbage, SAMPLE)
    partial = tmp_path / "partial"
    (partial / "keypoints").mkdir(parents=True)
    (partial / "keypoints" / "00000.json").write_text("{}")
    with pytest.raises(DataError, match="no manifest"):
        ExportedFrames(partial, SAMPLE)


def test_synth_size_is_capped_by_memory_and_the_pixel_cap(monkeypatch):
    from pnlviz.commands import synth

    assert "megapixels" in synth.size_problem((16384, 16384), 1)
    assert synth.size_problem((960, 540), 1) is None
    monkeypatch.setattr(synth, "available_memory", lambda: 500 * 2**20)
    assert "needs about" in synth.size_problem((3840, 2160), 1)


# ------------------------------------------------------------------------------ smaller
def test_control_characters_in_names_are_printed_escaped(tmp_path, capsys):
    assert escape_controls("a\x1b[2Jb\x07\x9b\tc\n") == "a\\x1b[2Jb\\x07\\x9b\tc\n"
    assert str(DataError("x\x1b]0;owned\x07.json", "bad")) == "x\\x1b]0;owned\\x07.json: bad"
    d = sample_copy(tmp_path / "d", stems=("00000",))
    (d / "\x1b[2Jevil.json").write_text("{broken")
    main(["validate", "--data", str(d)])
    out = capsys.readouterr()
    assert "\x1b" not in out.out + out.err and "\\x1b[2Jevil.json" in out.out + out.err


def test_a_jpeg_or_junk_named_mp4_and_a_fifo_video_are_refused(tmp_path):
    from pnlviz.data.video import VideoDataset

    jpeg = tmp_path / "photo.mp4"
    shutil.copy(SAMPLE / "00000.jpg", jpeg)
    junk = tmp_path / "junk.mp4"
    junk.write_bytes(np.random.default_rng(0).bytes(5000))
    fifo = tmp_path / "clip.mp4"
    os.mkfifo(fifo)
    with pytest.raises(DataError, match="JPEG image, not a video"):
        VideoDataset(jpeg)
    with pytest.raises(DataError, match="cannot open"):
        VideoDataset(junk)
    with no_hang(), pytest.raises(DataError, match="FIFO"):
        VideoDataset(fifo)


@pytest.mark.parametrize("kid", [5.5, True, "7", 7.0, None, np.float64(7)])
def test_keypoint_ids_of_the_wrong_type_are_refused_not_coerced(kid):
    from pnlviz.data.edits import EditError, check_keypoint_id

    with pytest.raises(EditError, match="must be an integer"):
        check_keypoint_id(kid)
    assert check_keypoint_id(7) == 7 and check_keypoint_id(np.int64(7)) == 7


def test_failed_handshakes_of_bare_connections_are_not_logged(caplog):
    from pnlviz.commands.serve import _quiet_handshakes

    _quiet_handshakes()
    log = logging.getLogger("websockets.server")
    with caplog.at_level(logging.INFO, logger="websockets.server"):
        try:
            raise EOFError("connection closed while reading HTTP request line")
        except EOFError:
            log.error("opening handshake failed", exc_info=True)
        log.error("something else")
    assert [r.getMessage() for r in caplog.records] == ["something else"]
