"""A shot's camera is never worse than its frames' own cameras (issue #31): every term of the frame
pipeline in the shot's problem, each frame judged against its own camera, a shot split where its
frames disagree with it; and one rule for what a clip is and where it cuts."""

import numpy as np
import pytest

from pnlviz.calib.frame import FrameInputs, FrameSettings, calibrate_frame
from pnlviz.calib.observations import Observations
from pnlviz.calib.problem import FrameData
from pnlviz.calib.shot import TemporalParams
from pnlviz.calib.shot_check import judge_frame
from pnlviz.calib.temporal import calibrate_clip, calibrate_clip_frames
from pnlviz.data.annotations import parse_annotation
from pnlviz.field import load_field_model
from pnlviz.geometry.camera import Camera
from pnlviz.metrics.soccernet import evaluate_frame
from pnlviz.synth.annotate import annotate, annotation_to_json
from pnlviz.synth.clip import plan_clip

W, H = 960, 540


def _annotated_clip(seed: int, frames: int):
    """A synthetic clip's true cameras and annotations (no pixels rendered)."""
    plan = plan_clip(seed, frames)
    anns = [parse_annotation(annotation_to_json(annotate(cam, np.random.default_rng([seed, t, 7]))))
            for t, cam in enumerate(plan.cameras)]
    return plan, anns


def _accuracy(cam, ann) -> float:
    return 0.0 if cam is None else evaluate_frame(cam.scaled(W, H), ann).accuracy(5)


def test_a_clip_of_few_keypoints_and_a_missed_cut_is_no_worse_than_its_frames():
    """Clip 3 (40 frames, two shots from two camera positions 22 m apart that see the same part of
    the pitch): its frames show two keypoints each, three lines and the circles. Without the images
    the cut cannot be seen; the shot model used to fit one camera 60 m away that fits the keypoints
    and lines (residual 0.1 px) and misses the circles, FS@5 0.519 against 1.000 frame by frame.
    Now the circles are in the shot's problem, the frames judge the shot's camera against their own,
    the shot is split where the frames' own centres jump, and each frame is as good as its own."""
    plan, anns = _annotated_clip(3, 40)
    true_cut = next(t for t in range(1, 40) if plan.shot_of[t] != plan.shot_of[t - 1])
    inputs = [FrameInputs((W, H), annotation=a) for a in anns]
    clip = calibrate_clip_frames(inputs, FrameSettings())
    obs = clip.observations
    assert all(o.n_keypoints <= 2 and o.circles for o in obs)
    res = clip.result
    assert [s.start for s in res.shots] == [0, true_cut] and res.splits == [true_cut]
    own = [_accuracy(c, a) for c, a in zip(clip.per_frame, anns)]
    used = [_accuracy(c, a) for c, a in zip(res.cameras, anns)]
    assert np.mean(used) >= np.mean(own) - 0.01 and np.mean(used) > 0.97, (np.mean(used), np.mean(own))
    for t, cam in enumerate(res.cameras):  # every frame within 2 m of its true camera centre
        assert np.linalg.norm(cam.C - plan.cameras[t].C) < 2.0
    assert all(c.use == "shot" for c in res.choices)
    # a fit left as one shot over the cut (every cut removed by hand) is worse than the frames: they keep their own
    from pnlviz.calib.cuts import CutEdits

    forced = calibrate_clip(obs, clip.per_frame, (W, H), cuts=CutEdits(removed=frozenset(range(1, 40))))
    assert len(forced.shots) == 1
    kept = [c for c in forced.choices if c.use == "own"]
    # one camera centre cannot carry both positions: the frames of at least one of them keep their own
    assert all(c.use == "own" for c in forced.choices[true_cut:]) or all(c.use == "own" for c in
                                                                          forced.choices[:true_cut])
    assert all("misses" in c.reason or "verdict" in c.reason for c in kept)
    # and no frame is worse than with its own camera
    got = [_accuracy(c, a) for c, a in zip(forced.cameras, anns)]
    assert all(g >= o - 1e-6 for g, o in zip(got, own)), [(t, g, o) for t, (g, o) in enumerate(zip(got, own)) if g < o]


def _frame(seed: int = 4):
    """A clean synthetic frame: its true camera and its annotation's observations."""
    plan, anns = _annotated_clip(seed, 1)
    fc = calibrate_frame(FrameInputs((W, H), annotation=anns[0]))
    return plan.cameras[0], fc.observations, fc.camera


def _moved(cam: Camera, px: float) -> Camera:
    """``cam`` turned so that the image moves by about ``px`` pixels."""
    from dataclasses import replace

    from pnlviz.geometry.so3 import so3_exp

    return replace(cam, R=so3_exp(np.array([0.0, px / cam.fx, 0.0])) @ cam.R)


def test_a_frame_keeps_its_own_camera_only_where_the_shot_is_clearly_worse():
    model = load_field_model()
    truth, obs, own = _frame()
    data = FrameData.build(obs, model)
    p = TemporalParams()
    # the shot's camera within the noise of the frame's own: the shot's
    near = judge_frame(data, _moved(own, 1.0), own, p)
    assert near.use == "shot" and not near.worse
    # 10 px off where the frame's own camera fits every item within a pixel: the frame's own, saying what it misses
    far = judge_frame(data, _moved(own, 10.0), own, p)
    assert far.use == "own" and far.worse and "misses" in far.reason
    # a frame of three keypoints: its own camera interpolates them and cannot vouch for itself
    few = obs.subset(np.arange(obs.n_keypoints) < 3)
    few = Observations(few.width, few.height, few.kp_ids, few.kp_xy, few.kp_xyz, few.kp_sets, few.kp_main)
    fd = FrameData.build(few, model)
    assert judge_frame(fd, _moved(own, 10.0), own, p).use == "shot"
    # no camera of its own: the shot carries it; a shot that did not converge gives none
    assert judge_frame(data, _moved(own, 10.0), None, p).use == "shot"
    assert judge_frame(data, _moved(own, 30.0), None, p).use == "none"  # fails the verdict, nothing to keep
    assert judge_frame(data, truth, own, p, converged=False).use == "own"
    assert judge_frame(None, truth, own, p).use == "none"
    # distances measured on another frame (another number of keypoints) are refused, not misread
    from pnlviz.calib.shot_fit import distances

    other = distances(fd, own)  # the three-keypoint frame's
    for mixed in ({"shot_distances": other}, {"own_distances": other}):
        with pytest.raises(ValueError, match=f"distances of 3 keypoints for a frame of {obs.n_keypoints}"):
            judge_frame(data, own, own, p, **mixed)


def test_the_shot_fits_circles_as_the_frame_does():
    """A shot whose frames see only the centre circle and the halfway line (no keypoint), started
    from one camera 6 px off: the shot's cameras come back on the truth, which needs the circle's
    points in the shot's problem (the line alone leaves the camera free to slide along it)."""
    from pnlviz.calib.shot_fit import fit_shot

    model = load_field_model()
    truth = [Camera.from_look_at((0.0, 60.0, -18.0), (2.0 * t - 6, 0.0, 0.0), hfov_deg=30, width=W, height=H)
             for t in range(8)]
    obs, start = [], []
    for t, cam in enumerate(truth):
        arc = model.circles["Circle central"].point_at(np.linspace(0, 2 * np.pi, 40))
        uv, z = cam.project_with_depth(arc)
        circle = uv[(z > 0) & cam.in_image(uv)]
        seg = model.lines["Middle line"]
        mid = cam.project(seg.start + np.linspace(0, 1, 20)[:, None] * (seg.end - seg.start))
        mid = mid[cam.in_image(mid)]
        obs.append(Observations(W, H, lines={"Middle line": mid}, circles={"Circle central": circle}))
        start.append(_moved(cam, 6.0) if t == 0 else None)
    fit = fit_shot(obs, start, (W, H), TemporalParams(fit_k1=False))
    for t in range(8):
        pa = truth[t].project(model.circles["Circle central"].point_at(np.linspace(0, 6, 30)))
        pb = fit.cameras[t].project(model.circles["Circle central"].point_at(np.linspace(0, 6, 30)))
        assert np.median(np.linalg.norm(pa - pb, axis=1)) < 1.0


def test_one_rule_says_which_frames_are_a_clip():
    """The same groups for the command line, the app's timeline and its shot models: named frames
    that follow each other; a split's plain frames, numbered frames and separate pictures are not."""
    from pnlviz.app.timeline import clip_index
    from pnlviz.data.layout import video_clips
    from pnlviz.pipeline.clip import dataset_clips

    stems = ([f"train/{i:05d}" for i in range(6)] + [f"valid/{i:05d}" for i in range(4)]
             + [f"valid/match-IMG_{i}" for i in (1, 2, 3, 5)] + ["wc14_3", "wc14_8", "wc14_11"]
             + [f"m2_frame{i}" for i in range(2)])
    groups = video_clips(stems)
    assert groups == {"valid/match": [f"valid/match-IMG_{i}" for i in (1, 2, 3, 5)]}
    assert dataset_clips(stems) == groups
    assert clip_index(stems) == {"valid/match": [stems.index(s) for s in groups["valid/match"]]}
    assert video_clips([f"{i:05d}" for i in range(24)]) == {}  # the bundled sample's names


def test_unrelated_pictures_named_as_a_clip_keep_their_own_cameras():
    """Nine frames named v-IMG_1..9, each from another broadcast (another camera position): the
    cut rule finds a cut before almost every frame, so they are not calibrated as a clip; each keeps
    its own camera and says why."""
    anns, own, obs = [], [], []
    for seed in range(20, 29):
        plan, a = _annotated_clip(seed, 1)
        fc = calibrate_frame(FrameInputs((W, H), annotation=a[0]))
        anns.append(a[0])
        own.append(fc.camera)
        obs.append(fc.observations)
    res = calibrate_clip(obs, own, (W, H))
    assert res.unrelated is not None and "not a clip" in res.unrelated
    assert all(a is b for a, b in zip(res.cameras, own))
    assert all(c.use == ("own" if cam is not None else "none") and "not a clip" in c.reason
               for c, cam in zip(res.choices, own))


def test_a_frame_alone_in_preferring_its_own_camera_keeps_the_shots():
    """A broadcast camera moves smoothly: the shot's camera cannot be wrong on one frame only.
    A frame whose items prefer its own camera while its neighbours' do not has observations that
    are off (its own camera follows them): it keeps the shot's camera, reported suspect; three
    frames in a row (or a whole shorter shot) keep their own, and so does a frame beside one whose
    shot camera fails its verdict."""
    from pnlviz.calib.shot_check import CameraChoice, alone_kept_by_shot

    own = CameraChoice("own", "the shot's camera misses keypoint 4 (9 px, own 0.5), which the frame's own camera fits",
                       ("keypoint 4", "keypoint 7"), (), by_items=True)
    shot = CameraChoice("shot", "the shot's camera fits the frame as well as its own")
    verdict = CameraChoice("own", "the shot's camera fails the frame's verdict (keypoint RMS 20.0 px > 15.0)")
    got = alone_kept_by_shot([shot, own, shot, own, own, own, shot, verdict, shot])
    assert [c.use for c in got] == ["shot", "shot", "shot", "own", "own", "own", "shot", "own", "shot"]
    assert "suspect observations" in got[1].reason and got[1].worse == own.worse
    assert [c.use for c in alone_kept_by_shot([own, own])] == ["own", "own"]  # the whole shot
    # beside a frame whose shot camera fails its verdict, the shot's camera is wrong there too: not alone
    assert [c.use for c in alone_kept_by_shot([shot, shot, own, verdict, shot, shot])] == [
        "shot", "shot", "own", "own", "shot", "shot"]


def test_the_shots_robust_loss_leaves_the_pins_out():
    """The soft-L1 loss bends at ``robust`` on every row of the shot's problem but a pin's, which
    has a bounded loss of its own and is squared. The bends line up with the rows the problem
    evaluates: the rows a move of the pin changes are exactly the squared ones."""
    from dataclasses import replace

    from pnlviz.calib.shot import ShotProblem, frame_data
    from pnlviz.calib.shot_fit import initial

    plan, anns = _annotated_clip(5, 6)
    clip = calibrate_clip_frames([FrameInputs((W, H), annotation=a) for a in anns], FrameSettings())
    obs = list(clip.observations)
    assert all(o.lines for o in obs) and obs[2].n_keypoints >= 2
    pinned = np.zeros(obs[2].n_keypoints, bool)
    pinned[1] = True
    obs[2] = replace(obs[2], kp_pinned=pinned)
    C, k1, per = initial(clip.per_frame, len(obs))
    x = np.concatenate([C, [k1], per.ravel()])

    def problem(observations):
        return ShotProblem(frame_data(observations, load_field_model()), (W, H), TemporalParams())

    m = problem(obs)
    bends = m.loss_bends(1.5)
    r, _ = m.evaluate(x)
    assert bends.shape == r.shape and m.n_data < len(r)
    moved = obs[2].kp_xy.copy()
    moved[1] += 10.0
    changed = problem(obs[:2] + [replace(obs[2], kp_xy=moved)] + obs[3:]).evaluate(x)[0] != r
    assert np.array_equal(np.flatnonzero(changed), np.flatnonzero(np.isinf(bends))), "the pin's rows"
    assert np.sum(changed) == 2 and np.all(bends[~changed] == 1.5)  # the other observations and the priors
    assert problem(clip.observations).loss_bends(1.5) == 1.5  # no pin: one bend for every row
