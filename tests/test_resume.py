"""Resumable batches (issue #15): a killed or interrupted `pnlviz calibrate` / `pnlviz detect`
restarts with --resume and does only the frames missing from its output; the output under its
name is valid at every moment."""

import json
import os
import signal
import subprocess
import sys
import time
import zipfile

import pytest

from helpers import copy_sample_frames, sn22_first
from pnlviz.cli import main
from pnlviz.data.zipwriter import ZipStream, journal_path, resume_members


def test_a_journal_keeps_what_a_killed_stream_wrote(tmp_path):
    out = tmp_path / "cams.zip"
    z = ZipStream(out, journal=True)
    z.add("camera_a.json", '{"x": 1}')
    z.add("camera_b.json", b"\x00\x01binary")
    # killed here: never closed; the journal is on disk, the output is not there (nothing half-written)
    assert not out.exists() and journal_path(out).is_file()
    with open(journal_path(out), "a") as f:
        f.write('{"name": "camera_c.json", "te')  # a line the kill cut short
    done = resume_members(out)
    assert done == {"camera_a.json": '{"x": 1}', "camera_b.json": b"\x00\x01binary"}
    z.close()  # a clean end removes the journal
    assert out.is_file() and not journal_path(out).exists()
    assert resume_members(out)["camera_a.json"] == '{"x": 1}'
    (tmp_path / "bad.zip").write_text("not a zip")
    with pytest.raises(ValueError, match="cannot resume"):
        resume_members(tmp_path / "bad.zip")


def _members(path):
    with zipfile.ZipFile(path) as z:
        return {n: z.read(n) for n in z.namelist()}


#: frames of the SN22 runs that are stopped and resumed (the first of the 400: enough to stop one midway)
RUN = 200


def test_calibrate_killed_then_resumed_does_only_the_missing_frames(tmp_path, shared_dir):
    gt = sn22_first(shared_dir, tmp_path / "sn22.zip", RUN)
    full, out = tmp_path / "full.zip", tmp_path / "cams.zip"
    assert main(["calibrate", "--data", str(gt), "--out", str(full), "--no-progress"]) == 0
    cmd = [sys.executable, "-m", "pnlviz", "calibrate", "--data", str(gt), "--out", str(out), "--no-progress"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:  # kill -9 once some frames are done
        j = journal_path(out)
        if j.is_file() and j.read_text().count("\n") >= 40:
            break
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert not out.exists()  # never a half-written output under its name
    partial = len(resume_members(out))
    assert 40 <= partial < len(_members(full))
    r = subprocess.run(cmd + ["--resume"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert f"resuming: {partial} of {RUN} frames already in cams.zip, {RUN - partial} to calibrate" in r.stdout
    assert _members(out) == _members(full)  # the same cameras, in the same order
    assert not journal_path(out).exists() and not list(tmp_path.glob(".cams.zip.*.tmp"))
    # resuming a finished run only retries the frames that got no camera
    n = len(_members(full))
    r = subprocess.run(cmd + ["--resume"], capture_output=True, text=True, timeout=300)
    assert f"resuming: {n} of {RUN} frames already in cams.zip, {RUN - n} to calibrate" in r.stdout
    assert _members(out) == _members(full)


def test_calibrate_stopped_by_ctrl_c_resumes_from_its_output(tmp_path, shared_dir):
    gt = sn22_first(shared_dir, tmp_path / "sn22.zip", RUN)
    out = tmp_path / "cams.zip"
    cmd = [sys.executable, "-m", "pnlviz", "calibrate", "--data", str(gt), "--out", str(out), "--no-progress"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        j = journal_path(out)
        if j.is_file() and j.read_text().count("\n") >= 20:
            break
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130 and "interrupted: kept" in err
    kept = len(_members(out))
    assert 20 <= kept < RUN and not journal_path(out).exists()
    r = subprocess.run(cmd + ["--resume"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0 and f"resuming: {kept} of {RUN}" in r.stdout
    assert len(_members(out)) > kept
    assert main(["calibrate", "--data", str(gt), "--out", str(out), "--resume", "--temporal"]) == 2


def test_detect_resume_detects_only_the_missing_frames(tmp_path, capsys):
    pytest.importorskip("torch")
    frames = copy_sample_frames(tmp_path / "frames", 3)
    out = tmp_path / "preds.zip"
    assert main(["detect", "--data", str(frames), "--out", str(out), "--no-progress", "--threads", "1"]) == 0
    full = _members(out)
    # as if the run had been killed after two frames: the journal of those two, no output
    os.unlink(out)
    with open(journal_path(out), "w") as f:
        for name in ("00000.json", "00002.json"):
            f.write(json.dumps({"name": name, "text": full[name].decode()}) + "\n")
    capsys.readouterr()
    assert main(["detect", "--data", str(frames), "--out", str(out), "--no-progress", "--threads", "1",
                 "--resume"]) == 0
    said = capsys.readouterr().out
    assert "resuming: 2 of 3 frames already in preds.zip, 1 to detect" in said and "detected 3/3" in said
    assert _members(out) == full
    # without --resume a leftover journal is named, and the run starts over
    with open(journal_path(out), "w") as f:
        f.write(json.dumps({"name": "00000.json", "text": "{}"}) + "\n")
    assert main(["detect", "--data", str(frames), "--out", str(out), "--no-progress", "--threads", "1"]) == 0
    assert "starting over (--resume continues it)" in capsys.readouterr().err and _members(out) == full
