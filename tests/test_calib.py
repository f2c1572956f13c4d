"""Calibration engine: exact recovery, robustness, PnL, failure reasons, real-data scores."""

import json
import zipfile

import numpy as np
import pytest

from pnlviz.calib.calibrate import CalibParams, calibrate
from pnlviz.calib.inputs import observations_from_annotation, observations_from_predictions
from pnlviz.calib.observations import Observations
from pnlviz.calib.refine import CameraProblem, RefineParams
from pnlviz.geometry.so3 import so3_exp
from pnlviz.cli import main as cli_main
from pnlviz.field import load_field_model
from pnlviz.geometry import Camera, visible_pitch
from pnlviz.synth import sample_camera

MODEL = load_field_model()


def cameras(seed, n, kind=None):
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < n:
        cam, _ = sample_camera(rng, 960, 540, kind=kind)
        out.append(Camera(cam.fx, cam.fy, cam.cx, cam.cy, cam.R, cam.C, 960, 540))  # no distortion
    return out


def keypoint_obs(cam, rng=None, noise=0.0, outliers=0.0, lines=False):
    uv, z = cam.project_with_depth(MODEL.keypoint_xyz())
    ok = (z > 0) & cam.in_image(uv)
    ids, uv = MODEL.keypoint_ids[ok], uv[ok]
    if rng is not None:
        uv = uv + rng.normal(0, noise, uv.shape)
        bad = rng.random(len(ids)) < outliers
        uv[bad] += rng.uniform(40, 150, (bad.sum(), 2)) * rng.choice([-1, 1], (bad.sum(), 2))
    seen = {}
    if lines:
        seen = {k: v[:: max(1, len(v) // 4)] for k, v in visible_pitch(cam).items() if k in MODEL.lines}
    return Observations.from_keypoints(960, 540, {int(k): p for k, p in zip(ids, uv)}, lines=seen)


def test_noise_free_keypoints_recover_focal_and_position_to_1e_3():
    done = 0
    for cam in cameras(0, 40):
        obs = keypoint_obs(cam)
        if obs.n_keypoints < 6:
            continue
        res = calibrate(obs, CalibParams(pnl=False, refine_k1=False))
        assert res.ok, res.failure
        assert abs(res.camera.fx / cam.fx - 1) < 1e-3
        assert np.linalg.norm(res.camera.C - cam.C) / np.linalg.norm(cam.C) < 1e-3
        done += 1
    assert done >= 25


def test_voting_finds_the_camera_with_1px_noise_and_20_percent_outliers():
    rng = np.random.default_rng(1)
    focal_err, pos_err, n = [], [], 0
    for cam in cameras(2, 40, kind="main"):
        obs = keypoint_obs(cam, rng, noise=1.0, outliers=0.2, lines=True)
        if obs.n_keypoints < 8:
            continue
        n += 1
        res = calibrate(obs)
        assert res.ok, res.failure
        focal_err.append(abs(res.camera.fx / cam.fx - 1))
        pos_err.append(np.linalg.norm(res.camera.C - cam.C) / np.linalg.norm(cam.C))
        # the outliers are not inliers of the winning candidate
        uv = cam.project(obs.kp_xyz)
        true_out = obs.kp_ids[np.linalg.norm(uv - obs.kp_xy, axis=1) > 20]
        assert not set(true_out) & set(res.inliers.tolist())
    assert n >= 20
    assert np.median(focal_err) < 0.01 and np.percentile(focal_err, 90) < 0.03
    assert np.median(pos_err) < 0.01 and np.percentile(pos_err, 90) < 0.03


def test_goal_plane_alone_gives_a_camera():
    """Only the goal mouth: posts, crossbar corners and points on the goal line (plane x = -52.5)."""
    cam = Camera.from_look_at([-40, 30, -12], [-52.5, 0, -1], hfov_deg=30, width=960, height=540)
    ids = [12, 13, 16, 17, 8]  # crossbar corners, post feet, small-box corner on the goal line
    uv = cam.project(MODEL.keypoint_xyz(ids))
    assert cam.in_image(uv).all()
    obs = Observations.from_keypoints(960, 540, {i: p for i, p in zip(ids, uv)})
    assert obs.ground.sum() == 3  # too few for a ground homography: the goal plane must do
    res = calibrate(obs, CalibParams(pnl=False, refine_k1=False))
    assert res.ok and res.plane == "goal_left", (res.failure, res.plane)
    assert abs(res.camera.fx / cam.fx - 1) < 1e-3


def test_pnl_uses_lines_to_correct_noisy_points():
    rng = np.random.default_rng(3)
    gains = []
    for cam in cameras(4, 15, kind="main"):
        obs = keypoint_obs(cam, rng, noise=3.0, lines=True)  # bad points, exact lines
        if obs.n_keypoints < 6 or len(obs.lines) < 3:
            continue
        base = calibrate(obs, CalibParams(pnl=False, refine_focal=False, refine_k1=False))
        pnl = calibrate(obs, CalibParams(refine_focal=False, refine_k1=False))
        assert pnl.pnl_lines, "lines consistent with the initial camera join the PnL set"

        def err(c):
            uv = cam.project(MODEL.keypoint_xyz())
            uv2 = c.project(MODEL.keypoint_xyz())
            ok = cam.in_image(uv)
            return np.median(np.linalg.norm(uv[ok] - uv2[ok], axis=1))

        gains.append(err(base.camera) - err(pnl.camera))
    assert len(gains) >= 8 and np.median(gains) > 0.3


def test_failures_come_back_with_a_reason():
    res = calibrate(Observations(960, 540))
    assert not res.ok and "too few keypoints" in res.failure
    # four collinear keypoints on the halfway line: no homography
    ids = [2, 32, 35, 29]
    cam = Camera.from_look_at([0, 50, -15], [0, 0, 0], hfov_deg=40, width=960, height=540)
    uv = cam.project(MODEL.keypoint_xyz(ids))
    res = calibrate(Observations.from_keypoints(960, 540, {i: p for i, p in zip(ids, uv)}),
                    CalibParams(prior_search=False))
    assert not res.ok and "degenerate" in res.failure


def test_analytic_jacobian_matches_finite_differences():
    """Every column of the Jacobian (rotation, centre, log focal, k1) against central differences
    of the residuals, through the model's own update, with keypoints, lines and circles."""
    cam = Camera.from_look_at([5, 50, -15], [-30, 0, 0], hfov_deg=40, width=960, height=540, k1=0.05)
    rng = np.random.default_rng(5)
    vis = visible_pitch(cam)
    obs = keypoint_obs(cam, rng, noise=2.0)
    obs.lines = {k: v[::3] + 2.0 for k, v in vis.items() if k in MODEL.lines}
    obs.circles = {k: v[::3] + 1.0 for k, v in vis.items() if k in MODEL.circles}
    prob = CameraProblem(cam, obs, RefineParams(refine_focal=True, refine_k1=True))
    state = prob.model.start()
    _, J = prob.problem.evaluate(state, jac=True)
    assert J.shape == (prob.n_res, 8) and prob.n_res > 100
    h = 1e-6
    for i in range(8):
        d = np.zeros(8)
        d[i] = h
        plus = prob.problem.residuals(prob.model.retract(state, d))
        minus = prob.problem.residuals(prob.model.retract(state, -d))
        np.testing.assert_allclose(J[:, i], (plus - minus) / (2 * h), atol=2e-3 * np.abs(J).max())


def test_the_solver_takes_a_jacobian_asked_for_at_accepted_steps_and_sparse():
    """The shot's way through the one solver: trial steps evaluated without a Jacobian, the
    Jacobian asked for (sparse) only where a step was accepted, a robust loss; the same minimum as
    with the Jacobian evaluated with every step, and a soft-L1 loss keeps an outlier from pulling
    the fit."""
    import scipy.sparse

    from pnlviz.calib.solver import SolverParams, levenberg_marquardt

    t = np.linspace(0, 1, 40)
    y = 2.0 * np.exp(-1.5 * t)
    y[7] += 3.0  # an outlier

    def residuals(x):
        return x[0] * np.exp(-x[1] * t) - y

    def dense(x, jac):
        e = np.exp(-x[1] * t)
        return residuals(x), (np.column_stack([e, -x[0] * t * e]) if jac else None)

    asked, accepted = [], []

    def lazy(x, jac):
        assert not jac
        return residuals(x), None

    def jacobian(x, r):
        accepted.append(x.copy())
        np.testing.assert_array_equal(r, residuals(x))
        return scipy.sparse.csr_matrix(dense(x, True)[1])

    def retract(x, d):
        asked.append(d)
        return x + d

    params = SolverParams(loss="soft_l1", f_scale=0.1, tol=1e-12)
    a, info_a = levenberg_marquardt(dense, lambda x, d: x + d, np.array([1.0, 1.0]), params)
    b, info_b = levenberg_marquardt(lazy, retract, np.array([1.0, 1.0]), params, jacobian=jacobian)
    np.testing.assert_allclose(b, a, rtol=1e-9)
    np.testing.assert_allclose(b, [2.0, 1.5], atol=0.02)  # the outlier all but left aside
    assert info_b["success"] and len(accepted) <= len(asked) and len(accepted) == info_b["iterations"]
    plain, _ = levenberg_marquardt(dense, lambda x, d: x + d, np.array([1.0, 1.0]), SolverParams(tol=1e-12))
    assert abs(plain[0] - 2.0) > 10 * abs(b[0] - 2.0)  # least squares is pulled by it
    # a limit on rejected steps in a row ends the search sooner than the damping's own limit (a
    # Jacobian of the wrong sign: every step goes uphill)
    calls = []

    def uphill(x, jac):
        calls.append(1)
        r, J = dense(x, jac)
        return r, (-J if jac else None)

    for max_trials, expected in ((3, 1 + 3), (None, 1 + 25)):  # 1e-3 * 4^25 > 1e12
        calls.clear()
        x, info = levenberg_marquardt(uphill, lambda x, d: x + d, np.array([1.0, 1.0]),
                                      SolverParams(max_trials=max_trials))
        assert np.array_equal(x, [1.0, 1.0]) and info["iterations"] == 1 and len(calls) == expected


def test_a_solve_stops_when_its_scope_says_so_and_only_inside_it():
    """Inside ``cancellable``, a solve asks before each iteration and raises ``Cancelled`` (which an
    ``except Exception`` does not swallow) once told; scopes nest, and outside them nothing asks."""
    from pnlviz.calib.solver import Cancelled, cancellable, levenberg_marquardt

    t = np.linspace(0, 1, 20)

    def evaluate(x, jac):
        return x[0] * t + x[1] - (3 * t + 1), (np.column_stack([t, np.ones_like(t)]) if jac else None)

    asked = []

    def after(n):
        return lambda: asked.append(1) or len(asked) > n

    with cancellable(after(2)):
        with pytest.raises(Cancelled):
            try:
                levenberg_marquardt(evaluate, lambda x, d: x + d, np.array([0.0, 0.0]))
            except Exception:  # noqa: BLE001 - what a frame's "internal error" catch does
                pytest.fail("Cancelled was caught as an Exception")
    assert len(asked) == 3  # asked before the start and each iteration until it said yes
    asked.clear()
    with cancellable(lambda: True):
        with cancellable(lambda: asked.append(1) or False):  # the inner scope decides, and lets it run
            x, info = levenberg_marquardt(evaluate, lambda x, d: x + d, np.array([0.0, 0.0]))
        np.testing.assert_allclose(x, [3.0, 1.0])
        assert asked
        with pytest.raises(Cancelled):  # the outer one is back
            levenberg_marquardt(evaluate, lambda x, d: x + d, np.array([0.0, 0.0]))
    x, info = levenberg_marquardt(evaluate, lambda x, d: x + d, np.array([0.0, 0.0]))  # no scope: runs
    np.testing.assert_allclose(x, [3.0, 1.0])
    assert info["success"]


def test_refinement_recovers_focal_pose_and_k1_from_lines_and_circles():
    rng = np.random.default_rng(6)
    for _ in range(10):
        pos = np.array([rng.uniform(-20, 20), rng.uniform(40, 70), -rng.uniform(8, 25)])
        cam = Camera.from_look_at(pos, [rng.uniform(-40, 40), rng.uniform(-20, 15), 0], hfov_deg=rng.uniform(20, 50),
                                  width=960, height=540, k1=rng.uniform(0, 0.08))
        vis = visible_pitch(cam, spacing=0.5)
        obs = keypoint_obs(cam)
        obs.lines = {k: v[1:-1:4] for k, v in vis.items() if k in MODEL.lines and len(v) > 6}
        obs.circles = {k: v[1:-1:6] for k, v in vis.items() if k in MODEL.circles and len(v) > 12}
        start = Camera(cam.fx * 1.05, cam.fy * 1.05, 480, 270, so3_exp(rng.normal(0, 0.01, 3)) @ cam.R,
                       cam.C + rng.normal(0, 1, 3), 960, 540)
        out, info = CameraProblem(start, obs, RefineParams(refine_k1=True)).solve()
        assert info["success"]
        assert abs(out.fx / cam.fx - 1) < 2e-3
        assert abs(out.radial[0] - cam.radial[0]) < 5e-3


# ------------------------------------------------------------------------------ real data
def _scores(gt_zip, cams):
    from pnlviz.metrics.soccernet import evaluate_dataset  # bit-identical to the official evaluator

    return evaluate_dataset(gt_zip, cams, progress=False)


def test_wc14_from_published_detections_beats_pnlcalib_cameras(shared_dir):
    from pnlviz.data import read_predictions

    data = shared_dir / "data" / "wc14_test_half"
    preds = read_predictions(data / "detections_pnlcalib.zip")
    scores = {}
    for name, params in (("pnl", CalibParams()), ("no_pnl", CalibParams(pnl=False, refine_focal=False, refine_k1=False))):
        cams = {}
        for stem, p in preds.items():
            res = calibrate(observations_from_predictions(p, 960, 540), params)
            if res.ok:
                cams[stem] = res.camera
        scores[name] = _scores(data / "annotations.zip", cams)
    pnl = scores["pnl"]
    assert pnl.completeness == 1.0
    assert pnl.jac(5) >= 0.87  # PnLCalib's own cameras: 0.860
    assert pnl.jac(5) > scores["no_pnl"].jac(5)


def test_sn22_cameras_agree_with_the_annotations(shared_dir, tmp_path):
    from pnlviz.data import open_dataset
    from pnlviz.metrics.soccernet import evaluate_dataset

    src = shared_dir / "data" / "sn22_test_subset" / "annotations.zip"
    ds = open_dataset(src)
    stems = ds.stems[::4]  # 100 of the 400 frames
    gt = tmp_path / "gt.zip"
    with zipfile.ZipFile(gt, "w") as zf, zipfile.ZipFile(src) as zsrc:
        for stem in stems:
            zf.writestr(f"{stem}.json", zsrc.read(f"{stem}.json"))
    cams = {}
    for stem in stems:
        obs, _ = observations_from_annotation(ds.annotation(stem), 960, 540)
        res = calibrate(obs)
        if res.ok:
            cams[stem] = res.camera
    summary = evaluate_dataset(gt, cams, progress=False)
    assert summary.completeness >= 0.97
    assert summary.final_score >= 0.85  # the authors' calibration code on the same inputs: 0.689


def test_calibrate_cli_writes_an_evaluator_ready_zip_and_a_report(tmp_path):
    from pnlviz import EXAMPLES_DIR

    out, report = tmp_path / "cams.zip", tmp_path / "report.jsonl"
    assert cli_main(["calibrate", "--data", str(EXAMPLES_DIR / "sample"), "--out", str(out), "--report", str(report),
                     "--no-progress"]) == 0
    with zipfile.ZipFile(out) as zf:
        names = zf.namelist()
        assert all(n.startswith("camera_") and "/" not in n for n in names)
        cam = json.loads(zf.read(names[0]))
        assert cam["principal_point"] == [480.0, 270.0]
    rows = [json.loads(line) for line in report.read_text().splitlines()]
    assert len(rows) == 32 and len(names) >= 30
    assert all("point_residuals" in r for r in rows if r["stem"] in {n[7:-5] for n in names})
    # the sample's keypoints come from its annotations, derived from its lines: where a frame's
    # PnL holds 4 classes or more the report lists them as left out of the fit
    calibrated = [r for r in rows if r["stem"] in {n[7:-5] for n in names}]
    assert all((set(r["lines_alone"]) <= set(map(int, r["point_residuals"]))) for r in calibrated)
    assert any(r["lines_alone"] for r in calibrated if len(r["pnl_lines"]) >= 4)
    assert not any(r["lines_alone"] for r in calibrated if len(r["pnl_lines"]) < 4)
    # synthetic frames: the cameras agree with the ground truth
    from pnlviz.metrics.soccernet import evaluate_dataset

    summary = evaluate_dataset(EXAMPLES_DIR / "sample", out, progress=False)
    assert summary.jac(5) > 0.9


def test_tightening_never_leaves_more_beyond_and_pulls_some_in(shared_dir):
    """``CameraProblem.tighten`` on real SN22 frames (every 8th, from their annotations), on the
    problem the final fit solved (its classes and keypoints): from the least-squares camera,
    never more classes or keypoints beyond the tolerance, and fewer on some frames."""
    from pnlviz.calib.calibrate import pin_settings
    from pnlviz.calib.pipeline import lines_alone
    from pnlviz.calib.problem import FrameData
    from pnlviz.data import open_dataset

    ds = open_dataset(shared_dir / "data" / "sn22_test_subset" / "annotations.zip")
    loose = CalibParams(class_tolerance_px=0.0, border_aim_px=0.0)
    model = load_field_model()
    fewer = 0
    for stem in ds.stems[::8]:
        obs, _ = observations_from_annotation(ds.annotation(stem), 960, 540)
        res = calibrate(obs, loose)
        if not res.ok:
            continue
        data = FrameData.build(obs, model)
        lines = [n for n in res.pnl_lines if n in obs.lines]
        circles = [n for n in res.pnl_lines if n in obs.circles]
        fitted = lines_alone(obs, loose, np.ones(obs.n_keypoints, bool), lines, circles)
        prob = CameraProblem(res.camera, data, RefineParams(alpha=loose.alpha, refine_focal=True, refine_k1=True,
                                                            **pin_settings(loose, 960, obs)),
                             use_keypoints=fitted, lines=lines, circles=circles)
        before = prob.beyond(res.camera, 4.0)
        tight = prob.tighten(res.camera, 4.0)
        after = prob.beyond(tight, 4.0)
        assert len(after) <= len(before), stem
        if tight is res.camera:
            assert after == before
        else:
            fewer += 1
            assert len(after) < len(before), stem
    assert fewer >= 3, fewer


def test_aim_inside_moves_only_the_points_on_the_border_and_keeps_its_input():
    from pnlviz.calib.problem import aim_inside

    pts = np.array([[0.0, 200.0], [959.0, 100.0], [300.0, 539.0], [400.0, 0.4], [958.2, 538.0], [480.0, 270.0],
                    [2.0, 3.0]])
    kept = pts.copy()
    out = aim_inside(pts, 960, 540, 2.0)
    assert np.array_equal(pts, kept)  # a copy
    expected = np.array([[2.0, 200.0], [957.0, 100.0], [300.0, 537.0], [400.0, 2.4], [956.2, 536.0],
                         [480.0, 270.0], [2.0, 3.0]])  # 2 px from the border is not on it
    assert np.allclose(out, expected)
    # at another width, "on the border" and the inset are the caller's pixels (1.5 px at 960 scales)
    assert np.allclose(aim_inside([[2.5, 100.0]], 1920, 1080, 4.0), [[6.5, 100.0]])


def test_border_points_aimed_inside_keep_frames_calibrated_and_residuals_as_observed(shared_dir):
    """Real SN22 frames (every 4th of those with an annotated line point on the image border):
    fitted with the border points aimed 2 px inside (the default), no frame loses its camera, and
    the residuals the result reports are against the points as observed, not the aimed ones (the
    score of the whole set: tests/test_calib_lines_alone.py)."""
    from pnlviz.calib.calibrate import line_residuals
    from pnlviz.calib.problem import FrameData, aim_inside
    from pnlviz.data import open_dataset

    ds = open_dataset(shared_dir / "data" / "sn22_test_subset" / "annotations.zip")
    as_seen = CalibParams(border_aim_px=0.0)
    model = load_field_model()
    checked, frames = 0, 0
    for stem in ds.stems:
        obs, _ = observations_from_annotation(ds.annotation(stem), 960, 540)
        if not any((aim_inside(pts, 960, 540, 2.0) != pts).any() for pts in obs.lines.values()):
            continue
        frames += 1
        if frames % 4:
            continue
        aimed, plain = calibrate(obs), calibrate(obs, as_seen)
        assert aimed.ok >= plain.ok, stem
        if not aimed.ok:
            continue
        reported = line_residuals(aimed.camera, FrameData.build(obs, model))
        assert reported == pytest.approx(aimed.line_residuals), stem
        checked += 1
    assert checked >= 40, checked


def test_annotation_observations_are_computed_once_and_shared_read_only():
    from pnlviz import EXAMPLES_DIR
    from pnlviz.calib.inputs import annotation_observations
    from pnlviz.data import open_dataset

    ds = open_dataset(EXAMPLES_DIR / "sample")
    model = load_field_model()
    ann = ds.annotation(ds.stems[2])
    fresh, _ = observations_from_annotation(ann, 960, 540, model=model)
    first = annotation_observations(ann, 960, 540, model)
    again = annotation_observations({k: np.array(v) for k, v in ann.items()}, 960, 540, model)  # equal content
    for obs in (first, again):  # what the frame pipeline computed before
        for name in ("kp_ids", "kp_xy", "kp_xyz", "kp_sets", "kp_main", "kp_derived"):
            np.testing.assert_array_equal(getattr(obs, name), getattr(fresh, name))
        assert obs.lines.keys() == fresh.lines.keys() and obs.circles.keys() == fresh.circles.keys()
    assert again.kp_xy is first.kp_xy  # computed once
    with pytest.raises(ValueError):  # shared: no caller can change it for the others
        again.kp_xy[0, 0] = 0.0
    again.lines.pop(next(iter(again.lines)))  # each caller's own dicts
    assert first.lines.keys() == fresh.lines.keys()
    assert annotation_observations(ann, 960, 540, model).lines.keys() == fresh.lines.keys()
    # another annotation (one point of one line moved), another size: computed anew
    moved = {k: np.array(v) for k, v in ann.items()}
    line = next(k for k in moved if k in model.lines)
    moved[line][0] += 0.01
    assert annotation_observations(moved, 960, 540, model).kp_xy is not first.kp_xy
    assert annotation_observations(ann, 1280, 720, model).width == 1280


def test_the_soft_l1_losss_own_curvature_reaches_the_same_minimum_in_fewer_steps():
    """A line fitted to 100 points under a soft-L1 loss that bends at 0.05, with one heavy row
    outside the loss (np.inf: squared, as a shot's pin) pulling it 1 unit off at x = 1: most points
    end past the bend. The reweighting's normal equations overstate the curvature there 1 + s
    times, and its steps crawl; with the loss's own curvature (``exact_curvature``) the solver
    lands on the same minimum in a fraction of the iterations."""
    from pnlviz.calib.solver import SolverParams, levenberg_marquardt

    rng = np.random.default_rng(3)
    x = np.linspace(-1, 1, 100)
    y = 2.0 * x + 0.5 + rng.normal(0, 0.02, 100)
    J = np.vstack([np.column_stack([x, np.ones_like(x)]), [30.0, 30.0]])

    def evaluate(p, jac=False):
        return np.r_[p[0] * x + p[1] - y, 30.0 * (p[0] + p[1] - 3.5)], (J if jac else None)

    got = {}
    for exact in (False, True):
        params = SolverParams(loss="soft_l1", f_scale=np.r_[np.full(100, 0.05), np.inf], max_iter=500, tol=1e-12,
                              exact_curvature=exact)
        got[exact] = levenberg_marquardt(evaluate, lambda p, d: p + d, np.array([2.0, 0.5]), params)
    (p0, i0), (p1, i1) = got[False], got[True]
    assert i0["success"] and i1["success"]
    assert np.allclose(p0, p1, atol=1e-5) and abs(i0["cost"] - i1["cost"]) < 1e-9 * i0["cost"]
    assert p1[0] + p1[1] > 3.0  # the heavy row is honoured: the line moved most of the way
    assert i1["iterations"] * 3 <= i0["iterations"], (i0["iterations"], i1["iterations"])
