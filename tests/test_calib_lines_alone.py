"""The keypoints derived from a frame's own lines (``Observations.kp_derived``) left out of the
final fit where its lines and circles fix the camera alone (``pipeline.lines_alone``), and the
gates applied again after PnL (``CalibParams.regate_rounds``)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from pnlviz.calib.calibrate import CalibParams, calibrate
from pnlviz.calib.inputs import PREDICTED_KEYPOINTS, observations_from_annotation, observations_from_predictions
from pnlviz.calib.observations import Observations
from pnlviz.calib.pipeline import lines_alone
from pnlviz.calib.sources import aligned_detections, apply_keypoint_edits, merge_observations
from pnlviz.field.model import load_field_model


@pytest.fixture(scope="module")
def sn22(shared_dir):
    from pnlviz.data import open_dataset

    gt = shared_dir / "data" / "sn22_test_subset" / "annotations.zip"
    ds = open_dataset(gt)
    return gt, ds, {s: observations_from_annotation(ds.annotation(s), 960, 540)[0] for s in ds.stems}


@pytest.fixture(scope="module")
def wc14(shared_dir):
    from pnlviz.data import read_predictions

    data = shared_dir / "data" / "wc14_test_half"
    preds = read_predictions(data / "detections_pnlcalib.zip")
    return data / "annotations.zip", {s: observations_from_predictions(p, 960, 540) for s, p in preds.items()}, preds


_SCORES: dict[tuple[str, CalibParams], float] = {}


def _fs(gt, observations: dict, params: CalibParams) -> float:
    """FS@5 of a development set calibrated with ``params`` (computed once per set and setting)."""
    from pnlviz.metrics.soccernet import evaluate_dataset

    key = (str(gt), params)
    if key not in _SCORES:
        cams = {s: r.camera for s, r in ((s, calibrate(o, params)) for s, o in observations.items()) if r.ok}
        _SCORES[key] = evaluate_dataset(gt, cams, progress=False).final_score
    return _SCORES[key]


def test_each_source_marks_the_keypoints_it_derived(sn22, wc14):
    model = load_field_model()
    _, ds, sn22_obs = sn22
    ann = sn22_obs[ds.stems[0]]
    assert ann.n_keypoints > 4 and ann.derived.all()  # labels are computed from the annotated lines
    _, wc14_obs, preds = wc14
    # the detections' own keypoints are measurements, but for the points of a marking where
    # nothing painted marks them; the intersections of detected lines are not
    stem, det = next((s, o) for s, o in wc14_obs.items() if o.derived.any())
    detected = [k for k, (_, _, p) in preds[stem].keypoints.items() if k in PREDICTED_KEYPOINTS and p >= 0.1]
    unmarked = list(model.unmarked_points())
    assert np.array_equal(det.derived, ~np.isin(det.kp_ids, detected) | np.isin(det.kp_ids, unmarked))
    sub = det.subset(det.kp_ids % 2 == 0)
    assert np.array_equal(sub.derived, ~np.isin(sub.kp_ids, detected) | np.isin(sub.kp_ids, unmarked))
    # a keypoint a hand moved is its own measurement, and pinned; the others keep their mark
    moved = int(ann.kp_ids[0])
    edited = apply_keypoint_edits(ann, {str(moved): [100.0, 200.0]}, model)
    assert not edited.derived[edited.kp_ids == moved].any() and edited.pins[edited.kp_ids == moved].all()
    assert edited.derived[edited.kp_ids != moved].all()
    # merged: each keypoint keeps the mark of the source it came from (the annotation wins; the
    # detections named on its sides first, which keeps their marks)
    aligned = aligned_detections(ann, det, model)
    assert np.array_equal(aligned.derived, det.derived)
    merged = merge_observations(ann, det, model)
    from_ann = np.isin(merged.kp_ids, ann.kp_ids)
    assert merged.derived[from_ann].all()
    assert np.array_equal(merged.derived[~from_ann], aligned.derived[~np.isin(aligned.kp_ids, ann.kp_ids)])


def test_a_mark_of_the_wrong_length_is_refused_by_name():
    with pytest.raises(ValueError, match=r"Observations.kp_derived: expected \(2,\) or empty, got \(3,\)"):
        Observations(960, 540, np.array([1, 2]), np.zeros((2, 2)), np.zeros((2, 3)), np.array(["Kp", "Kp"]),
                     np.ones(2, bool), kp_derived=np.ones(3, bool))


def test_lines_alone_leaves_out_derived_keypoints_only_with_enough_classes():
    ids = np.array([1, 2, 3, 4])
    obs = Observations(960, 540, ids, np.zeros((4, 2)), np.zeros((4, 3)), np.array(["Kp"] * 4), np.ones(4, bool),
                       kp_pinned=np.array([False, False, True, False]),
                       kp_derived=np.array([True, False, True, True]))
    gated = np.array([True, True, True, False])
    params = CalibParams()
    assert params.lines_alone_classes == 4
    four = ["Side line top", "Side line left", "Middle line", "Big rect. left main"]
    # derived 1 out; 2 is a measurement; 3 is pinned (a hand's point is never derived); 4 was gated out
    assert lines_alone(obs, params, gated, four[:3], ["Circle central"]).tolist() == [False, True, True, False]
    assert lines_alone(obs, params, gated, four[:3], []).tolist() == gated.tolist()  # 3 classes: kept
    assert lines_alone(obs, replace(params, lines_alone_classes=0), gated, four, []).tolist() == gated.tolist()
    assert gated.tolist() == [True, True, True, False]  # its input unchanged


def test_the_verdict_judges_the_keypoints_the_fit_used(wc14):
    """WC14 frame 144 (published detections): the intersection of two detected lines far outside
    the image (keypoint 72) disagrees with the detected lines by 100 px once the lines alone fit the
    camera; it is reported, left out of the fit, and the camera is judged on what it was fitted to."""
    _, obs, _ = wc14
    res = calibrate(obs["144"])
    assert res.ok, res.failure
    assert 72 in res.lines_alone and res.point_residuals[72] > CalibParams().max_rms
    fitted = [r for k, r in res.point_residuals.items() if k not in res.lines_alone]
    assert np.sqrt(np.mean(np.square(fitted))) < CalibParams().max_rms
    without = calibrate(obs["144"], CalibParams(lines_alone_classes=0))
    assert without.ok and without.lines_alone == []


def test_lines_alone_and_the_second_gate_raise_both_development_sets(sn22, wc14):
    """Set-level, as bench_calib measures them: leaving the derived keypoints out raises both sets'
    FS@5; the second gate raises SN22's (on WC14 it moves the score by under a thousandth)."""
    gt, _, sn22_obs = sn22
    default = CalibParams()
    sn = {name: _fs(gt, sn22_obs, p) for name, p in (
        ("default", default), ("no lines alone", replace(default, lines_alone_classes=0)),
        ("no second gate", replace(default, regate_rounds=0)))}
    assert sn["default"] > sn["no lines alone"] and sn["default"] > sn["no second gate"], sn
    wgt, wc14_obs, _ = wc14
    wc = {name: _fs(wgt, wc14_obs, p) for name, p in (
        ("default", default), ("no lines alone", replace(default, lines_alone_classes=0)))}
    assert wc["default"] > wc["no lines alone"], wc


def test_the_pulling_in_stays_off_while_it_does_not_raise_the_sn22_score(sn22):
    """``class_tolerance_px`` is off by default: with the verdict judging a fit from the lines alone
    by its lines, pulling the classes beyond 4 px in no longer raises the FS@5 of the 400 SN22
    frames from their annotations (0.9332 with it, 0.9337 without, when written). Should a change
    make it pay again, this fails and the default is to be chosen again."""
    gt, _, observations = sn22
    default = CalibParams()
    assert default.class_tolerance_px == 0.0
    assert _fs(gt, observations, default) >= _fs(gt, observations, replace(default, class_tolerance_px=4.0))


def test_border_points_aimed_inside_raise_both_development_sets(sn22, wc14):
    """The line points on the image border aimed inside while fitting (the evaluator clips the
    projected lines at the border) raise the FS@5 of both sets."""
    default = CalibParams()
    for gt, observations in ((sn22[0], sn22[2]), (wc14[0], wc14[1])):
        assert _fs(gt, observations, default) > _fs(gt, observations, replace(default, border_aim_px=0.0)), gt


def test_the_second_gate_adds_what_the_refined_model_lets_through_and_drops_nothing():
    """``pnl_refine`` with a model whose first solve moves one line out of the gate and brings
    another in: the second solve keeps the first line and adds the second; a third round is not
    run when nothing changes, and the rounds stop at ``regate_rounds``."""
    from types import SimpleNamespace

    from pnlviz.calib.pipeline import pnl_refine

    lines = {name: np.zeros((2, 2)) for name in ("Side line top", "Middle line", "Side line left")}
    obs = Observations(960, 540, np.array([1, 2]), np.zeros((2, 2)), np.zeros((2, 3)), np.array(["Kp", "Kp"]),
                       np.ones(2, bool), lines)
    calls = []
    errors = {0: {"Side line top": 3.0, "Middle line": 3.0, "Side line left": 50.0},
              1: {"Side line top": 3.0, "Middle line": 40.0, "Side line left": 5.0},  # after the first solve
              2: {"Side line top": 3.0, "Middle line": 40.0, "Side line left": 5.0}}

    class Kind:
        data = SimpleNamespace(obs=obs, model=load_field_model())

        def pnl_solve(self, estimate, keypoints, lines, circles):
            calls.append((estimate, list(lines)))
            return estimate + 1

        def class_errors(self, estimate):
            return errors[estimate]

        def point_errors(self, estimate):
            return {1: 1.0, 2: 60.0 if estimate else 1.0}

    new, used, left_out = pnl_refine(0, Kind(), CalibParams(), errors[0], Kind().point_errors(0))
    assert calls == [(0, ["Side line top", "Middle line"]), (1, ["Side line top", "Middle line", "Side line left"])]
    assert new == 2 and used == sorted(lines) and not left_out.any()
    calls.clear()
    pnl_refine(0, Kind(), replace(CalibParams(), regate_rounds=0), errors[0], Kind().point_errors(0))
    assert len(calls) == 1
