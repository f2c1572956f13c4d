"""Batch commands: bad frames are reported in one line and skipped, the rest goes on."""

import json
import shutil

import cv2
import numpy as np
import pytest

from pnlviz import EXAMPLES_DIR
from pnlviz.cli import main, parse_size


@pytest.fixture()
def small_dataset(tmp_path):
    """Four sample frames plus one corrupt annotation, one unknown class and one broken image."""
    src = EXAMPLES_DIR / "sample"
    ds = tmp_path / "ds"
    (ds / "cameras").mkdir(parents=True)
    for stem in ("00000", "00001", "00002", "00003"):
        shutil.copy(src / "cameras" / f"camera_{stem}.json", ds / "cameras" / f"camera_{stem}.json")
        shutil.copy(src / f"{stem}.jpg", ds / f"{stem}.jpg")
        shutil.copy(src / f"{stem}.json", ds / f"{stem}.json")
    (ds / "00004.json").write_text('{"Side line top": [{"x": 0.1, "y": 0.2}, ')  # truncated
    (ds / "00005.json").write_text(json.dumps({"Big rect left mian": [{"x": 0.1, "y": 0.2}, {"x": 0.3, "y": 0.2}]}))
    (ds / "00006.jpg").write_bytes(b"not a jpeg at all")
    return ds


def test_validate_reports_each_bad_file_in_one_line_and_fails(small_dataset, capsys):
    assert main(["validate", "--data", str(small_dataset), "--images"]) == 1
    out, err = capsys.readouterr()
    assert "7 frames, 4 valid annotations, 5 images" in out
    lines = [line.strip() for line in err.splitlines() if "0000" in line]
    assert len(lines) == 3
    assert any("00004.json" in line and "JSON" in line.upper() for line in lines)
    assert any("00005.json" in line and "Big rect. left main" in line for line in lines)
    assert any("00006.jpg" in line for line in lines)


def test_validate_passes_on_the_bundled_sample(capsys):
    assert main(["validate", "--data", str(EXAMPLES_DIR / "sample")]) == 0
    assert "33 frames, 32 valid annotations" in capsys.readouterr().out


def test_sheet_skips_bad_frames_and_draws_the_rest(small_dataset, tmp_path, capsys):
    out = tmp_path / "sheet.png"
    assert main(["sheet", "--data", str(small_dataset), "--out", str(out), "--columns", "3", "--tile-width", "200"]) == 0
    img = cv2.imread(str(out))
    assert img is not None and img.shape[1] == 3 * 200 + 4 * 4
    err = capsys.readouterr().err
    assert err.count("skipped:") == 3
    # without the annotations on top, the ground-truth pitch shows in amber on the synthetic frames
    assert main(["sheet", "--data", str(small_dataset), "--out", str(out), "--no-annotation"]) == 0
    img = cv2.imread(str(out)).astype(int)
    amber = (np.abs(img - [60, 220, 255]).sum(axis=2) < 90).sum()
    assert amber > 2000


def test_calibrate_goes_on_past_bad_frames(small_dataset, tmp_path, capsys):
    out = tmp_path / "cams.zip"
    assert main(["calibrate", "--data", str(small_dataset), "--out", str(out), "--no-progress"]) == 0
    text = capsys.readouterr()
    assert "calibrated 4/6 frames" in text.out
    assert "00004.json" in text.err and "00005.json" in text.err


def test_missing_dataset_is_one_line_error(tmp_path, capsys):
    assert main(["validate", "--data", str(tmp_path / "nope")]) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith("error:") and "nope" in err and "\n" not in err


def test_parse_size():
    assert parse_size("960x540") == (960, 540)
    with pytest.raises(Exception, match="WIDTHxHEIGHT"):
        parse_size("960")


def test_calibration_settings_defaults_then_detector_then_flags():
    """The defaults; the settings recorded with the detections on top, for frames calibrated
    from detections; the command line flags last (--no-k1, --no-pnl win)."""
    import argparse

    from pnlviz.calib.calibrate import CalibParams
    from pnlviz.calib.frame import calib_params
    from pnlviz.commands.calibrate import add_calibrate_parser, frame_settings

    ap = argparse.ArgumentParser()
    add_calibrate_parser(ap.add_subparsers())
    base = ["calibrate", "--data", "d", "--out", "c.zip"]
    assert calib_params(frame_settings(ap.parse_args(base)), "annotation") == CalibParams()
    recorded = {"final_loss": "soft_l1", "ransac_thresholds": [5, 10]}
    settings = frame_settings(ap.parse_args(base + ["--alpha", "0.3"]), recorded)
    got = calib_params(settings, "detections")
    assert got == CalibParams(alpha=0.3, final_loss="soft_l1", ransac_thresholds=(5, 10)) and got.refine_k1
    assert calib_params(settings, "annotation") == CalibParams(alpha=0.3)  # an annotation: not the detector's
    assert not calib_params(frame_settings(ap.parse_args(base + ["--no-k1"]), recorded), "detections").refine_k1
    assert not calib_params(frame_settings(ap.parse_args(base + ["--no-pnl"]), {"pnl": True}), "detections").pnl
    with pytest.raises(ValueError, match="unknown calibration setting"):
        calib_params(frame_settings(ap.parse_args(base), {"k_one": 0.1}), "detections")


def test_calibrate_takes_a_prediction_zip_alone(shared_dir, tmp_path, capsys):
    """``--detections`` without ``--data``: every frame of the zip calibrated at ``--size``, the same
    cameras as with a dataset that has no images (annotations are not used for detected frames)."""
    import zipfile

    half = shared_dir / "data" / "wc14_test_half"
    alone, with_data = tmp_path / "alone.zip", tmp_path / "with_data.zip"
    assert main(["calibrate", "--detections", str(half / "detections_pnlcalib.zip"), "--size", "1280x720",
                 "--out", str(alone), "--no-progress"]) == 0
    assert "calibrated at 1280x720 (--size)" in capsys.readouterr().out
    assert main(["calibrate", "--data", str(half / "annotations.zip"), "--detections",
                 str(half / "detections_pnlcalib.zip"), "--size", "1280x720", "--out", str(with_data),
                 "--no-progress"]) == 0
    with zipfile.ZipFile(alone) as a, zipfile.ZipFile(with_data) as b:
        assert len(a.namelist()) > 80 and a.namelist() == b.namelist()
        assert all(a.read(n) == b.read(n) for n in a.namelist())
    capsys.readouterr()
    assert main(["calibrate", "--out", str(tmp_path / "none.zip"), "--no-progress"]) == 2
    assert "give --data" in capsys.readouterr().err
