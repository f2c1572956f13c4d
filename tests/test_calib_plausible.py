"""A camera a broadcast can have (issue #35): at least 2 m above the pitch and within 1 km of the
centre mark. A few weak detections fit degenerate cameras exactly (one standing on a pitch corner,
one 3e7 m away); the verdict refused neither."""

import numpy as np
import pytest

from pnlviz.calib.calibrate import CalibParams, _sane, calibrate
from pnlviz.calib.observations import Observations
from pnlviz.field import load_field_model
from pnlviz.geometry.camera import Camera

W, H = 960, 540
MODEL = load_field_model()


def _camera(C, target=(0.0, 0.0, 0.0), hfov=40.0) -> Camera:
    return Camera.from_look_at(np.array(C, float), np.array(target, float), hfov_deg=hfov, width=W, height=H)


def _observed(cam: Camera) -> Observations:
    """Every ground keypoint the camera shows, exactly where it shows it."""
    ids = [k for k in MODEL.keypoint_ids if abs(MODEL.keypoint_xyz([k])[0, 2]) < 1e-9]
    uv, z = cam.project_with_depth(MODEL.keypoint_xyz(ids))
    ok = (z > 0) & cam.in_image(uv)
    return Observations.from_keypoints(W, H, {k: uv[i] for i, k in enumerate(ids) if ok[i]})


def test_the_sanity_gate_names_what_no_broadcast_camera_does():
    p = CalibParams()
    assert _sane(_camera((0.0, 50.0, -15.0)), p) is None
    assert "above the pitch" in _sane(_camera((0.0, 34.0, -0.5), target=(0.0, 0.0, 0.0)), p)
    assert "from the centre mark" in _sane(_camera((0.0, 1500.0, -30.0)), p)
    assert _sane(_camera((0.0, 400.0, -30.0)), p) is None  # far, but a fit that may be seen
    assert _sane(_camera((0.0, 34.0, -0.5)), CalibParams(min_height_m=0.0)) is None  # 0: off
    assert "below the pitch" in _sane(_camera((0.0, 50.0, 5.0), target=(0.0, 0.0, 10.0)), p)


@pytest.mark.parametrize("height, calibrated", [(15.0, True), (1.0, False)])
def test_a_frame_whose_only_camera_stands_on_the_grass_gets_none(height, calibrated):
    cam = _camera((-20.0, 40.0, -height), target=(-35.0, 0.0, 0.0), hfov=60.0)
    obs = _observed(cam)
    assert obs.n_keypoints >= 6
    res = calibrate(obs, CalibParams())
    assert res.ok is calibrated
    if calibrated:
        assert np.linalg.norm(res.camera.C - cam.C) < 0.5
    else:  # said so; the same frame, the gate off: the camera on the grass is found, and fits
        assert res.failure_code == "degenerate"
        assert res.failure.startswith("no camera a broadcast can have: the keypoints fit a camera 1.0 m above")
        off = calibrate(obs, CalibParams(min_height_m=0.0))
        assert off.ok and abs(off.camera.C[2] + height) < 0.2
