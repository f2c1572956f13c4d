"""Homography-only calibration (planar estimation): exact recovery, voting under outliers, PnL,
Jacobian, gating, failure reasons, and the WC14 metrics on the published detections."""

from pathlib import Path

import numpy as np

from pnlviz.calib.homography import (
    HomographyKind, HomographyParams, HomographyResult, estimate_homography, template_homography,
)
from pnlviz.calib.observations import Observations
from pnlviz.calib.problem import FrameData
from pnlviz.field import load_field_model
from pnlviz.geometry import Camera, visible_pitch
from pnlviz.metrics.homography import homography_from_camera
from pnlviz.synth import sample_camera
from helpers import needs_shared

MODEL = load_field_model()
SHARED = Path(__file__).resolve().parents[2] / "shared"
WC14 = SHARED / "data" / "wc14_test_half"


def cameras(seed, n, kind="main"):
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < n:
        cam, _ = sample_camera(rng, 960, 540, kind=kind)
        out.append(Camera(cam.fx, cam.fy, cam.cx, cam.cy, cam.R, cam.C, 960, 540))  # no distortion
    return out


def keypoint_obs(cam, rng=None, noise=0.0, outliers=0.0, lines=False, circles=False):
    uv, z = cam.project_with_depth(MODEL.keypoint_xyz())
    ok = (z > 0) & cam.in_image(uv)
    ids, uv = MODEL.keypoint_ids[ok], uv[ok]
    if rng is not None:
        uv = uv + rng.normal(0, noise, uv.shape)
        bad = rng.random(len(ids)) < outliers
        uv[bad] += rng.uniform(40, 150, (bad.sum(), 2)) * rng.choice([-1, 1], (bad.sum(), 2))
    vis = visible_pitch(cam) if lines or circles else {}
    seen = {k: v[:: max(1, len(v) // 4)] for k, v in vis.items() if k in MODEL.lines} if lines else {}
    arcs = {k: v[:: max(1, len(v) // 6)] for k, v in vis.items() if k in MODEL.circles and len(v) > 3} if circles else {}
    return Observations.from_keypoints(960, 540, {int(k): p for k, p in zip(ids, uv)}, lines=seen, circles=arcs)


def unit(H):
    H = np.asarray(H, float) / np.linalg.norm(H)
    return H if np.linalg.det(H) > 0 else -H


def pitch_mapping_error(cam, H):
    """Pixel distance between the true and the estimated images of the visible ground markings."""
    pts = np.vstack([v for k, v in visible_pitch(cam, spacing=1.0).items()
                     if k in MODEL.lines and MODEL.lines[k].plane == "ground"])
    X = cam.back_project_to_ground(pts)[:, :2]
    h = np.hstack([X, np.ones((len(X), 1))]) @ np.asarray(H).T
    return np.linalg.norm(h[:, :2] / h[:, 2:] - pts, axis=1)


# ------------------------------------------------------------------------------ synthetic
def test_exact_ground_keypoints_give_the_camera_ground_homography():
    done = 0
    for cam in cameras(0, 30):
        obs = keypoint_obs(cam)
        if obs.ground.sum() < 5:
            continue
        res = estimate_homography(obs)
        assert res.ok, res.failure
        Hg = unit(cam.ground_homography())
        assert np.linalg.norm(unit(res.H) - Hg) < 1e-6
        # returned convention: unit norm, positive depth of the visible points, det > 0
        assert abs(np.linalg.norm(res.H) - 1) < 1e-12 and np.linalg.det(res.H) > 0
        assert np.all(obs.kp_xyz[obs.ground, :2] @ res.H[2, :2] + res.H[2, 2] > 0)
        assert max(res.point_residuals.values()) < 1e-3
        assert set(res.point_residuals) == set(obs.kp_ids[obs.ground].tolist())
        # the WC14 form (template yards -> 1280 x 720) agrees with the camera's
        Ht = res.template_homography((1280, 720))
        assert np.linalg.norm(unit(Ht) - unit(homography_from_camera(cam))) < 1e-6
        if done == 0:  # and the camera closest to H is the camera
            back = res.camera()
            assert abs(back.fx / cam.fx - 1) < 1e-6 and np.linalg.norm(back.C - cam.C) < 1e-4
        done += 1
    assert done >= 20


def test_voting_maps_the_pitch_within_a_few_pixels_with_noise_and_outliers():
    rng = np.random.default_rng(1)
    medians, n = [], 0
    for cam in cameras(2, 30):
        obs = keypoint_obs(cam, rng, noise=1.0, outliers=0.2, lines=True)
        if obs.ground.sum() < 8:
            continue
        n += 1
        res = estimate_homography(obs)
        assert res.ok, res.failure
        err = pitch_mapping_error(cam, res.H)
        assert np.median(err) < 2.0 and np.percentile(err, 90) < 5.0
        medians.append(np.median(err))
        # the outliers are not inliers of the winning candidate
        uv = cam.project(obs.kp_xyz)
        true_out = obs.kp_ids[np.linalg.norm(uv - obs.kp_xy, axis=1) > 20]
        assert not set(true_out.tolist()) & set(res.inliers.tolist())
    assert n >= 20 and np.median(medians) < 1.0


def test_pnl_with_exact_lines_corrects_noisy_points():
    rng = np.random.default_rng(3)
    gains = []
    for cam in cameras(4, 15):
        obs = keypoint_obs(cam, rng, noise=3.0, lines=True)  # bad points, exact lines
        if obs.ground.sum() < 6 or len(obs.lines) < 3:
            continue
        base = estimate_homography(obs)
        pnl = estimate_homography(obs, pnl=True)
        assert pnl.pnl_lines, "lines consistent with the initial homography join the PnL set"
        assert np.array_equal(pnl.initial_H, base.H)
        gains.append(np.median(pitch_mapping_error(cam, base.H)) - np.median(pitch_mapping_error(cam, pnl.H)))
        # residual reports before/after
        assert pnl.line_residuals_initial.keys() == pnl.line_residuals.keys()
        assert np.median(list(pnl.line_residuals.values())) < np.median(list(pnl.line_residuals_initial.values()))
    assert len(gains) >= 8 and np.median(gains) > 0.3


def test_pnl_keeps_an_exact_homography_and_uses_circles():
    cam = cameras(5, 1)[0]
    obs = keypoint_obs(cam, lines=True, circles=True)
    res = estimate_homography(obs, pnl=True)
    assert np.linalg.norm(res.initial_H - unit(cam.ground_homography())) < 1e-6
    joined = res.pnl_lines
    assert joined and set(joined) <= {k for k in obs.lines if MODEL.lines[k].plane == "ground"} | set(obs.circles)
    assert set(joined) & set(obs.circles)
    assert np.percentile(pitch_mapping_error(cam, res.H), 99) < 0.05


def test_pnl_gate_keeps_a_wrong_line_out():
    cam = cameras(6, 1)[0]
    rng = np.random.default_rng(6)
    obs = keypoint_obs(cam, rng, noise=0.5, lines=True)
    ground = [k for k in obs.lines if MODEL.lines[k].plane == "ground"]
    bad = ground[0]
    obs.lines[bad] = obs.lines[bad] + np.array([0.0, 60.0])  # a misdetected line, 60 px off
    res = estimate_homography(obs, pnl=True)
    assert res.ok and bad not in res.pnl_lines and set(res.pnl_lines) == set(ground) - {bad}
    assert np.median(pitch_mapping_error(cam, res.H)) < 1.0


def test_analytic_jacobian_matches_finite_differences():
    cam = cameras(7, 1)[0]
    rng = np.random.default_rng(7)
    obs = keypoint_obs(cam, rng, noise=2.0, lines=True, circles=True)
    # points beyond the segment ends too, so that the overshoot term is active
    name = next(k for k in obs.lines if MODEL.lines[k].plane == "ground")
    p = obs.lines[name]
    obs.lines[name] = np.vstack([p, p[-1] + 3 * (p[-1] - p[0])]) + 1.5
    kind = HomographyKind(FrameData.build(obs, MODEL), HomographyParams())
    problem, model = kind.problem(0.6), kind.model
    assert len(problem.line_pts) and problem.circle_items
    M = model.retract(model.start(unit(cam.ground_homography())), rng.normal(0, 1e-3, 8))
    r, J = problem.evaluate(M, jac=True)
    assert J.shape == (len(r), 8) and len(r) == problem.n_res
    h = 1e-7
    for k in range(8):
        d = np.zeros(8)
        d[k] = h
        num = (problem.residuals(model.retract(M, d)) - problem.residuals(model.retract(M, -d))) / (2 * h)
        np.testing.assert_allclose(J[:, k], num, atol=1e-4 * np.abs(J).max())


def test_failures_come_back_with_a_reason():
    res = estimate_homography(Observations(960, 540))
    assert isinstance(res, HomographyResult) and not res.ok and "too few ground keypoints" in res.failure
    cam = Camera.from_look_at([0, 50, -15], [0, 0, 0], hfov_deg=40, width=960, height=540)
    # the goal mouth only: 5 keypoints, 3 of them on the ground
    cam_goal = Camera.from_look_at([-40, 30, -12], [-52.5, 0, -1], hfov_deg=30, width=960, height=540)
    ids = [12, 13, 16, 17, 8]
    uv = cam_goal.project(MODEL.keypoint_xyz(ids))
    res = estimate_homography(Observations.from_keypoints(960, 540, {i: q for i, q in zip(ids, uv)}))
    assert not res.ok and "too few ground keypoints (3 < 4)" in res.failure
    # four collinear keypoints on the halfway line: no homography
    ids = [2, 32, 35, 29]
    uv = cam.project(MODEL.keypoint_xyz(ids))
    res = estimate_homography(Observations.from_keypoints(960, 540, {i: q for i, q in zip(ids, uv)}))
    assert not res.ok and "degenerate" in res.failure


def test_template_homography_scales_pixels_and_composes_the_template_map():
    H = unit(cameras(8, 1)[0].ground_homography())
    Ht = template_homography(H, 960, 540, (1280, 720))
    t = np.array([[10.0, 20.0], [57.5, 37.0], [100.0, 70.0]])
    X = MODEL.template_to_field(t)
    a = np.hstack([t, np.ones((3, 1))]) @ Ht.T
    b = np.hstack([X, np.ones((3, 1))]) @ H.T
    np.testing.assert_allclose(a[:, :2] / a[:, 2:], b[:, :2] / b[:, 2:] * (1280 / 960), rtol=1e-12)


# ------------------------------------------------------------------------------ real data
@needs_shared
def test_wc14_pnl_does_not_lower_iou_part():
    from pnlviz.calib.inputs import observations_from_predictions
    from pnlviz.data import read_homographies, read_predictions
    from pnlviz.metrics.homography import iou_part

    preds = read_predictions(WC14 / "detections_pnlcalib.zip")
    gt = read_homographies(WC14 / "homographies.json")
    T = MODEL.template_to_field_matrix
    base, pnl, joined = [], [], 0
    for stem, H_gt in gt.items():
        obs = observations_from_predictions(preds[stem], 1280, 720, model=MODEL)
        res = estimate_homography(obs, model=MODEL)
        refined = estimate_homography(obs, pnl=True, model=MODEL)
        assert res.ok and refined.ok, (stem, res.failure, refined.failure)
        assert np.array_equal(refined.initial_H, res.H)
        joined += bool(refined.pnl_lines)
        base.append(iou_part(H_gt, res.template_homography(model=MODEL)))
        pnl.append(iou_part(H_gt, refined.H @ T))
    assert len(base) == 93 and joined >= 80
    assert np.mean(base) > 0.95  # published detections, no fine-tuning on WC14
    assert np.mean(pnl) >= np.mean(base) - 0.005
