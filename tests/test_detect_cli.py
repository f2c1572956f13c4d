"""pnlviz detect: weights saved -> command line -> the same detections as in process; clear errors."""

import shutil

import pytest

torch = pytest.importorskip("torch")

from pnlviz import EXAMPLES_DIR  # noqa: E402
from pnlviz.cli import main  # noqa: E402
from pnlviz.data import open_dataset, read_predictions  # noqa: E402


@pytest.fixture()
def frames(tmp_path):
    d = tmp_path / "frames"
    d.mkdir()
    for stem in ("00000", "00001"):
        shutil.copy(EXAMPLES_DIR / "sample" / f"{stem}.jpg", d / f"{stem}.jpg")
    return d


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
                 "--threads", "2", "--no-progress"]) == 0
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
    assert st.source == "both" and st.needs_detection("00000")
    before = st.view("00000")
    assert before.detections is None
    st.run_detector("00000")
    assert not st.needs_detection("00000")
    after = st.view("00000")
    assert after.detections is not None and len(after.detections.keypoints) == 57
    assert after.observations is not None and after.observations.n_keypoints > 0
