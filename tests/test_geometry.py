"""Camera model, SoccerNet camera JSON, evaluator-identical clipping, and conics."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pnlviz.field import load_field_model
from pnlviz.geometry import Camera, visible_pitch
from pnlviz.geometry.conics import Conic, ConicError, fit_ellipse, intersect_lines, line_through
from pnlviz.geometry.homography import apply_homography

MODEL = load_field_model()


def random_camera(rng, distortion=False, width=960, height=540):
    pos = np.array([rng.uniform(-30, 30), rng.uniform(35, 70), -rng.uniform(6, 30)])
    if rng.random() < 0.2:
        pos[1] *= -1
    target = np.array([rng.uniform(-55, 55), rng.uniform(-30, 30), 0.0])
    cam = Camera.from_look_at(pos, target, hfov_deg=rng.uniform(8, 80), width=width, height=height,
                              roll_deg=rng.normal(0, 2))
    if distortion:
        cam = Camera(cam.fx, cam.fy, cam.cx, cam.cy, cam.R, cam.C, width, height,
                     rng.normal(0, 0.05, 6), rng.normal(0, 0.005, 2), rng.normal(0, 0.005, 4))
    return cam


def sn_camera(sn, d):
    c = sn.Camera()
    c.from_json_parameters(d)
    return c


def test_catalogue_projects_and_comes_back_through_the_ground_homography_exactly():
    rng = np.random.default_rng(1)
    ground = [k for k in MODEL.keypoint_ids if MODEL.keypoints[k].xyz[2] == 0]
    X = MODEL.keypoint_xyz(ground)
    for _ in range(50):
        cam = random_camera(rng)
        uv, depth = cam.project_with_depth(X)
        front = depth > 1
        H = cam.ground_homography()
        np.testing.assert_allclose(apply_homography(H, X[front, :2]), uv[front], rtol=1e-10, atol=1e-7)
        back = apply_homography(np.linalg.inv(H), uv[front])
        np.testing.assert_allclose(back, X[front, :2], atol=1e-7)
        # and through the ray model (back-projection onto z = 0)
        np.testing.assert_allclose(cam.back_project_to_ground(uv[front])[:, :2], X[front, :2], atol=1e-6)


def test_non_planar_keypoints_project_through_P():
    cam = random_camera(np.random.default_rng(2))
    X = MODEL.keypoint_xyz([12, 15, 16, 19])  # crossbar corners, z = -2.44
    uv = cam.project(X)
    h = np.hstack([X, np.ones((4, 1))]) @ cam.P.T
    np.testing.assert_allclose(uv, h[:, :2] / h[:, 2:], rtol=1e-12)


def test_points_behind_the_camera_do_not_project():
    cam = Camera.from_look_at([0, 50, -15], [0, 0, 0], hfov_deg=40, width=960, height=540)
    uv, depth = cam.project_with_depth(np.array([[0, 80, 0], [0, 0, 0]]))
    assert depth[0] < 0 and np.all(np.isnan(uv[0]))
    assert np.all(np.isfinite(uv[1]))
    assert np.allclose(uv[1], [480, 270])  # look-at target lands on the principal point


@pytest.mark.parametrize("distortion", [False, True])
def test_soccernet_json_round_trip_and_agreement_with_the_official_package(distortion, evaluator):
    rng = np.random.default_rng(3 + distortion)
    X = MODEL.keypoint_xyz()
    for _ in range(40):
        cam = random_camera(rng, distortion)
        d = cam.to_soccernet()
        back = Camera.from_soccernet(d)
        np.testing.assert_allclose(back.R, cam.R, atol=1e-12)
        np.testing.assert_allclose(back.C, cam.C)
        assert (back.width, back.height) == (960, 540)
        theirs = sn_camera(evaluator, d)
        np.testing.assert_allclose(theirs.rotation, cam.R, atol=1e-12)
        # the package's own decomposition gives the same angles
        pan, tilt, roll = evaluator.rotation_matrix_to_pan_tilt_roll(cam.R)
        np.testing.assert_allclose([d["pan_degrees"], d["tilt_degrees"], d["roll_degrees"]],
                                   np.degrees([pan, tilt, roll]), atol=1e-9)
        uv, depth = cam.project_with_depth(X)
        for x, p, z in zip(X, uv, depth):
            if z > 1:
                ref = theirs.project_point(x)
                np.testing.assert_allclose(p, ref[:2], rtol=1e-6, atol=2e-3)  # the package rounds to float32


def test_rescaling_scales_pixels():
    cam = random_camera(np.random.default_rng(5), width=1280, height=720)
    small = cam.scaled(960, 540)
    X = MODEL.keypoint_xyz()
    uv, z = cam.project_with_depth(X)
    uv2 = small.project(X)
    ok = z > 1
    np.testing.assert_allclose(uv2[ok], uv[ok] * 0.75, rtol=1e-12, atol=1e-9)
    assert small.to_soccernet()["principal_point"] == [480.0, 270.0]


def test_distortion_is_inverted_by_pixel_rays():
    rng = np.random.default_rng(6)
    cam = random_camera(rng, distortion=True)
    uv = rng.uniform([0, 0], [960, 540], size=(200, 2))
    rays = cam.pixel_rays(uv)
    uv2 = cam.project(cam.C + 30 * rays)
    np.testing.assert_allclose(uv2, uv, atol=1e-6)


def test_visible_pitch_is_identical_to_the_official_get_polylines(evaluator):
    rng = np.random.default_rng(7)
    for i in range(120):
        cam = random_camera(rng, distortion=i % 4 == 0)
        d = cam.to_soccernet()
        theirs = evaluator.get_polylines(d, 960, 540, sampling_factor=0.9)
        ours = visible_pitch(Camera.from_soccernet(d), evaluator_precision=True)
        assert set(ours) == set(theirs)
        for name, pts in theirs.items():
            np.testing.assert_array_equal(ours[name], [[p["x"], p["y"]] for p in pts])


def _crossing_with_numpy(cur, prev, width, height):
    """The border crossing as the evaluator writes it (np.cross, numpy division and norm)."""
    line = np.cross(cur, prev)
    best, best_d = None, np.inf
    with np.errstate(divide="ignore", invalid="ignore"):
        for side in ((1.0, 0.0, 0.0), (1.0, 0.0, -width + 1), (0.0, 1.0, 0.0), (0.0, 1.0, -height + 1)):
            p = np.cross(line, side)
            p = p / p[2]
            if 0 <= p[0] < width and 0 <= p[1] < height:
                d = np.sqrt(np.sum(np.square(p - cur)))
                if d < best_d:
                    best, best_d = p, d
    return best


def test_border_crossing_in_python_floats_has_numpys_bits():
    """The crossing is computed on Python floats (numpy's overhead on three numbers was most of an
    overlay's time); it must give numpy's result bit for bit, degenerate segments included."""
    from pnlviz.geometry.polylines import _border_crossing

    rng = np.random.default_rng(11)
    found = 0
    for i in range(4000):
        cur = np.r_[rng.integers(-2, 962, 2).astype(float) if i % 3 == 0 else rng.uniform(-300, 1300, 2), 1.0]
        prev = [np.r_[rng.uniform(-300, 1300, 2), 1.0], np.zeros(3),  # a segment's first point: nothing before
                np.r_[cur[0], rng.uniform(-60, 600), 1.0], np.r_[rng.uniform(-60, 1000), cur[1], 1.0],  # axis-parallel
                cur.copy()][i % 5]  # the same point twice: no line
        ours, theirs = _border_crossing(cur, prev, 960, 540), _crossing_with_numpy(cur, prev, 960, 540)
        assert (ours is None) == (theirs is None), (cur, prev)
        if theirs is not None:
            found += 1
            assert np.array_equal(ours, theirs), (cur, prev, ours, theirs)
    assert found > 1000  # most segments do cross the border


def test_visible_pitch_in_float64_stays_within_a_millipixel_of_the_evaluator(evaluator):
    rng = np.random.default_rng(8)
    for _ in range(30):
        cam = random_camera(rng)
        theirs = evaluator.get_polylines(cam.to_soccernet(), 960, 540, sampling_factor=0.9)
        ours = visible_pitch(cam)
        assert set(ours) == set(theirs)
        for name, pts in theirs.items():
            np.testing.assert_allclose(ours[name], [[p["x"], p["y"]] for p in pts], atol=1e-3)


# ----------------------------------------------------------------------------------------- conics
ellipses = st.tuples(
    st.floats(100, 900), st.floats(100, 500),  # centre
    st.floats(20, 400), st.floats(0.1, 1.0),  # major semi-axis, minor/major ratio
    st.floats(0, math.pi),
)


@settings(max_examples=60, deadline=None)
@given(ellipses, st.integers(6, 60), st.floats(0.5, 2 * math.pi))
def test_fit_ellipse_recovers_exact_ellipses_from_any_arc(e, n, span):
    cu, cv, a, ratio, ang = e
    truth = Conic.from_ellipse((cu, cv), (a, a * ratio), ang)
    t = np.linspace(0, span, n)
    c, s = math.cos(ang), math.sin(ang)
    local = np.stack([a * np.cos(t), a * ratio * np.sin(t)], 1)
    pts = local @ np.array([[c, s], [-s, c]]) + [cu, cv]
    fit = fit_ellipse(pts)
    center, axes, _ = fit.ellipse_params()
    np.testing.assert_allclose(center, [cu, cv], atol=1e-4 * a)
    np.testing.assert_allclose(sorted(axes), sorted([a, a * ratio]), rtol=1e-5)
    # the same conic as the true ellipse, up to scale and sign
    q, t_q = fit.Q / np.linalg.norm(fit.Q), truth.Q / np.linalg.norm(truth.Q)
    assert min(np.abs(q - t_q).max(), np.abs(q + t_q).max()) < 1e-4


def test_fit_ellipse_refuses_too_few_or_collinear_points():
    with pytest.raises(ConicError, match="at least 5"):
        fit_ellipse(np.zeros((4, 2)))
    with pytest.raises(ConicError):
        fit_ellipse(np.stack([np.arange(10.0), 2 * np.arange(10.0)], 1))


@settings(max_examples=60, deadline=None)
@given(ellipses, st.floats(-math.pi, math.pi), st.floats(1.2, 5))
def test_tangent_points_touch_and_line_intersections_lie_on_the_ellipse(e, phi, dist):
    cu, cv, a, ratio, ang = e
    conic = Conic.from_ellipse((cu, cv), (a, a * ratio), ang)
    external = np.array([cu, cv]) + dist * a * np.array([math.cos(phi), math.sin(phi)])
    tps = conic.tangent_points(external)
    assert len(tps) == 2
    for tp in tps:
        assert abs(conic.residuals(tp[None])[0]) < 1e-9 * np.abs(conic.Q).max() * a * a
        # the line from the external point through tp meets the ellipse only there (double root)
        hits = conic.intersect_line(line_through(external, tp))
        assert np.allclose(hits, tp, atol=1e-3 * a)
    # a line through the centre cuts the ellipse twice, at points on it
    hits = conic.intersect_line(line_through((cu, cv), external))
    assert len(hits) == 2
    center, _, _ = conic.ellipse_params()
    np.testing.assert_allclose(hits.mean(0), center, atol=1e-6 * a)


def test_line_helpers():
    l1 = line_through((0, 0), (1, 1))
    l2 = line_through((0, 1), (1, 0))
    np.testing.assert_allclose(intersect_lines(l1, l2), [0.5, 0.5])
    assert intersect_lines(l1, line_through((0, 1), (1, 2))) is None
    assert len(Conic.from_ellipse((0, 0), (1, 1), 0).intersect_line(line_through((0, 5), (1, 5)))) == 0


def test_fit_line_is_total_least_squares():
    from pnlviz.geometry.conics import fit_line

    rng = np.random.default_rng(9)
    t = rng.uniform(-100, 100, 50)
    pts = np.stack([300 + 0.8 * t, 200 + 0.6 * t], 1) + rng.normal(0, 0.5, (50, 2)) * [[-0.6, 0.8]]
    l = fit_line(pts)
    assert abs(np.hypot(l[0], l[1]) - 1) < 1e-12
    np.testing.assert_allclose(abs(l[:2] @ [0.8, 0.6]), 0, atol=0.01)  # normal is perpendicular to the direction
    assert abs(l @ [300, 200, 1]) < 0.5
    # a vertical line, where y-on-x regression would fail
    l = fit_line(np.array([[5.0, 0], [5, 10], [5, 20]]))
    np.testing.assert_allclose(abs(l[0]), 1) and np.testing.assert_allclose(abs(l[2]), 5)


def test_public_helpers_check_their_shapes_on_entry():
    from pnlviz.calib.frame import FrameInputs
    from pnlviz.geometry.distance import closest_on_polyline
    from pnlviz.geometry.projection import project_k1

    with pytest.raises(ValueError, match="polyline"):
        closest_on_polyline(np.zeros((3, 2)), np.zeros((1, 2)))
    with pytest.raises(ValueError, match="X \\(N, 3\\)"):
        project_k1(np.zeros((4, 2)), np.eye(3), np.zeros(3), 1000.0, 1.0, 480.0, 270.0, 0.0)
    with pytest.raises(ValueError, match="frame size"):
        FrameInputs((0, 540))
    assert closest_on_polyline([[0.0, 1.0]], [[0.0, 0.0], [2.0, 0.0]]).distance.tolist() == [1.0]


def test_rotations_from_angles_are_vectorised_over_frames():
    """Arrays of angles (the frames of a shot) give each frame's rotation to the last bit of the
    scalar call, and the angles come back from the rotation (the SoccerNet convention)."""
    from pnlviz.geometry.camera import pan_tilt_roll_from_rotation, rotation_from_pan_tilt_roll

    rng = np.random.default_rng(0)
    a = np.column_stack([rng.uniform(-3, 3, 50), rng.uniform(0.1, 3.0, 50), rng.uniform(-1, 1, 50)])
    R = rotation_from_pan_tilt_roll(a[:, 0], a[:, 1], a[:, 2])
    assert R.shape == (50, 3, 3)
    for t in range(50):
        assert np.array_equal(R[t], rotation_from_pan_tilt_roll(*a[t]))
        np.testing.assert_allclose(R[t] @ R[t].T, np.eye(3), atol=1e-14)
        np.testing.assert_allclose(pan_tilt_roll_from_rotation(R[t]), a[t], atol=1e-12)
    cam = Camera.from_soccernet({"pan_degrees": 10.0, "tilt_degrees": 80.0, "roll_degrees": 1.0,
                                 "position_meters": [0.0, 50.0, -15.0], "x_focal_length": 1000.0,
                                 "y_focal_length": 1000.0, "principal_point": [480.0, 270.0]})
    assert np.array_equal(cam.R, rotation_from_pan_tilt_roll(*np.radians([10.0, 80.0, 1.0])))


def test_projection_takes_one_rotation_and_focal_length_per_point():
    """The shot model's projection: points of several frames at once, each with its frame's
    rotation and focal length, equal frame by frame calls; the Jacobian and the undistortion too."""
    from pnlviz.geometry.projection import camera_to_pixels, to_camera, undistort_k1

    rng = np.random.default_rng(3)
    C = np.array([5.0, 55.0, -15.0])
    cams = [Camera.from_look_at(C, [x, 0.0, 0.0], hfov_deg=h, width=960, height=540) for x, h in ((-30, 20), (0, 35), (30, 60))]
    frame = np.repeat(np.arange(3), 4)
    # points each frame sees (a little beyond its image, where the lens model still holds)
    X = np.vstack([cam.back_project_to_ground(rng.uniform((-50, 50), (1010, 490), (4, 2))) for cam in cams])
    R = np.stack([c.R for c in cams])[frame]
    f = np.array([c.fx for c in cams])[frame]
    Xc = to_camera(X, R, C)
    uv, J = camera_to_pixels(Xc, R, f, 1.0, 480.0, 270.0, -0.05, jac=True)
    q, Jq = undistort_k1(uv, f, 1.0, 480.0, 270.0, -0.05, jac=True)
    for t, cam in enumerate(cams):
        m = frame == t
        Xc1 = to_camera(X[m], cam.R, C)
        uv1, J1 = camera_to_pixels(Xc1, cam.R, cam.fx, 1.0, 480.0, 270.0, -0.05, jac=True)
        q1, Jq1 = undistort_k1(uv1, cam.fx, 1.0, 480.0, 270.0, -0.05, jac=True)
        for a, b in ((Xc[m], Xc1), (uv[m], uv1), (J[m], J1), (q[m], q1), (Jq[m], Jq1)):
            np.testing.assert_allclose(a, b, rtol=1e-13, atol=1e-9)
    # and the undistortion inverts the lens: the undistorted points project back to the pixels
    back = q * (1 - 0.05 * (q * q).sum(1))[:, None] * f[:, None] + (480.0, 270.0)
    np.testing.assert_allclose(back, uv, atol=1e-6)
