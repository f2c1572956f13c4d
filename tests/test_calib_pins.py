"""Pinned keypoints (placed or moved by hand): the camera fits them, weighted above the detections
and never gated out; one it cannot agree with is flagged with its residual; four hand-placed ground
points calibrate a frame, or the failure names the condition that fails; the app draws and says them."""

import cv2
import numpy as np
import pytest

from pnlviz.calib.calibrate import CalibParams, calibrate
from pnlviz.calib.frame import FrameInputs, calibrate_frame
from pnlviz.calib.observations import Observations
from pnlviz.calib.pins import PinCondition
from pnlviz.calib.problem import pin_block
from pnlviz.calib.residuals import Block
from pnlviz.calib.sources import apply_keypoint_edits
from pnlviz.field.model import load_field_model
from pnlviz.geometry.camera import Camera
from pnlviz.geometry.homography import camera_from_ground_homography

W, H = 960, 540
MODEL = load_field_model()
TRUTH = Camera.from_look_at([20, 55, -18], [30, 0, 0], hfov_deg=40, width=W, height=H)
GROUND = [int(k) for k in MODEL.keypoint_ids if abs(MODEL.keypoints[int(k)].xyz[2]) < 1e-9]
#: keypoints 6, 7, 10 and 22 where a real broadcast frame (1073x603, the right penalty area) shows them
MESSI = {"6": [40.2, 287.7], "7": [473.0, 260.6], "10": [446.6, 319.8], "22": [683.6, 425.5]}


def truth_uv() -> dict[int, np.ndarray]:
    uv = TRUTH.project(MODEL.keypoint_xyz(GROUND))
    return {k: p for k, p in zip(GROUND, uv) if np.isfinite(p).all() and 0 < p[0] < W and 0 < p[1] < H}


def with_pin(detections: dict, kid: int, xy) -> Observations:
    return apply_keypoint_edits(Observations.from_keypoints(W, H, detections, model=MODEL), {str(kid): list(xy)}, MODEL)


def projected(cam: Camera, kid: int) -> np.ndarray:
    return cam.project(MODEL.keypoint_xyz([kid]))[0]


def test_a_pin_far_from_the_detections_camera_pulls_the_camera_and_is_never_dropped():
    uv = truth_uv()
    kid = 22
    # detections away from keypoint 22 (exact), and 22 where the annotator says it is, 60 px off
    det = {k: p for k, p in uv.items() if k != kid and np.hypot(*(p - uv[kid])) > 200}
    where = uv[kid] + [-36.0, 48.0]
    # the same point as a detection: an outlier of the detections' camera, dropped
    plain = calibrate(Observations.from_keypoints(W, H, {**det, kid: where}, model=MODEL), CalibParams(), MODEL)
    assert plain.ok and kid not in plain.inliers and plain.point_residuals[kid] > 55
    # pinned: the camera comes to it
    pinned = calibrate(with_pin(det, kid, where), CalibParams(), MODEL)
    assert pinned.ok and pinned.pinned == [kid] and kid in pinned.inliers
    assert pinned.point_residuals[kid] < 5.0 and pinned.flagged == {}
    assert np.hypot(*(projected(pinned.camera, kid) - projected(plain.camera, kid))) > 50


def test_a_pin_the_camera_cannot_agree_with_is_flagged_with_its_residual_not_dropped():
    uv = truth_uv()
    kid = 22
    det = {k: p for k, p in uv.items() if k != kid}
    result = calibrate(with_pin(det, kid, uv[kid] + [-300.0, 0.0]), CalibParams(), MODEL)
    assert result.ok and kid in result.inliers and result.pinned == [kid]
    assert set(result.flagged) == {kid}
    assert result.flagged[kid] == pytest.approx(result.point_residuals[kid]) and result.flagged[kid] > 250
    # its pull is bounded: the detections keep their camera
    assert max(result.point_residuals[k] for k in det) < 5.0


def test_without_pins_nothing_is_pinned_or_flagged():
    result = calibrate(Observations.from_keypoints(W, H, truth_uv(), model=MODEL), CalibParams(), MODEL)
    assert result.ok and result.pinned == [] and result.flagged == {} and result.pin_condition is None


def test_four_hand_placed_ground_points_calibrate_a_frame():
    uv = truth_uv()
    rng = np.random.default_rng(3)
    for trial in range(10):  # clicked to within a couple of pixels
        edits = {str(k): list(uv[k] + rng.uniform(-2, 2, 2)) for k in (6, 7, 10, 22)}
        fc = calibrate_frame(FrameInputs((W, H), keypoint_edits=edits))
        assert fc.ok, fc.failure
        err = [np.hypot(*(projected(fc.result.camera, k) - p)) for k, p in uv.items()]
        assert np.median(err) < 10.0
    # the real frame's four points
    fc = calibrate_frame(FrameInputs((1073, 603), keypoint_edits=MESSI))
    assert fc.ok and fc.origin == "edits" and sorted(fc.result.pinned) == [6, 7, 10, 22]
    assert max(fc.result.point_residuals.values()) < 3.0
    # clicked to whole pixels: their homography has no closed-form focal length (this gave
    # "degenerate geometry"); the field-of-view search finds the camera
    clicked = {"6": [41, 287], "7": [470, 258], "10": [448, 322], "22": [683, 423]}
    Hc, _ = cv2.findHomography(MODEL.keypoint_xyz([6, 7, 10, 22])[:, :2], np.array(list(clicked.values()), float), 0)
    assert camera_from_ground_homography(Hc, 1073, 603) is None
    fc = calibrate_frame(FrameInputs((1073, 603), keypoint_edits=clicked))
    assert fc.ok and max(fc.result.point_residuals.values()) < 5.0
    uv = fc.result.camera.project(MODEL.keypoint_xyz([6, 7, 10, 22]))
    assert np.max(np.hypot(*(uv - np.array(list(MESSI.values()))).T)) < 8.0


@pytest.mark.parametrize("edits, condition, words", [
    ({"6": [40, 288], "7": [473, 261], "10": [447, 320]}, PinCondition.FEWER_THAN_FOUR, "fewer than 4"),
    ({"6": [40, 288], "7": [473, 261], "10": [447, 320], "15": [700, 200]}, PinCondition.FEWER_THAN_FOUR,
     "15 not on the ground plane"),
    (MESSI, None, None),
    ({"1": [40, 288], "2": [473, 261], "3": [700, 250], "10": [447, 320]}, PinCondition.COLLINEAR_ON_PITCH,
     "1, 2, 3 lie on one line of the pitch"),
    ({"6": [40, 288], "7": [473, 261], "10": [447, 320], "22": [800, 320]}, PinCondition.COLLINEAR_IN_IMAGE,
     "lie on one line in the image"),
    ({"7": [40.2, 287.7], "6": [473.0, 260.6], "10": [446.6, 319.8], "22": [683.6, 425.5]}, PinCondition.MIRRORED,
     "mirror order"),
    ({"6": [40.2, 287.7], "7": [473.0, 260.6], "10": [200, 240], "22": [683.6, 425.5]}, PinCondition.HORIZON,
     "both sides of the horizon"),
])
def test_each_named_condition_is_said(edits, condition, words):
    fc = calibrate_frame(FrameInputs((1073, 603), keypoint_edits=edits))
    if condition is None:  # general position: calibrates
        assert fc.ok
        return
    assert not fc.ok and fc.failure.code == "pins" and fc.result.pin_condition == condition.value
    assert words in fc.failure.message


def test_focal_out_of_range_is_named():
    from pnlviz.calib.frame import FrameSettings

    fc = calibrate_frame(FrameInputs((1073, 603), keypoint_edits=MESSI),
                         FrameSettings(overrides={"min_hfov_deg": 60.0, "max_hfov_deg": 120.0}))
    assert not fc.ok and fc.result.pin_condition == PinCondition.FOCAL_OUT_OF_RANGE.value
    assert "no field of view of 60-120 deg" in fc.failure.message


def test_the_pin_rows_jacobian_matches_finite_differences():
    rng = np.random.default_rng(0)
    theta = rng.normal(size=3)
    A = rng.normal(size=(6, 3)) * 40

    def block(t, jac=True):
        r = A @ t
        return Block(r, A.copy() if jac else None)

    pins = np.array([True, False, True])
    b = pin_block(block(theta), pins, 3.0, 10.0)
    eps = 1e-6
    num = np.stack([(pin_block(block(theta + eps * np.eye(3)[i], False), pins, 3.0, 10.0).r - b.r) / eps
                    for i in range(3)], axis=1)
    np.testing.assert_allclose(b.J, num, rtol=1e-4, atol=1e-4)
    # bounded: the pin's cost grows like a log, not a square
    r = b.r.reshape(-1, 2)
    d = np.hypot(*(A @ theta).reshape(-1, 2).T)
    np.testing.assert_allclose(np.hypot(*r[0]), 3 * 10 * np.sqrt(np.log1p((d[0] / 10) ** 2)))
    np.testing.assert_allclose(r[1], (A @ theta).reshape(-1, 2)[1])


def test_the_app_draws_and_says_the_pins():
    """The overlay knows the pinned and the flagged keypoints; the card and the points list say them."""
    from types import SimpleNamespace

    from pnlviz.app import cards
    from pnlviz.app.modes import PointKind, Selection
    from pnlviz.app.overlay import overlay_geometry

    uv = truth_uv()
    edits = {"22": list(uv[22] + [-300.0, 0.0])}
    det = {k: p for k, p in uv.items() if k != 22}
    obs = apply_keypoint_edits(Observations.from_keypoints(W, H, det, model=MODEL), edits, MODEL)
    result = calibrate(obs, CalibParams(), MODEL)
    view = SimpleNamespace(size=(W, H), result=result, observations=obs, reference_camera=None, annotation=None,
                           detections=None, camera=result.camera)
    overlay = overlay_geometry(view, model=MODEL)
    assert overlay.pinned == [22] and set(overlay.flagged) == {22}
    assert f"**pinned point 22 is {result.flagged[22]:.0f} px from the camera**" in cards.pin_lines(result)
    assert cards.pin_lines(result)[0] == "pinned (placed by hand): 1 point (22)"
    assert any(r.startswith("22 · visible · flagged pin") for r in cards.point_rows(overlay, set()))
    assert "cannot agree" in cards.selected_text(Selection(PointKind.KEYPOINTS, 22), overlay, MODEL, 1)


def test_observations_refuse_arrays_of_another_length_than_their_keypoints():
    """A pin mask of the wrong length used to mean "no pins" silently: now it is refused by name,
    as is any keypoint array whose length is not the ids'."""
    import numpy as np
    import pytest

    from pnlviz.calib.observations import Observations

    ids, xy, xyz = np.array([1, 2, 3]), np.zeros((3, 2)), np.zeros((3, 3))
    sets, main = np.array(["Kp"] * 3), np.ones(3, bool)
    ok = Observations(960, 540, ids, xy, xyz, sets, main, kp_pinned=np.array([True, False, False]))
    assert ok.pins.tolist() == [True, False, False]
    with pytest.raises(ValueError, match="kp_pinned"):
        Observations(960, 540, ids, xy, xyz, sets, main, kp_pinned=np.array([True, False]))
    with pytest.raises(ValueError, match="kp_xy"):
        Observations(960, 540, ids, np.zeros((2, 2)), xyz, sets, main)


def test_a_refit_from_the_frames_camera_finds_the_slip_and_no_other():
    """The slip check refits the frame's own camera without each hand point (one solve, not a new
    vote): of three hand points, the one 30 px off is flagged, at the distance a whole new
    calibration without it gives; the exact clicks are not (a new vote without each, the check
    before, flags one of them too)."""
    from pnlviz.calib.calibrate import refit
    from pnlviz.calib.pins import slips

    rng = np.random.default_rng(3)
    true = truth_uv()
    det = {k: p + rng.normal(0, 1.0, 2) for k, p in true.items()}
    hand = sorted(det)[:3]
    edits = {str(k): list(true[k] + (np.array([30.0, 0.0]) if k == hand[0] else 0.0)) for k in hand}
    obs = apply_keypoint_edits(Observations.from_keypoints(W, H, det, model=MODEL), edits, MODEL)
    assert obs.pins.sum() == 3
    res = calibrate(obs, CalibParams(), MODEL)
    assert res.ok

    def by(fit):
        return slips(obs, lambda o: (lambda r: r.camera if r.ok else None)(fit(o)), 10.0)

    refitted = by(lambda o: refit(o, res.camera, CalibParams(), MODEL))
    voted = by(lambda o: calibrate(o, CalibParams(), MODEL))
    assert list(refitted) == [hand[0]] and hand[0] in voted  # a new vote flags an exact click too here
    assert 25 < refitted[hand[0]] < 35 and abs(refitted[hand[0]] - voted[hand[0]]) < 1.0
