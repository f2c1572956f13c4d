"""The calibration's shortcuts give what the long way gives: a plane fit that kept every point is
not repeated at larger thresholds (its inliers off the plane still follow the threshold); k1 at its
bound does not stall the solver; the pipeline computes the errors of one camera once and hands
them out as copies."""

import numpy as np

import pnlviz.calib.calibrate as calibrate_module
from pnlviz.calib.calibrate import CalibParams, CameraKind, calibrate
from pnlviz.calib.refine import CameraProblem, RefineParams
from pnlviz.geometry import Camera, visible_pitch
from pnlviz.geometry.so3 import so3_exp
from test_calib import MODEL, cameras, keypoint_obs

GOAL_TOP = (12, 16)  # the left crossbar's ends: 2.44 m above the ground


def _counting(monkeypatch) -> dict[bytes, int]:
    """Count the RANSAC plane fits by their input points."""
    calls: dict[bytes, int] = {}
    real = calibrate_module.plane_homography

    def counted(local_xy, xy, threshold):
        key = np.asarray(xy).tobytes()
        calls[key] = calls.get(key, 0) + 1
        return real(local_xy, xy, threshold)

    monkeypatch.setattr(calibrate_module, "plane_homography", counted)
    return calls


def _frame_with_crossbar():
    """A noise-free frame of a synthetic camera that sees the left crossbar and 6+ ground points."""
    for cam in cameras(11, 200):
        obs = keypoint_obs(cam)
        on_ground = np.abs(obs.kp_xyz[:, 2]) < 1e-9
        if on_ground.sum() >= 6 and all(k in obs.kp_ids for k in GOAL_TOP):
            return cam, obs
    raise AssertionError("no synthetic camera sees the crossbar")


def test_a_plane_fit_that_keeps_every_point_runs_once_and_off_plane_inliers_still_follow_the_threshold(monkeypatch):
    _, obs = _frame_with_crossbar()
    off = int(np.flatnonzero(obs.kp_ids == GOAL_TOP[0])[0])
    obs.kp_xy[off] += (7.0, 0.0)  # off the ground plane, 7 px off: an inlier at 10 px, not at 5
    calls = _counting(monkeypatch)
    res = calibrate(obs, CalibParams(pnl=False, refine_k1=False))
    assert res.ok, res.failure
    # every ground point is exact: each subset's ground fit keeps them all at 5 px, and the
    # thresholds 10, 20 and 40 reuse it instead of running RANSAC three more times
    assert calls and set(calls.values()) == {1}
    raw = [c for c in res.candidates if c["stage"] == "candidate" and c["subset"] == "full"]
    by_threshold = {c["threshold"]: c["inliers"] for c in raw}
    n = obs.n_keypoints
    assert by_threshold[5.0] == n - 1 and by_threshold[10.0] == n, by_threshold


def test_a_plane_fit_that_drops_a_point_is_fitted_again_at_the_next_threshold(monkeypatch):
    _, obs = _frame_with_crossbar()
    ground = np.flatnonzero(np.abs(obs.kp_xyz[:, 2]) < 1e-9)
    obs.kp_xy[ground[0]] += (0.0, 8.0)  # a ground point 8 px off: RANSAC at 5 px leaves it out
    calls = _counting(monkeypatch)
    res = calibrate(obs, CalibParams(pnl=False, refine_k1=False))
    assert res.ok, res.failure
    assert max(calls.values()) >= 2  # the 5 px fit did not keep every point: 10 px runs again


def test_k1_at_its_bound_does_not_stall_the_solver():
    """A lens bent more than the bound allows: k1 ends on the bound, and the other parameters
    converge in a few steps instead of zigzagging against the clamp until the iterations run out."""
    rng = np.random.default_rng(3)
    for _ in range(4):
        pos = np.array([rng.uniform(-20, 20), rng.uniform(40, 70), -rng.uniform(8, 25)])
        cam = Camera.from_look_at(pos, [rng.uniform(-40, 40), rng.uniform(-20, 15), 0], hfov_deg=rng.uniform(30, 50),
                                  width=960, height=540, k1=0.6)
        obs = keypoint_obs(cam)
        obs.lines = {k: v[1:-1:4] for k, v in visible_pitch(cam, spacing=0.5).items()
                     if k in MODEL.lines and len(v) > 6}
        start = Camera(cam.fx * 1.05, cam.fy * 1.05, 480, 270, so3_exp(rng.normal(0, 0.01, 3)) @ cam.R,
                       cam.C + rng.normal(0, 1, 3), 960, 540)
        params = RefineParams(refine_k1=True, k1_bound=0.3, max_iter=20, tol=1e-6)
        outcome = {}
        for held in (True, False):
            prob = CameraProblem(start, obs, params)
            if not held:  # the clamp alone, as before the held step
                prob.model.held = lambda state, delta: None
            out, info = prob.solve()
            r = prob.residuals(out)
            outcome[held] = (info, float(r @ r), out.radial[0])
        (info, cost, k1), (info_clamped, cost_clamped, _) = outcome[True], outcome[False]
        assert k1 == 0.3 and info["success"] and info["iterations"] <= 8, info
        assert info_clamped["iterations"] == 20 and not info_clamped["success"]
        assert cost < 0.95 * cost_clamped


def test_the_errors_of_one_camera_are_computed_once_and_handed_out_as_copies(monkeypatch):
    cam, obs = _frame_with_crossbar()
    obs.lines = {k: v[1:-1:4] for k, v in visible_pitch(cam, spacing=0.5).items() if k in MODEL.lines and len(v) > 6}
    from pnlviz.calib.pipeline import _LastErrors  # what the pipeline's steps 3 and 4 ask through

    kind = _LastErrors(CameraKind.of(obs, CalibParams()))
    computed = []
    real = calibrate_module.line_residuals
    monkeypatch.setattr(calibrate_module, "line_residuals",
                        lambda c, data: computed.append(c) or real(c, data))
    first = kind.class_errors(cam)
    first[next(iter(first))] = 1e9  # a caller writing into its copy
    second = kind.class_errors(cam)
    assert len(computed) == 1 and second == real(cam, kind.observed)
    moved = cam.with_pose(cam.R, cam.C + np.array([0.0, 0.0, -1.0]))
    assert kind.class_errors(moved) != second and len(computed) == 2
    points = kind.point_errors(cam)
    points[int(obs.kp_ids[0])] = 1e9
    assert kind.point_errors(cam)[int(obs.kp_ids[0])] < 1e-6


def test_the_solver_skips_the_last_steps_jacobian_and_ends_where_it_did(monkeypatch):
    """The step predicted to end the solve is evaluated without its Jacobian; the solve takes the
    same steps to the same camera, bit for bit, as when every trial has its Jacobian."""
    import pnlviz.calib.solver as solver_module

    cam, _ = _frame_with_crossbar()
    obs = keypoint_obs(cam, np.random.default_rng(5), noise=1.0, lines=True)  # noisy: a minimum above 0
    start = Camera(cam.fx * 1.05, cam.fy * 1.05, 480, 270, so3_exp(np.array([0.01, -0.005, 0.0])) @ cam.R,
                   cam.C + np.array([1.0, -0.5, 0.5]), 960, 540)

    def solve_counting():
        prob = CameraProblem(start, obs, RefineParams(refine_k1=True, tol=1e-6))
        asked = []
        evaluate = prob.problem.evaluate
        prob.problem.evaluate = lambda state, jac=False: asked.append(jac) or evaluate(state, jac)
        out, info = prob.solve()
        return out, info, asked

    out, info, asked = solve_counting()
    monkeypatch.setattr(solver_module, "_likely_last", lambda *args: False)
    out_all, info_all, asked_all = solve_counting()
    assert info["success"] and info["iterations"] == info_all["iterations"] >= 2
    assert all(asked_all) and asked[-1] is False and sum(asked) == len(asked_all) - 1
    assert np.array_equal(out.R, out_all.R) and np.array_equal(out.C, out_all.C) and out.fx == out_all.fx
