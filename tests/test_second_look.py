"""A second look at a frame's detections (issue #35): the detector reads its heatmaps again at
lower thresholds, and the frame keeps that reading only where the first gives no camera
(:func:`pnlviz.calib.looks.take_look`); `pnlviz detect` and the app keep what it decides. A clip's
shots fit each frame's first reading only (:func:`pnlviz.calib.looks.for_shot`), and the card says
when a frame's detections are a second look."""

import numpy as np
import pytest

from pnlviz.calib.frame import FrameInputs, FrameSettings, calibrate_frame
from pnlviz.calib.looks import take_look
from pnlviz.data import Predictions
from pnlviz.field import load_field_model
from pnlviz.geometry.camera import Camera

W, H = 960, 540
MODEL = load_field_model()


def _camera() -> Camera:
    return Camera.from_look_at(np.array([0.0, 55.0, -18.0]), np.array([-30.0, 5.0, 0.0]), hfov_deg=40.0,
                               width=W, height=H)


def _seen(cam: Camera, p: float = 0.9) -> Predictions:
    """The ground keypoints (PnLCalib's ids, not 52) the camera shows, as detections scoring ``p``."""
    ids = [k for k in range(1, 58) if k != 52 and abs(MODEL.keypoint_xyz([k])[0, 2]) < 1e-9]
    uv, z = cam.project_with_depth(MODEL.keypoint_xyz(ids))
    inside = (z > 0) & cam.in_image(uv)
    return Predictions(keypoints={k: (float(u) / W, float(v) / H, p) for k, (u, v), ok in zip(ids, uv, inside) if ok})


def _calibrates(pred: Predictions) -> bool:
    return calibrate_frame(FrameInputs((W, H), detections=pred), FrameSettings(source="detections")).ok


def test_a_frame_keeps_its_first_reading_unless_only_the_second_gives_a_camera():
    full = _seen(_camera())
    assert len(full.keypoints) >= 6 and _calibrates(full)
    one = Predictions(keypoints=dict(list(full.keypoints.items())[:1]))
    assert not _calibrates(one)

    # the first gives no camera, the second does: the second, without anything attached
    weak = Predictions(keypoints=dict(one.keypoints), second=full)
    kept, second = take_look(weak, (W, H))
    assert second and kept == full and kept.second is None

    # the first gives a camera: kept as it is, the weaker peaks dropped
    more = Predictions(keypoints={**full.keypoints, 99: (0.5, 0.5, 0.2)})
    strong = Predictions(keypoints=dict(full.keypoints), second=more)
    kept, second = take_look(strong, (W, H))
    assert not second and kept == full and kept.second is None

    # neither gives one: the first; no second reading: the detections as they came
    kept, second = take_look(Predictions(keypoints=dict(one.keypoints), second=one), (W, H))
    assert not second and kept == one and kept.second is None
    assert take_look(full, (W, H)) == (full, False)


def test_the_detector_attaches_a_second_reading_only_where_it_finds_more():
    torch = pytest.importorskip("torch")
    from pnlviz.detect.run import Detector

    class Fixed(torch.nn.Module):
        """A network whose heatmaps are given (one frame)."""

        def __init__(self, maps):
            super().__init__()
            self.maps = torch.from_numpy(maps)

        def forward(self, x):
            return self.maps[None].expand(x.shape[0], -1, -1, -1)

    h, w = 64, 112  # heatmaps of a 224x128 input
    kp = np.zeros((58, h, w), np.float32)
    kp[0, 20, 30] = 0.9  # keypoint 1: a strong peak
    kp[4, 40, 80] = 0.25  # keypoint 5: under the first threshold, over the second
    kp[9, 10, 10] = 0.1  # keypoint 10: under both
    lines = np.zeros((24, h, w), np.float32)
    lines[2, 10, 10], lines[2, 50, 90] = 0.8, 0.35  # line 3: one end under the first threshold
    image = np.zeros((128, 224, 3), np.uint8)
    kw = dict(input_size=(224, 128), kp_threshold=0.3, line_threshold=0.4)

    pred = Detector(Fixed(kp), Fixed(lines), second_look=(0.2, 0.3), **kw).detect([image])[0]
    assert set(pred.keypoints) == {1} and pred.lines == {}
    assert pred.second is not None and set(pred.second.keypoints) == {1, 5} and set(pred.second.lines) == {3}
    assert pred.second.keypoints[1] == pred.keypoints[1]  # the same peak, the same place
    # nothing between the two thresholds: no second reading; none asked for: none either
    kp[4, 40, 80] = 0.1
    lines[2, 50, 90] = 0.2
    assert Detector(Fixed(kp), Fixed(lines), second_look=(0.2, 0.3), **kw).detect([image])[0].second is None
    kp[4, 40, 80] = 0.25
    assert Detector(Fixed(kp), Fixed(lines), **kw).detect([image])[0].second is None
    with pytest.raises(ValueError, match="second_look"):
        Detector(Fixed(kp), Fixed(lines), second_look=(0.2, 1.5), **kw)


class _Stub:
    """A detector whose detections of every frame are given: a first reading that gives no camera
    and a second that does."""

    calibration: dict = {}

    def __init__(self, weak: Predictions):
        self.weak = weak

    def detect(self, images):
        return [Predictions(keypoints=dict(self.weak.keypoints), second=self.weak.second) for _ in images]


def _weak_frame() -> Predictions:
    full = _seen(_camera())
    return Predictions(keypoints=dict(list(full.keypoints.items())[:1]), second=full)


def test_pnlviz_detect_and_the_app_keep_the_reading_take_look_decides(tmp_path):
    from helpers import copy_sample_frames
    from pnlviz.app.state import AppState
    from pnlviz.commands.detect import _detect_here
    from pnlviz.data import open_dataset

    frames = copy_sample_frames(tmp_path / "frames", 2)
    weak = _weak_frame()
    ds = open_dataset(frames)
    out = list(_detect_here(ds, _Stub(weak), ds.stems, 2))
    assert [s for s, _, _ in out] == list(ds.stems) and all(problem is None for _, _, problem in out)
    # the sample frames are 960x540: the second reading, as a zip holds it (nothing attached)
    assert all(p == weak.second and p.second is None for _, p, _ in out)

    st = AppState(frames, edits=tmp_path / "edits", detector=_Stub(weak))
    try:
        st.run_detector(ds.stems[0])
        assert st.detected[ds.stems[0]] == weak.second and st.detected[ds.stems[0]].second is None
    finally:
        st.close()


def _pan(t: int) -> Camera:
    """Frame ``t`` of a slow pan from the main camera's place."""
    return Camera.from_look_at(np.array([0.0, 55.0, -18.0]), np.array([-30.0 + 1.5 * t, 5.0, 0.0]), hfov_deg=40.0,
                               width=W, height=H)


def _grid_error(a: Camera, b: Camera) -> float:
    """Median distance (px) between where two cameras put a 5 m grid of the pitch in view."""
    gx, gy = np.meshgrid(np.arange(-50.0, 51.0, 5.0), np.arange(-30.0, 31.0, 5.0))
    grid = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], 1)
    pa, za = a.project_with_depth(grid)
    ok = (za > 0) & a.in_image(pa)
    return float(np.median(np.hypot(*(pa[ok] - b.project(grid[ok])).T)))


def _misread_clip(weak: range, T: int = 12):
    """A pan whose frames ``weak`` the first reading leaves with two keypoints each and the second
    look fills with weak peaks in the wrong places: those of a camera 40 m to the side."""
    frames = [_seen(_pan(t)) for t in range(T)]
    for t in weak:
        wrong = _seen(Camera.from_look_at(np.array([40.0, 55.0, -18.0]), np.array([-20.0 + 1.5 * t, 5.0, 0.0]),
                                          hfov_deg=40.0, width=W, height=H), p=0.25)
        strong = dict(list(frames[t].keypoints.items())[:2])
        frames[t] = Predictions(keypoints={**{k: v for k, v in wrong.keypoints.items() if k not in strong}, **strong})
    return frames


def test_a_shot_fits_the_first_reading_and_carries_the_frames_a_second_look_misread():
    """Three frames in a row whose weak peaks fit another camera (a central view read again:
    clip 113 of the clip benchmark): the shot places them from their neighbours."""
    from pnlviz.calib.temporal import calibrate_clip_frames

    weak = range(5, 8)
    frames = _misread_clip(weak)
    inputs = [FrameInputs((W, H), detections=p) for p in frames]
    floor = FrameSettings(source="detections", detection_settings={"shot_min_score": [0.3, 0.4]})
    for t in weak:  # each one's own camera follows its weak peaks
        alone = calibrate_frame(inputs[t], floor)
        assert alone.ok and _grid_error(_pan(t), alone.camera) > 50

    fit = calibrate_clip_frames(inputs, floor)
    assert fit.result.shots == [range(0, 12)]
    for t in weak:
        assert fit.per_frame[t] is None  # the first reading alone: no camera of its own
        assert len(fit.observations[t].kp_ids) == 2
        assert fit.result.choices[t].use == "shot" and _grid_error(_pan(t), fit.result.cameras[t]) < 2.0
        assert fit.result.choices[t].reason == ("its own camera rests on detections under the detector's thresholds "
                                                "(a second look), which a shot does not fit: the shot carries it")
    assert fit.result.choices[4].reason != fit.result.choices[5].reason
    # every detection in the shot: the misread frames keep their own (wrong) cameras
    every = calibrate_clip_frames(inputs, FrameSettings(source="detections"))
    assert all(_grid_error(_pan(t), every.result.cameras[t]) > 50 for t in weak)


def test_confident_drops_what_scores_under_the_first_thresholds_and_nothing_else():
    from pnlviz.calib.calibrate import CalibParams
    from pnlviz.calib.looks import confident, for_shot

    pred = Predictions(keypoints={1: (0.1, 0.2, 0.9), 2: (0.3, 0.4, 0.25), 3: (0.5, 0.5, 0.3)},
                       lines={1: (0.1, 0.1, 0.9, 0.2, 0.2, 0.5), 2: (0.1, 0.1, 0.9, 0.2, 0.2, 0.35)})
    kept = confident(pred, (0.3, 0.4))
    assert set(kept.keypoints) == {1, 3} and set(kept.lines) == {1} and kept.keypoints[1] == pred.keypoints[1]
    assert confident(kept, (0.3, 0.4)) is kept and confident(pred, (0.0, 0.0)) is pred
    inputs = FrameInputs((W, H), detections=pred)
    assert for_shot(inputs, CalibParams()) is inputs  # no floor stated: every detection
    assert for_shot(inputs, CalibParams(shot_min_score=(0.3, 0.4))).detections == kept
    bare = FrameInputs((W, H), annotation={})
    assert for_shot(bare, CalibParams(shot_min_score=(0.3, 0.4))) is bare


def test_the_apps_clip_model_fits_what_the_shot_sees_whatever_cameras_it_is_given(tmp_path):
    """The app builds a clip's model from a prediction zip and the detector's settings beside it,
    handing over the frames' own cameras (from all their detections): the misread frames still
    get the shot's camera, and the shot shows their two confident points only."""
    import shutil

    from pnlviz import EXAMPLES_DIR
    from pnlviz.data import write_predictions, write_predictions_info
    from pnlviz.pipeline.clip import clip_solver, dataset_clips
    from pnlviz.pipeline.reader import FrameReader

    weak = range(5, 8)
    frames = _misread_clip(weak)
    data = tmp_path / "clip"
    data.mkdir()
    stems = [f"m-IMG_{t + 1}" for t in range(len(frames))]
    for s in stems:  # one picture for every frame: no cut in the clip
        shutil.copy(EXAMPLES_DIR / "sample" / "00000.jpg", data / f"{s}.jpg")
    preds = tmp_path / "preds.zip"
    write_predictions(preds, dict(zip(stems, frames)))
    write_predictions_info(preds, {"calibration": {"shot_min_score": [0.3, 0.4]}})
    reader = FrameReader.open(data, detections=preds)
    try:
        assert dataset_clips(reader.stems)["m"] == stems
        own = [calibrate_frame(FrameInputs((W, H), detections=p), FrameSettings(source="detections")).camera
               for p in frames]
        for cameras in (None, own):
            solver = clip_solver(reader, "m", stems, cameras=cameras)
            for t in weak:
                assert solver.own_camera(t) is None and len(solver.shown_observations(t).kp_ids) == 2
                assert solver.choice(t).use == "shot" and _grid_error(_pan(t), solver.camera(t)) < 2.0
                assert "(a second look)" in solver.choice(t).reason
    finally:
        reader.close()


def test_a_frame_without_the_shots_camera_is_told_its_own_rests_on_a_second_look():
    from pnlviz.calib.shot_check import CameraChoice, second_look_choice

    told = second_look_choice(CameraChoice("none", "the shot has no camera, and the frame has none of its own"))
    assert told.use == "none" and told.reason == (
        "the shot has no camera; its own camera rests on detections under the detector's thresholds "
        "(a second look), which a shot does not fit")


def _looked_folder(tmp_path):
    """Two frames of one picture with a prediction zip and its settings file: "a" read a second
    time (one keypoint above the thresholds, the others under them), "b" not."""
    import shutil

    from pnlviz import EXAMPLES_DIR
    from pnlviz.data import write_predictions, write_predictions_info

    data = tmp_path / "frames"
    data.mkdir()
    for s in ("a", "b"):
        shutil.copy(EXAMPLES_DIR / "sample" / "00000.jpg", data / f"{s}.jpg")
    full = _seen(_camera())
    weak = Predictions(keypoints={**dict(list(full.keypoints.items())[:1]),
                                  **{k: (x, y, 0.25) for k, (x, y, _) in list(full.keypoints.items())[1:]}})
    preds = tmp_path / "preds.zip"
    write_predictions(preds, {"a": weak, "b": full})
    write_predictions_info(preds, {"calibration": {"shot_min_score": [0.3, 0.4]}})
    return data, preds, len(full.keypoints) - 1


def test_the_card_says_when_a_frames_detections_are_a_second_look(tmp_path):
    """A frame whose detections hold points under the detector's thresholds (read again because
    the others gave no camera) says so on its card, with how many; the other frames do not."""
    from pnlviz.app.cards import calibration_card
    from pnlviz.app.state import AppState

    data, preds, weak = _looked_folder(tmp_path)
    with AppState(data, detections=preds, edits=tmp_path / "edits") as st:
        card = calibration_card(st.view("a"), st)
        assert st.view("a").result.ok
        assert (f"**a second look**: {weak} of its detections score under the detector's "
                "thresholds (0.3 keypoints, 0.4 lines)") in card
        assert "second look" not in calibration_card(st.view("b"), st)


def test_calibrate_reports_the_frames_whose_camera_rests_on_a_second_look(tmp_path):
    """`pnlviz calibrate --report` says what the card says: how many of a frame's detections
    score under the detector's thresholds, for that frame alone."""
    import json

    from pnlviz.cli import main

    data, preds, weak = _looked_folder(tmp_path)
    report = tmp_path / "frames.jsonl"
    assert main(["calibrate", "--data", str(data), "--detections", str(preds), "--out", str(tmp_path / "cams.zip"),
                 "--report", str(report), "--no-progress"]) == 0
    rows = {r["stem"]: r for r in map(json.loads, report.read_text().splitlines())}
    assert rows["a"]["second_look"] == weak and "second_look" not in rows["b"]
    assert "failure" not in rows["a"]  # the camera it rests on was given
