"""A frame whose keypoints and classes name both halves of the pitch and give no camera together
is calibrated from each half alone (`CalibParams.one_half_when_both_fail`)."""

import numpy as np

from pnlviz.calib.calibrate import CalibParams, CameraKind, _one_half, calibrate
from pnlviz.calib.observations import Observations
from pnlviz.field import load_field_model
from pnlviz.geometry import Camera


def _twins(model):
    """id -> the id at the centrally mirrored position (the other end's same point)."""
    ids = [int(k) for k in model.keypoint_ids]
    X = model.keypoint_xyz(ids)
    out = {}
    for i, k in enumerate(ids):
        d = np.linalg.norm(X - X[i] * [-1, -1, 1], axis=1)
        j = int(np.argmin(d))
        if d[j] < 1e-6 and ids[j] != k:
            out[k] = ids[j]
    return out


def test_each_half_is_tried_and_the_one_that_fits_is_kept():
    model = load_field_model()
    cam = Camera.from_look_at((-20, 45, -14), (-42, 0, 0), hfov_deg=45, width=960, height=540)
    ids = [int(k) for k in model.keypoint_ids]
    X = model.keypoint_xyz(ids)
    uv = cam.project(X)
    seen = np.flatnonzero(cam.in_image(np.nan_to_num(uv, nan=-1)))
    left = {ids[i]: tuple(uv[i]) for i in seen}
    assert all(model.keypoints[k].xyz[0] < 0 for k in left)  # the left goal area only
    # a detector unsure of the side: four of them also named with the right end's ids, at their pixels
    twins = _twins(model)
    mixed = dict(left)
    for k in [k for k in sorted(left) if k in twins][:4]:
        mixed[twins[k]] = left[k]
    obs = Observations.from_keypoints(960, 540, mixed)
    before = obs.kp_ids.copy()
    result = _one_half(CameraKind.of(obs, CalibParams(), model), CalibParams())
    assert result is not None and result.ok and result.half == "left"
    np.testing.assert_allclose(result.camera.project(X[seen]), uv[seen], atol=1e-6)
    assert set(result.inliers.tolist()) == set(left)
    np.testing.assert_array_equal(obs.kp_ids, before)  # the frame's observations are left as they were
    # one half named only: nothing to split
    assert _one_half(CameraKind.of(Observations.from_keypoints(960, 540, left), CalibParams(), model),
                     CalibParams()) is None


def test_a_frame_annotated_with_both_ends_gets_the_camera_of_one(shared_dir):
    from pnlviz.calib.inputs import observations_from_annotation
    from pnlviz.data import open_dataset

    # SN22 00039 is annotated with the right goal and the left penalty and goal areas at once
    ds = open_dataset(shared_dir / "data" / "sn22_test_subset" / "annotations.zip")
    obs = observations_from_annotation(ds.annotation("00039"), 960, 540)[0]
    names = {*obs.lines}
    assert any("left" in n for n in names) and any("right" in n for n in names)
    alone = calibrate(obs, CalibParams(one_half_when_both_fail=False))
    assert not alone.ok and alone.half is None
    result = calibrate(obs)
    assert result.ok and result.half == "right"
    # its residuals are reported for every observation (the left end's too), its inliers are
    # right-end or centre keypoints only
    assert set(result.line_residuals) == set(obs.lines) | set(obs.circles)
    assert set(result.point_residuals) == {int(k) for k in obs.kp_ids}
    xs = {int(k): x for k, x in zip(obs.kp_ids, obs.kp_xyz[:, 0])}
    assert result.inliers.size and all(xs[int(k)] >= 0 for k in result.inliers)

