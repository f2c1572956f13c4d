"""A calibrated lens with k1 < 0 folds back far off its axis: what it folds into the image is not
drawn (pitch lines through the stands, ghosts where no keypoint is), and metrics keep the
evaluator's rule (it draws the fold)."""

import json
import math

import numpy as np
import pytest

from helpers import copy_sample_set
from pnlviz import EXAMPLES_DIR
from pnlviz.field import load_field_model
from pnlviz.geometry import Camera, project_polylines
from pnlviz.geometry.lens import fold_radius, imaged


def _radial_growth(camera, r):
    """The radial model's r f(r^2) at radii ``r`` through the camera's own distort()."""
    return np.hypot(*camera.distort(np.stack([r, np.zeros_like(r)], axis=1)).T)


def test_the_fold_radius_is_where_the_radial_model_stops_growing():
    base = Camera.from_look_at((0, 50, -20), (0, 0, 0), hfov_deg=40, width=960, height=540)
    assert math.isinf(fold_radius(base))
    assert math.isinf(fold_radius(Camera.from_look_at((0, 50, -20), (0, 0, 0), hfov_deg=40, width=960,
                                                      height=540, k1=0.02)))
    k1 = Camera.from_look_at((0, 50, -20), (0, 0, 0), hfov_deg=40, width=960, height=540, k1=-0.0052)
    assert fold_radius(k1) == pytest.approx(1 / math.sqrt(3 * 0.0052), rel=1e-12)
    # more radial terms: found by a scan, within its 0.4 % spacing, checked against distort() itself
    for radial in ([-0.02, 0.0001, 0, 0, 0, 0], [0.01, -0.003, 0, 0.002, 0, 0], [-0.05, 0, 0, 0.01, 0, 0]):
        cam = Camera(base.fx, base.fy, base.cx, base.cy, base.R, base.C, 960, 540, radial=radial)
        r = fold_radius(cam)
        assert math.isfinite(r)
        inside = np.linspace(0, r * 0.995, 2000)
        assert np.all(np.diff(_radial_growth(cam, inside)) > 0)
        assert _radial_growth(cam, np.array([r * 1.01]))[0] < _radial_growth(cam, np.array([r * 0.995]))[0]
    grows = Camera(base.fx, base.fy, base.cx, base.cy, base.R, base.C, 960, 540, radial=[0.01, 0.001, 0, 0, 0, 0])
    assert math.isinf(fold_radius(grows))


def test_imaged_points_are_in_front_and_inside_the_fold():
    cam = Camera.from_look_at((0, 50, -20), (0, 0, 0), hfov_deg=40, width=960, height=540, k1=-0.0052)
    limit = fold_radius(cam)
    # points at normalised radii 0.5 limit, 0.999 limit, 1.001 limit and 3 limit, one metre deep
    radii = np.array([0.5, 0.999, 1.001, 3.0]) * limit
    xyz_cam = np.stack([radii, np.zeros(4), np.ones(4)], axis=1)
    world = xyz_cam @ cam.R + cam.C  # camera -> world: R^T x + C
    assert imaged(cam, world).tolist() == [True, True, False, False]
    behind = cam.C - 5 * cam.R[2]
    assert imaged(cam, behind[None]).tolist() == [False]
    with pytest.raises(ValueError, match=r"world: expected points \(N, 3\)"):
        imaged(cam, [1.0, 2.0, 3.0])


def _sample_camera(stem):
    return Camera.from_soccernet(json.loads((EXAMPLES_DIR / "sample" / "cameras" / f"camera_{stem}.json").read_text()))


def test_a_folded_line_is_skipped_in_pictures_and_kept_for_the_evaluator():
    # sample frame 00000's true camera has no distortion; the calibration gives it k1 = -0.0052,
    # which folds the left touchline (under and beside the camera) into the picture
    truth = _sample_camera("00000")
    folded = Camera(truth.fx, truth.fy, truth.cx, truth.cy, truth.R, truth.C, truth.width, truth.height,
                    radial=[-0.0052, 0, 0, 0, 0, 0])
    lines = load_field_model().sample_polylines(0.5, 0.25)
    seen = project_polylines(truth, lines, 960, 540)
    kept = project_polylines(folded, lines, 960, 540)  # the evaluator's rule
    drawn = project_polylines(folded, lines, 960, 540, skip_folded=True)
    assert "Side line left" not in seen and "Side line left" in kept
    assert set(drawn) == set(seen)
    for name in drawn:
        inside = imaged(folded, lines[name])
        assert inside.any()
        # what is drawn lies on the true line (k1 moves points near the edge by a pixel or two)
        d = np.min(np.linalg.norm(drawn[name][:, None] - seen[name][None], axis=2), axis=1)
        assert np.max(d) < 3.0, name


@pytest.fixture()
def folded_frames(tmp_path):
    return copy_sample_set(tmp_path / "set", ("00000", "00004"))


def _distance_to_segments(points, segments):
    a, b = segments[:, 0], segments[:, 1]
    d = b - a
    length2 = np.maximum((d * d).sum(axis=1), 1e-12)
    out = []
    for p in points:
        t = np.clip(((p - a) * d).sum(axis=1) / length2, 0, 1)
        out.append(np.min(np.hypot(*(a + t[:, None] * d - p).T)))
    return np.array(out)


def test_the_app_draws_the_pitch_and_ghosts_where_the_true_camera_does(folded_frames):
    from dataclasses import replace

    from pnlviz.app.overlay import Layers, overlay_geometry
    from pnlviz.app.state import AppState

    # each frame shown with its true pose and a k1 < 0 as the calibration used to fit them (it
    # now refuses a lens that folds the evaluator's samples, not every fold a finer drawing meets)
    with AppState(folded_frames) as st:
        for stem, k1 in (("00000", -0.0052), ("00004", -0.0535)):
            view = st.view(stem)
            truth = view.reference_camera
            cam = Camera(truth.fx, truth.fy, truth.cx, truth.cy, truth.R, truth.C, truth.width, truth.height,
                         radial=[k1, 0, 0, 0, 0, 0])
            view = replace(view, result=replace(view.result, estimate=cam))
            geom = overlay_geometry(view, Layers(), st.model)
            reference = geom.segments["reference_pitch"].points
            drawn = geom.segments["refined_pitch"].points.reshape(-1, 2)
            # every drawn vertex lies on the pitch as the true camera draws it: k1 moves the
            # picture's corners by up to 2 px; the fold put vertices 228 and 260 px off it
            assert np.max(_distance_to_segments(drawn, reference)) < 3.0, stem
            folded = project_polylines(cam, st.model.sample_polylines(0.5, 0.25), *view.size)
            assert np.max(_distance_to_segments(np.vstack(list(folded.values())), reference)) > 100, stem
            # a ghost is where the true camera puts its keypoint (the fold put two of 00004's
            # 17,000 px away from it)
            assert geom.ghosts.keys
            where = truth.project(st.model.keypoint_xyz(geom.ghosts.keys))
            assert np.max(np.hypot(*(where - geom.ghosts.uv).T)) < 3.0, stem
            if stem == "00004":
                ids = [int(k) for k in st.model.keypoint_ids]
                uv = cam.project(st.model.keypoint_xyz(ids))
                assert not np.all(imaged(cam, st.model.keypoint_xyz(ids))[cam.in_image(np.nan_to_num(uv, nan=-1))])


def test_folds_into_view_names_a_lens_that_draws_the_pitch_where_it_is_not():
    from pnlviz.geometry.lens import folds_into_view

    truth = _sample_camera("00000")
    points = load_field_model().sample_points(0.9)

    def with_k1(k1):
        return Camera(truth.fx, truth.fy, truth.cx, truth.cy, truth.R, truth.C, 960, 540, radial=[k1, 0, 0, 0, 0, 0])

    assert not folds_into_view(truth, points)
    assert not folds_into_view(with_k1(-0.0052), points)  # its fold falls between the 0.9 m samples
    assert folds_into_view(with_k1(-0.01), points)  # the left touchline, beside the camera
    assert not folds_into_view(with_k1(0.05), points)  # k1 > 0 never folds
    assert not folds_into_view(with_k1(-0.01), points[points[:, 0] > 0])  # the right half stays clear


def test_calibration_refuses_a_lens_that_folds_the_pitch_into_its_picture(shared_dir):
    from pnlviz.calib.calibrate import CalibParams, calibrate
    from pnlviz.calib.inputs import observations_from_annotation
    from pnlviz.data import open_dataset
    from pnlviz.geometry.lens import folds_into_view

    # SN22 from its human annotations: 19 of 398 cameras fitted with k1 folded the pitch into
    # their own picture, where the official evaluator draws (and scores) it
    ds = open_dataset(shared_dir / "data" / "sn22_test_subset" / "annotations.zip")
    points = load_field_model().sample_points(0.9)
    folded = refitted = 0
    for stem in ds.stems:
        obs = observations_from_annotation(ds.annotation(stem), 960, 540)[0]
        result = calibrate(obs)
        if not result.ok:
            continue
        folded += folds_into_view(result.camera, points)
        if folds_into_view(calibrate(obs, CalibParams(refuse_folding_lens=False)).camera, points):
            refitted += 1
            assert result.camera.radial[0] == 0.0, stem  # fitted again without k1
            assert not folds_into_view(result.camera, points)
    assert folded == 0
    assert refitted >= 10  # the rule is exercised on this set, not only allowed


def test_a_keypoint_finding_is_not_drawn_where_a_lens_fold_puts_it():
    from pnlviz.calib.qa import FrameQA, finding_marks
    from pnlviz.calib.qa_checks import Finding

    truth = _sample_camera("00004")
    cam = Camera(truth.fx, truth.fy, truth.cx, truth.cy, truth.R, truth.C, truth.width, truth.height,
                 radial=[-0.0535, 0, 0, 0, 0, 0])
    model = load_field_model()
    assert cam.in_image(cam.project(model.keypoint_xyz([44, 4]))).tolist() == [True, True]  # 44 by the fold
    qa = FrameQA(2.0, [Finding("off_keypoint", "keypoint 44 is off", 2.0, keypoint=44),
                       Finding("off_keypoint", "keypoint 4 is off", 2.0, keypoint=4)], cam)
    marks = finding_marks(qa, {}, (960, 540), model)
    points = {m.finding.keypoint: m.points for m in marks}
    np.testing.assert_allclose(points[4], cam.project(model.keypoint_xyz([4])))
    assert 44 not in points  # the camera does not see 44: nothing to draw (the fold put it inside)
