"""Temporal calibration (issue #14): one broadcast camera per shot, recovered from noisy detections;
cuts; frames with too few keypoints placed by their shot; the jitter metric."""

import dataclasses
import math

import numpy as np
import pytest

from pnlviz.calib.calibrate import CalibParams, calibrate
from pnlviz.calib.observations import Observations
from pnlviz.calib.cuts import segment_shots
from pnlviz.calib.shot import ShotProblem, TemporalParams, angle_steps, frame_data
from pnlviz.calib.shot_fit import fit_shot, initial
from pnlviz.calib.temporal import image_change
from pnlviz.field import load_field_model
from pnlviz.geometry.camera import Camera

W, H = 960, 540
GRID = np.array([[x, y, 0.0] for x in np.arange(-50, 51, 5) for y in np.arange(-30, 31, 5)])


def _shot(T, centre, seed, *, noise=1.0, sparse_frame=None, start=-30.0, span=None):
    """A pan-tilt-zoom shot from ``centre``: the true cameras and noisy observations (keypoints and
    two points per visible line); ``sparse_frame`` keeps only two keypoints and no line. The motion
    takes ``span`` frames (default T): a longer span is a slower camera."""
    model = load_field_model()
    rng = np.random.default_rng(seed)
    truth = []
    for t in range(T):
        s = t / (span or T)
        target = np.array([start + 50 * s, 10 * math.sin(2 * s), 0.0])
        truth.append(Camera.from_look_at(centre, target, hfov_deg=40 - 15 * math.sin(math.pi * s), width=W, height=H,
                                         roll_deg=0.3, k1=-0.05))
    ids = [k for k in model.keypoint_ids if k <= 57]
    xyz = model.keypoint_xyz(ids)
    obs = []
    for t, cam in enumerate(truth):
        uv, z = cam.project_with_depth(xyz)
        flat = cam.project(xyz, distort=False)  # far outside the view the lens model folds back in
        inside = (z > 0) & (uv[:, 0] >= 0) & (uv[:, 0] < W) & (uv[:, 1] >= 0) & (uv[:, 1] < H)
        inside &= (np.abs(flat[:, 0] - W / 2) < W) & (np.abs(flat[:, 1] - H / 2) < H)
        keep = np.flatnonzero(inside)
        if t == sparse_frame:
            keep = keep[:2]
        kp = {int(ids[i]): uv[i] + rng.normal(0, noise, 2) for i in keep}
        lines = {}
        for name, seg in model.lines.items():
            if t == sparse_frame:
                break
            P = seg.start + np.linspace(0, 1, 30)[:, None] * (seg.end - seg.start)
            puv, pz = cam.project_with_depth(P)
            flat = cam.project(P, distort=False)  # far outside the view the lens model folds back in
            m = (pz > 0) & (puv[:, 0] >= 0) & (puv[:, 0] < W) & (puv[:, 1] >= 0) & (puv[:, 1] < H)
            m &= (np.abs(flat[:, 0] - W / 2) < W) & (np.abs(flat[:, 1] - H / 2) < H)
            if m.sum() >= 2:
                lines[name] = puv[m][[0, -1]] + rng.normal(0, noise, (2, 2))
        obs.append(Observations.from_keypoints(W, H, kp, lines=lines))
    return truth, obs


def _per_frame(obs):
    out = []
    for o in obs:
        r = calibrate(o, CalibParams())
        out.append(r.camera if r.ok else None)
    return out


def _grid_error(a: Camera, b: Camera) -> float:
    pa = a.project(GRID)
    pb = b.project(GRID)
    m = np.all(np.isfinite(pa), 1) & (pa[:, 0] >= 0) & (pa[:, 0] < W) & (pa[:, 1] >= 0) & (pa[:, 1] < H)
    return float(np.median(np.linalg.norm(pa[m] - pb[m], axis=1)))


@pytest.mark.parametrize("noise, centre_cm, angle_deg, k1_tol", [(0.3, 1.0, 0.01, 0.005), (1.0, 5.0, 0.02, 0.01)])
def test_a_shot_is_recovered_from_noisy_detections(noise, centre_cm, angle_deg, k1_tol):
    """90 frames, one centre, smooth pan and zoom, Gaussian detection noise on every keypoint and
    line end; frame 40 has two keypoints and no line (per-frame calibration cannot place it). At
    0.3 px of noise the shot's centre comes back to 1 cm, k1 to 0.005 and the angles to 0.01 degree
    (median over frames); at 1 px to 5 cm (measured 1.0-2.2 cm over seeds 1-3), k1 to 0.01
    (measured 0.004-0.007) and 0.02 degree. The
    two-keypoint frame lands within 1 px of the truth, and every frame is closer to the truth than
    per-frame calibration gets (median pitch-grid error halved)."""
    centre = np.array([5.0, 58.0, -16.0])
    truth, obs = _shot(90, centre, seed=1, sparse_frame=40, noise=noise)
    cams = _per_frame(obs)
    assert cams[40] is None and sum(c is not None for c in cams) == 89
    fit = fit_shot(obs, cams, (W, H), TemporalParams(noise_px=noise))
    assert np.linalg.norm(fit.C - centre) < centre_cm / 100
    assert abs(fit.k1 - (-0.05)) < k1_tol
    err = np.array([np.abs(np.subtract(truth[t].pan_tilt_roll_deg, fit.cameras[t].pan_tilt_roll_deg))
                    for t in range(90)])
    assert np.all(np.median(err, axis=0) < angle_deg), np.median(err, axis=0)
    assert _grid_error(truth[40], fit.cameras[40]) < 1.0
    temporal = np.median([_grid_error(truth[t], fit.cameras[t]) for t in range(90)])
    per_frame = np.median([_grid_error(truth[t], cams[t]) for t in range(90) if cams[t] is not None])
    assert temporal < 0.5 * per_frame, (temporal, per_frame)
    assert sum(fit.dropped) == 0  # nothing in this shot is an outlier


def test_outlier_detections_and_an_outlier_frame_do_not_pull_the_shot():
    """Three keypoints 80 px off and a frame whose keypoints are all 40 px off are left out, and
    every other frame's camera stays where the clean shot puts it (within 0.3 px on the pitch grid;
    the clean shot itself is within 1.2 px of the truth everywhere, its two end frames the worst)."""
    centre = np.array([-3.0, 60.0, -18.0])
    truth, obs = _shot(40, centre, seed=2)
    clean = fit_shot(obs, _per_frame(obs), (W, H))
    rng = np.random.default_rng(5)
    obs = [Observations(o.width, o.height, o.kp_ids, o.kp_xy.copy(), o.kp_xyz, o.kp_sets, o.kp_main, o.lines)
           for o in obs]
    for t in (5, 17, 29):  # one keypoint per frame 80 px off
        obs[t].kp_xy[0] += rng.normal(0, 80, 2)
    obs[20].kp_xy[:] += 40.0  # a whole frame shifted (a detector failure)
    cams = _per_frame(obs)
    fit = fit_shot(obs, cams, (W, H))
    assert np.linalg.norm(fit.C - centre) < 0.05
    assert sum(fit.dropped) >= 3 + obs[20].n_keypoints // 2
    assert max(_grid_error(truth[t], clean.cameras[t]) for t in range(40)) < 1.2
    assert max(_grid_error(clean.cameras[t], fit.cameras[t]) for t in range(40) if t != 20) < 0.3


def test_a_cut_is_found_between_two_camera_positions():
    truth_a, obs_a = _shot(25, np.array([5.0, 58.0, -16.0]), seed=3)
    truth_b, obs_b = _shot(20, np.array([-40.0, 45.0, -12.0]), seed=4, start=10.0)
    cams = _per_frame(obs_a) + _per_frame(obs_b)
    shots = segment_shots(cams)
    assert [(s.start, s.stop) for s in shots] == [(0, 25), (25, 45)]
    # a single bad per-frame camera inside a shot is not a cut
    bad = list(cams)
    bad[10] = Camera.from_look_at(np.array([0.0, -70.0, -20.0]), np.zeros(3), hfov_deg=30, width=W, height=H)
    assert [(s.start, s.stop) for s in segment_shots(bad)] == [(0, 25), (25, 45)]
    # an image change marks a cut the cameras cannot see
    changes = [0.004] * 44
    changes[9] = 0.08
    assert [(s.start, s.stop) for s in segment_shots(cams, changes)] == [(0, 10), (10, 25), (25, 45)]


def test_image_change_is_small_within_a_view_and_large_across_a_cut():
    rng = np.random.default_rng(0)
    grass = np.zeros((90, 160, 3), np.uint8)
    grass[:] = (40, 140, 50)
    grass[:30] = (120, 110, 100)  # stands
    panned = np.roll(grass, 7, axis=1)
    crowd = rng.integers(0, 255, (90, 160, 3), dtype=np.uint8)
    assert image_change(grass, grass) == 0.0
    assert image_change(grass, panned) < 0.01
    assert image_change(grass, crowd) > 0.05


def test_fit_shot_needs_a_camera_to_start_from():
    _, obs = _shot(3, np.array([0.0, 60.0, -15.0]), seed=9)
    with pytest.raises(ValueError, match="no frame"):
        fit_shot(obs, [None, None, None], (W, H))


def test_calibrate_temporal_on_a_prediction_zip(tmp_path, capsys):
    """`pnlviz calibrate --detections clip.zip --size WxH --temporal`: the frames group into their
    clip by stem, the frame with two keypoints (no per-frame camera) gets the shot's camera, and
    the cameras jitter less than per-frame ones."""
    from pnlviz.cli import main
    from pnlviz.data import write_predictions
    from pnlviz.data.cameras import read_cameras
    from pnlviz.data.predictions import Predictions
    from pnlviz.metrics.temporal import jitter

    centre = np.array([5.0, 58.0, -16.0])
    truth, obs = _shot(30, centre, seed=6, sparse_frame=15, span=150)
    preds = {}
    for t, o in enumerate(obs):
        kp = {int(k): (float(x) / W, float(y) / H, 0.9) for k, (x, y) in zip(o.kp_ids, o.kp_xy) if k != 52}
        preds[f"match3-IMG_{t + 1:03d}"] = Predictions(keypoints=kp)
    preds["other-IMG_001"] = preds["match3-IMG_001"]  # another clip: calibrated on its own
    z = tmp_path / "clip.zip"
    write_predictions(z, preds)
    base = ["calibrate", "--detections", str(z), "--size", f"{W}x{H}", "--no-progress"]
    assert main(base + ["--out", str(tmp_path / "per_frame.zip")]) == 0
    assert main(base + ["--out", str(tmp_path / "temporal.zip"), "--temporal",
                        "--report", str(tmp_path / "r.jsonl")]) == 0
    per_frame, _ = read_cameras(tmp_path / "per_frame.zip")
    temporal, _ = read_cameras(tmp_path / "temporal.zip")
    stems = [f"match3-IMG_{t + 1:03d}" for t in range(30)]
    assert "match3-IMG_016" not in per_frame and len(temporal) == 31

    def cam(d):
        return Camera.from_soccernet(d, 960, 540).scaled(W, H)

    assert _grid_error(truth[15], cam(temporal["match3-IMG_016"])) < 1.0
    jt = np.nanmedian(jitter([cam(temporal[s]) for s in stems]))
    jp = np.nanmedian(jitter([cam(per_frame[s]) if s in per_frame else None for s in stems]))
    jtrue = np.nanmedian(jitter(truth))
    assert jt < 0.5 * jp and abs(jt - jtrue) < 0.2, (jt, jp, jtrue)
    import json

    reports = [json.loads(line) for line in (tmp_path / "r.jsonl").read_text().splitlines()]
    clip_names = {r["temporal"]["clip"] for r in reports}
    assert clip_names == {"match3", None}  # one frame named "other" is no clip
    other = next(r for r in reports if r["stem"] == "other-IMG_001")["temporal"]
    assert other["camera"] == "own" and "not part of a clip" in other["why"]
    assert next(r for r in reports if r["stem"] == "match3-IMG_016")["temporal"]["per_frame"] is False


def test_a_video_file_goes_through_detect_and_calibrate(tmp_path, capsys):
    """`pnlviz detect --video clip.mp4` reads the frames one at a time (named <video>-IMG_<n>),
    `pnlviz calibrate --video clip.mp4 --detections ... --temporal` calibrates them as one clip at
    the video's size; the frames decode back in order and a jump seeks."""
    pytest.importorskip("torch")
    import cv2

    from pnlviz.cli import main
    from pnlviz.data import read_predictions
    from pnlviz.data.video import VideoDataset
    from pnlviz.data.cameras import read_cameras
    from pnlviz.synth.clip import clip_frame, plan_clip

    plan = plan_clip(8, 12, (480, 270), cuts=0)
    frames = [clip_frame(plan, t)["image"] for t in range(12)]
    video = tmp_path / "match.mp4"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"mp4v"), 25.0, (480, 270))
    if not writer.isOpened():
        pytest.skip("this OpenCV build cannot write mp4")
    for img in frames:
        writer.write(img)
    writer.release()
    ds = VideoDataset(video)
    assert len(ds) == 12 and ds.stems[0] == "match-IMG_00001" and (ds.width, ds.height) == (480, 270)
    # decoded frames are the written ones (up to the codec's loss), in order and after a jump
    assert np.abs(ds.image("match-IMG_00003").astype(int) - frames[2]).mean() < 12
    assert np.abs(ds.image("match-IMG_00004").astype(int) - frames[3]).mean() < 12
    assert np.abs(ds.image("match-IMG_00002").astype(int) - frames[1]).mean() < 12
    # threads sharing the dataset (the app's view, triage and shot builds) each get their own frame
    import threading

    wrong: list[int] = []

    def read(t: int) -> None:
        for _ in range(4):
            if np.abs(ds.image(ds.stems[t]).astype(int) - frames[t]).mean() >= 12:
                wrong.append(t)

    threads = [threading.Thread(target=read, args=(t,)) for t in (1, 6, 10)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    assert wrong == []
    preds = tmp_path / "preds.zip"
    assert main(["detect", "--video", str(video), "--out", str(preds), "--no-progress", "--threads", "1"]) == 0
    assert sorted(read_predictions(preds)) == list(ds.stems)
    cams = tmp_path / "cams.zip"
    assert main(["calibrate", "--video", str(video), "--detections", str(preds), "--temporal", "--out", str(cams),
                 "--no-progress"]) == 0
    said = capsys.readouterr().out
    assert "video match.mp4 at 480x270" in said
    got, _ = read_cameras(cams)
    assert len(got) >= 10
    # the overlay video: same frames, the pitch drawn where the camera puts it
    overlay = tmp_path / "overlay.mp4"
    assert main(["render", "--video", str(video), "--cameras", str(cams), "--out", str(overlay), "--no-progress"]) == 0
    out = VideoDataset(overlay)
    assert len(out) == 12 and (out.width, out.height) == (480, 270)
    stem = sorted(got)[5]
    drawn = out.image(out.stems[ds.stems.index(stem)]).astype(int)
    plain = frames[ds.stems.index(stem)].astype(int)
    from pnlviz.viz import draw_pitch

    mask = draw_pitch(np.zeros((270, 480, 3), np.uint8), Camera.from_soccernet(got[stem], 960, 540),
                      colour=(255, 255, 255), thickness=2)[:, :, 0] > 128
    assert mask.sum() > 200
    changed = np.abs(drawn - plain).sum(axis=2) > 60
    # the bird's-eye inset in the bottom-right corner (the camera's footprint on the pitch)
    from pnlviz.viz import inset_top_view

    inset = np.any(inset_top_view(np.zeros((270, 480, 3), np.uint8), Camera.from_soccernet(got[stem], 960, 540)) > 0,
                   axis=2)
    assert 0.02 < inset.mean() < 0.15 and not inset[:100].any()
    assert changed[inset].mean() > 0.5
    assert changed[mask & ~inset].mean() > 0.5 and changed[~mask & ~inset].mean() < 0.05
    assert main(["render", "--video", str(video), "--cameras", str(cams), "--out", str(overlay), "--no-progress",
                 "--no-top-view"]) == 0
    bare = VideoDataset(overlay).image(out.stems[ds.stems.index(stem)]).astype(int)
    assert (np.abs(bare - plain).sum(axis=2) > 60)[inset & ~mask].mean() < 0.05
    assert main(["calibrate", "--video", str(video), "--out", str(cams)]) == 2  # --video needs --detections
    with pytest.raises(SystemExit):
        main(["detect", "--video", str(video), "--data", str(tmp_path), "--out", str(preds)])


def test_the_shot_jacobian_is_the_frames_own_chained_to_the_shot_and_matches_plain_differences():
    """The shot's analytic Jacobian (each frame's problem, chained from its camera to the shot's
    centre, k1, angles and log f) agrees with central differences of the residuals, column by
    column, on a shot with keypoints, lines, a circle and a pin."""
    model = load_field_model()
    _, obs = _shot(7, np.array([5.0, 58.0, -16.0]), seed=12)
    cams = _per_frame(obs)
    obs[3].circles = {"Circle central": cams[3].project(model.circles["Circle central"].point_at(np.linspace(0, 6, 9)))}
    obs[2].kp_pinned = np.zeros(obs[2].n_keypoints, bool)
    obs[2].kp_pinned[0] = True
    m = ShotProblem(frame_data(obs, model), (W, H), TemporalParams())
    C, k1, per = initial(cams, 7)
    x = np.concatenate([C, [k1 - 0.01], per.ravel() + 0.002])
    r0, J = m.evaluate(x, True)
    assert J.shape == (len(r0), len(x))
    J = J.toarray()
    plain = np.empty_like(J)
    for c in range(len(x)):
        h = 1e-6 * max(1.0, abs(x[c]))
        xp, xm = x.copy(), x.copy()
        xp[c] += h
        xm[c] -= h
        plain[:, c] = (m.evaluate(xp)[0] - m.evaluate(xm)[0]) / (2 * h)
    assert np.allclose(J, plain, atol=1e-5 * np.abs(plain).max()), np.abs(J - plain).max()


def test_a_problem_restricted_to_selections_is_the_problem_built_on_them():
    """A solve restricts its shot anew after each gating (``ShotProblem.restricted``, rows taken
    from the problem with everything): residuals and Jacobian are those of a problem built on the
    frames without the observations left out, with the weights that follow from what each frame
    keeps (a frame left with no keypoint weighs its lines alone; one left with no line or circle,
    its keypoints alone)."""
    from pnlviz.calib.shot import Selection
    from pnlviz.calib.shot_fit import distances

    model = load_field_model()
    _, obs = _shot(8, np.array([5.0, 58.0, -16.0]), seed=13)
    cams = _per_frame(obs)
    for t in (2, 3, 5):
        obs[t].circles = {"Circle central": cams[t].project(model.circles["Circle central"].point_at(np.linspace(0, 6, 9))),
                          "Circle left": cams[t].project(model.circles["Circle left"].point_at(np.linspace(-0.9, 0.9, 5)))}
    obs[6] = None
    data = frame_data(obs, model)
    everything = [None if o is None else Selection.everything(o) for o in obs]
    sel = list(everything)
    sel[0] = Selection(np.arange(obs[0].n_keypoints) % 3 != 0, everything[0].lines[1:], ())
    sel[1] = Selection(np.zeros(obs[1].n_keypoints, bool), everything[1].lines, ())  # lines alone
    sel[2] = Selection(everything[2].keypoints, (), ())  # keypoints alone
    sel[3] = Selection(everything[3].keypoints[::-1] & (np.arange(obs[3].n_keypoints) > 1), everything[3].lines[:2],
                       ("Circle left",))  # the class seen first on the shot is left out here
    sel[5] = None
    whole = ShotProblem(data, (W, H), TemporalParams())
    C, k1, per = initial(cams, 8)
    x = np.concatenate([C, [k1], per.ravel()])
    def without(o, s):  # the frame's observations without those left out
        if o is None or s is None:
            return o
        return dataclasses.replace(o.subset(s.keypoints), lines={k: o.lines[k] for k in s.lines},
                                   circles={k: o.circles[k] for k in s.circles})

    for chosen in (sel, everything):
        built = ShotProblem(frame_data([without(o, s) for o, s in zip(obs, chosen)], model), (W, H), TemporalParams())
        restricted = whole.restricted(chosen)
        assert restricted.n_data == built.n_data < whole.n_data or chosen is everything
        (r1, J1), (r2, J2) = built.evaluate(x, True), restricted.evaluate(x, True)
        assert np.array_equal(r1, r2) and np.array_equal(J1.toarray(), J2.toarray())
    assert not np.array_equal(ShotProblem(data, (W, H), TemporalParams(), sel).evaluate(x)[0], whole.evaluate(x)[0])
    with pytest.raises(ValueError, match="keypoint mask does not match"):  # only the problem with everything
        whole.restricted(sel).restricted(sel)
    # each frame's distances, all frames at once, are those of its camera alone
    for t, (mine, d) in enumerate(zip(whole.distances(x), data)):
        if d is None:
            assert mine is None
            continue
        alone = distances(d, whole.cameras(x)[t])
        assert np.allclose(mine.keypoints, alone.keypoints)
        assert mine.classes.keys() == alone.classes.keys()
        assert np.allclose([mine.classes[k] for k in alone.classes], list(alone.classes.values()), atol=1e-6)


def test_angle_steps_turn_the_camera_as_its_angles_do():
    """Each column of angle_steps is the left rotation step a change of pan, tilt or roll makes."""
    from pnlviz.geometry.camera import rotation_from_pan_tilt_roll
    from pnlviz.geometry.so3 import so3_exp

    a = np.array([0.4, 1.2, -0.05])
    S = angle_steps(*a)
    for i in range(3):
        d = np.zeros(3)
        d[i] = 1e-7
        moved = rotation_from_pan_tilt_roll(*(a + d))
        assert np.allclose(so3_exp(1e-7 * S[:, i]) @ rotation_from_pan_tilt_roll(*a), moved, atol=1e-12)
