"""pnlviz detect: weights saved -> command line -> the same detections as in process; clear errors."""

import json
import shutil

import pytest

torch = pytest.importorskip("torch")

from helpers import copy_sample_frames  # noqa: E402
from pnlviz.cli import main  # noqa: E402
from pnlviz.data import open_dataset, predictions_info_path, read_predictions, read_predictions_info  # noqa: E402


@pytest.fixture()
def frames(tmp_path):
    return copy_sample_frames(tmp_path / "frames", 2)


def test_round_trip_save_detect_same_predictions(frames, tmp_path):
    from pnlviz.detect.checkpoint import save_checkpoint
    from pnlviz.detect.hrnet import keypoint_net, line_net
    from pnlviz.detect.run import Detector

    torch.manual_seed(0)
    kp, lines = keypoint_net().eval(), line_net().eval()
    save_checkpoint(kp, tmp_path / "kp.pt")
    save_checkpoint(lines, tmp_path / "lines.pt")
    out = tmp_path / "preds.zip"
    assert main(["detect", "--data", str(frames), "--out", str(out), "--weights-kp", str(tmp_path / "kp.pt"),
                 "--weights-lines", str(tmp_path / "lines.pt"), "--input-size", "224x128", "--kp-threshold", "0",
                 "--threads", "2", "--no-progress", "--settings", str(predictions_info_path(out))]) == 0
    got = read_predictions(out)
    det = Detector(kp, lines, input_size=(224, 128), kp_threshold=0.0)
    ds = open_dataset(frames)
    expected = det.detect([ds.image(s) for s in ds.stems])
    assert set(got) == {"00000", "00001"}
    for stem, exp in zip(ds.stems, expected):
        assert got[stem].keypoints.keys() == exp.keypoints.keys() and len(exp.keypoints) == 57
        for k, v in exp.keypoints.items():
            assert got[stem].keypoints[k] == pytest.approx(v, abs=1e-4)  # torch thread counts reorder sums
        assert got[stem].lines.keys() == exp.lines.keys()
    info = read_predictions_info(out)  # the provenance beside the zip: published networks, no overrides
    assert info["detector"] == "PnLCalib networks" and info["calibration"] == {} and info["frames"] == 2
    assert info["weights"] == {"kp": str(tmp_path / "kp.pt"), "lines": str(tmp_path / "lines.pt")}


def test_no_weights_and_wrong_weights_are_clear_errors(frames, tmp_path, capsys, monkeypatch):
    import pnlviz.detect.run as run
    from pnlviz.detect.checkpoint import save_checkpoint
    from pnlviz.detect.hrnet import line_net

    monkeypatch.setattr(run, "DEFAULT_MODEL", tmp_path / "missing.pt")  # no default model installed
    assert main(["detect", "--data", str(frames), "--out", str(tmp_path / "p.zip"), "--no-progress"]) == 2
    assert "no detector weights" in capsys.readouterr().err
    save_checkpoint(line_net(), tmp_path / "lines.pt")
    assert main(["detect", "--data", str(frames), "--out", str(tmp_path / "p.zip"), "--weights-kp",
                 str(tmp_path / "lines.pt"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "head.0.3.weight" in err and "Traceback" not in err


def test_the_app_runs_the_detector_on_demand(frames, tmp_path):
    from pnlviz.app.state import AppState
    from pnlviz.detect.hrnet import keypoint_net, line_net
    from pnlviz.detect.run import Detector

    torch.manual_seed(0)
    det = Detector(keypoint_net().eval(), line_net().eval(), input_size=(224, 128), kp_threshold=0.0)
    st = AppState(frames, edits=tmp_path / "edits", detector=det)
    assert st.default_settings.source == "both" and st.needs_detection("00000")
    before = st.view("00000")
    assert before.detections is None
    st.run_detector("00000")
    assert not st.needs_detection("00000")
    after = st.view("00000")
    assert after.detections is not None and len(after.detections.keypoints) == 57
    assert after.observations is not None and after.observations.n_keypoints > 0


def test_detections_carry_the_detectors_calibration_settings(frames, tmp_path, capsys):
    """`pnlviz detect` with the light model names its calibration settings and writes them only
    when asked (--settings FILE); `pnlviz calibrate --detections` applies them when named
    (--detector-settings) or beside the zip (preds.json), and says so; a bad file is a one-line
    error."""
    from pnlviz.detect.light import read_sidecar
    from pnlviz.detect.run import DEFAULT_MODEL

    out = tmp_path / "preds.zip"
    assert main(["detect", "--data", str(frames), "--out", str(out), "--no-progress"]) == 0
    settings = read_sidecar(DEFAULT_MODEL)["calibration"]
    # nothing written that was not asked: the settings are named, and kept only with --settings
    assert sorted(p.name for p in tmp_path.iterdir()) == ["frames", "preds.zip"]
    said = capsys.readouterr().out
    assert "--settings FILE keeps them" in said and all(f"{k} {v}" in said for k, v in settings.items())
    elsewhere = tmp_path / "detector.json"
    assert main(["detect", "--data", str(frames), "--out", str(out), "--no-progress", "--settings",
                 str(elsewhere)]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["detector.json", "frames", "preds.zip"]
    info = read_predictions_info(out, elsewhere)
    assert info["detector"] == "light default model" and info["calibration"] == settings and settings
    assert read_predictions_info(out) == {}  # not beside the zip: applied only when named
    capsys.readouterr()
    assert main(["calibrate", "--data", str(frames), "--detections", str(out), "--detector-settings", str(elsewhere),
                 "--out", str(tmp_path / "c0.zip"), "--no-progress"]) == 0
    said = capsys.readouterr().out
    assert "detector.json" in said and all(f"{k}={v}" in said for k, v in settings.items())
    assert main(["calibrate", "--data", str(frames), "--detections", str(out), "--detector-settings",
                 str(tmp_path / "none.json"), "--out", str(tmp_path / "c1.zip"), "--no-progress"]) == 2
    assert "none.json: no such file" in capsys.readouterr().err and not (tmp_path / "c1.zip").exists()
    elsewhere.rename(predictions_info_path(out))  # beside the zip, with its name: applied by itself
    calibrate = ["calibrate", "--data", str(frames), "--detections", str(out), "--out", str(tmp_path / "c.zip"),
                 "--no-progress"]
    assert main(calibrate) == 0
    said = capsys.readouterr().out
    assert "preds.json" in said and all(f"{k}={v}" in said for k, v in settings.items())
    predictions_info_path(out).write_text(json.dumps({"calibration": {"k_one": 0.1}}))
    assert main(calibrate) == 2
    err = capsys.readouterr().err
    assert "unknown calibration setting" in err and "Traceback" not in err


def test_default_threads_leave_a_core_and_the_busy_ones_alone(frames, tmp_path, capsys):
    """More torch threads than free cores makes torch wait for itself (5-9x slower measured): the
    default takes the idle cores less one, at least one; a negative count is refused."""
    from pnlviz.detect.default import default_threads

    assert default_threads(2, 0.0) == 1 and default_threads(1, 0.0) == 1
    assert default_threads(8, 0.0) == 7 and default_threads(8, 0.2) == 7  # a little noise is idle
    assert default_threads(8, 2.6) == 5 and default_threads(8, 7.9) == 1 and default_threads(8, 30.0) == 1
    assert default_threads() >= 1
    assert main(["detect", "--data", str(frames), "--out", str(tmp_path / "p.zip"), "--threads", "-2",
                 "--no-progress"]) == 2
    assert "--threads must be 0" in capsys.readouterr().err and not (tmp_path / "p.zip").exists()


def test_a_light_model_from_train_is_taken_with_weights(frames, tmp_path, capsys):
    """`pnlviz detect --weights F` runs that light model (e.g. a fine-tuned one) with the settings
    of its own sidecar: its detections are the in-process ones of that model and preds.json names
    it; combined with PnLCalib's networks it is a clear error."""
    from pnlviz.detect.run import DEFAULT_MODEL, light_detector
    from pnlviz.detect.train import write_sidecar

    weights = tmp_path / "mine.pt"
    shutil.copy(DEFAULT_MODEL.with_name("light_synth.pt"), weights)
    side = json.loads(DEFAULT_MODEL.with_name("light_synth.json").read_text())
    side["kp_threshold"] = 0.5  # its own threshold, not the default model's
    write_sidecar(weights, side)
    out = tmp_path / "preds.zip"
    assert main(["detect", "--data", str(frames), "--out", str(out), "--weights", str(weights), "--no-progress",
                 "--settings", str(predictions_info_path(out))]) == 0
    info = read_predictions_info(out)
    assert info["detector"] == "light model" and info["weights"] == str(weights) and info["kp_threshold"] == 0.5
    det = light_detector(weights)
    ds = open_dataset(frames)
    preds = read_predictions(out)
    for stem in ds.stems:
        mine = det.detect([ds.image(stem)])[0]
        assert preds[stem].keypoints.keys() == mine.keypoints.keys()
        assert all(abs(preds[stem].keypoints[k][0] - mine.keypoints[k][0]) < 1e-6 for k in mine.keypoints)
    capsys.readouterr()
    assert main(["detect", "--data", str(frames), "--out", str(tmp_path / "p2.zip"), "--weights", str(weights),
                 "--weights-kp", str(weights), "--no-progress"]) == 2
    assert "not both" in capsys.readouterr().err


def test_device_is_chosen_or_clearly_refused(frames, tmp_path, capsys):
    """--device cpu / auto run here (no GPU: auto is the CPU, recorded in preds.json); cuda is a
    one-line error naming why; an unknown device too."""
    out = tmp_path / "preds.zip"
    assert main(["detect", "--data", str(frames), "--out", str(out), "--device", "auto", "--no-progress",
                 "--threads", "1", "--settings", str(predictions_info_path(out))]) == 0
    expected = "cuda" if torch.cuda.is_available() else "cpu"
    assert read_predictions_info(out)["device"] == expected
    if not torch.cuda.is_available():
        capsys.readouterr()
        assert main(["detect", "--data", str(frames), "--out", str(tmp_path / "p2.zip"), "--device", "cuda",
                     "--no-progress"]) == 2
        err = capsys.readouterr().err
        assert "no CUDA GPU" in err and "--device cpu or auto" in err and "Traceback" not in err
    assert main(["detect", "--data", str(frames), "--out", str(tmp_path / "p3.zip"), "--device", "tpu",
                 "--no-progress"]) == 2
    assert "expected cpu, cuda" in capsys.readouterr().err


def test_batches_and_half_precision_keep_the_detections(tmp_path):
    """--batch 3 finds what one frame at a time finds (to 1e-3 px); --half (float16, run on the CPU
    here) moves the points of real frames by less than 1 px, and says so in the sidecar."""
    import numpy as np

    frames = copy_sample_frames(tmp_path / "frames", 5)
    outs = {}
    for name, extra in (("one", []), ("batch", ["--batch", "3"]), ("half", ["--half", "--batch", "2"])):
        outs[name] = tmp_path / f"{name}.zip"
        assert main(["detect", "--data", str(frames), "--out", str(outs[name]), "--threads", "1", "--no-progress",
                     "--settings", str(predictions_info_path(outs[name]))] + extra) == 0
    ref, batch, half = (read_predictions(outs[n]) for n in ("one", "batch", "half"))
    assert set(ref) == set(batch) == set(half) and len(ref) == 5
    moved, unshared, total = [], 0, 0
    for stem in ref:
        a, b, h = (p[stem].points_px(960, 540) for p in (ref, batch, half))
        assert a.keys() == b.keys() and len(a) >= 5  # something to compare on every frame
        assert max(np.hypot(a[k][0] - b[k][0], a[k][1] - b[k][1]) for k in a) < 1e-3
        total += len(a)
        unshared += len(a.keys() ^ h.keys())
        moved += [np.hypot(a[k][0] - h[k][0], a[k][1] - h[k][1]) for k in a.keys() & h.keys()]
    moved = np.asarray(moved)
    assert total > 100
    assert unshared <= 0.02 * total and np.mean(moved < 1.0) >= 0.98 and np.median(moved) < 0.1
    assert moved.max() > 0  # float16 did run: float32 again would give the same points exactly
    assert read_predictions_info(outs["half"])["precision"] == "float16"
    assert read_predictions_info(outs["one"])["precision"] == "float32"


def test_a_cluster_worker_reloads_a_retrained_model(tmp_path):
    """The worker's cached detector is keyed on its weight files as they are: a model retrained
    under the same name is not served from the old one."""
    import os

    from pnlviz.commands.detect import _detector_key

    w = tmp_path / "light.pt"
    w.write_bytes(b"one")
    kw = {"weights_kp": None, "weights_lines": None, "light": w, "device": "cpu"}
    before = _detector_key(kw)
    assert _detector_key(dict(kw)) == before
    w.write_bytes(b"second")
    os.utime(w, ns=(1, 2))
    assert _detector_key(kw) != before
