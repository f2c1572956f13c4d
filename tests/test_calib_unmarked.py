"""Detected points of a marking where nothing painted marks them (the circles' tangent points,
where the long axis or a diagonal meets a circle or a box's main line) are also points of that
marking, and their keypoints are derived: the final fit holds them to the marking only, where the
lines and circles fix the camera (``FieldModel.unmarked_points``,
``observations_from_predictions``, the edits, mirroring and merging that carry them, and the
shot's selections)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from pnlviz.calib.calibrate import CalibParams, calibrate
from pnlviz.calib.inputs import observations_from_predictions
from pnlviz.calib.observations import Observations
from pnlviz.calib.shot import FrameDistances
from pnlviz.calib.sources import apply_keypoint_edits, merge_observations, mirrored
from pnlviz.data import Predictions
from pnlviz.field import CLASS_TO_LINE_ID
from pnlviz.field.model import FieldModel, load_field_model

W, H = 960, 540
BOX = "Big rect. left main"


@pytest.fixture(scope="module")
def model():
    return load_field_model()


def _detections() -> Predictions:
    """38 (a tangent point of the centre circle), 32 (the halfway line meets the circle: painted)
    and 46 (the long axis meets the left box's main line), with that line detected."""
    return Predictions(keypoints={38: (0.30, 0.40, 0.9), 32: (0.50, 0.35, 0.9), 46: (0.20, 0.60, 0.8)},
                       lines={CLASS_TO_LINE_ID[BOX]: (0.21, 0.30, 0.9, 0.19, 0.90, 0.9)})


def test_the_catalogue_names_the_points_no_paint_marks(model):
    unmarked = model.unmarked_points()
    assert {k for k, c in unmarked.items() if c in model.circles} == set(range(37, 45)) | {47, 48, 49, 50, 52, 53,
                                                                                         54, 55}
    assert {k: c for k, c in unmarked.items() if c in model.lines} == {46: BOX, 56: "Big rect. right main"}
    # painted: the halfway line on the circle, the penalty marks, the centre mark (51)
    assert not {32, 35, 45, 51, 57} & set(unmarked)
    for kid, cls in unmarked.items():  # each lies on the marking it is named for
        xyz = model.keypoints[kid].xyz
        if cls in model.circles:
            arc = model.circles[cls]
            assert np.linalg.norm(np.subtract(xyz, arc.center)) == pytest.approx(arc.radius, abs=1e-6), kid
        else:
            seg = model.lines[cls]
            d = np.cross(seg.end - seg.start, np.subtract(xyz, seg.start))
            assert np.linalg.norm(d) / seg.length < 1e-6, kid


def test_a_detected_unmarked_point_joins_its_marking(model):
    obs = observations_from_predictions(_detections(), W, H, model=model)
    xy = dict(zip(obs.kp_ids.tolist(), obs.kp_xy))
    np.testing.assert_allclose(obs.circles["Circle central"], [xy[38]])
    np.testing.assert_allclose(obs.lines[BOX], [[0.21 * W, 0.30 * H], [0.19 * W, 0.90 * H], xy[46]])
    assert dict(zip(obs.kp_ids.tolist(), obs.derived.tolist())) == {32: False, 38: True, 46: True}
    # without its line detected, the point alone stands for the line
    alone = observations_from_predictions(Predictions(keypoints={46: (0.2, 0.6, 0.8)}), W, H, model=model)
    np.testing.assert_allclose(alone.lines[BOX], [[0.2 * W, 0.6 * H]])


def test_an_edited_unmarked_point_leaves_its_marking(model):
    obs = observations_from_predictions(_detections(), W, H, model=model)
    before = {k: v.copy() for k, v in {**obs.lines, **obs.circles}.items()}
    moved = apply_keypoint_edits(obs, {"38": [300.0, 215.0], "46": None}, model)
    assert "Circle central" not in moved.circles  # its only point was the detection of 38
    np.testing.assert_allclose(moved.lines[BOX], before[BOX][:2])  # back to the detected ends
    i = moved.kp_ids.tolist().index(38)
    assert moved.pins[i] and not moved.derived[i]  # the hand's point is a measurement of its own
    painted = apply_keypoint_edits(obs, {"32": [480.0, 190.0]}, model)
    for k, v in before.items():
        np.testing.assert_array_equal({**painted.lines, **painted.circles}[k], v)
    for k, v in before.items():  # the input unchanged
        np.testing.assert_array_equal({**obs.lines, **obs.circles}[k], v)


def test_mirroring_and_merging_carry_the_circles(model):
    det = observations_from_predictions(Predictions(keypoints={37: (0.3, 0.4, 0.9), 38: (0.6, 0.4, 0.9)}), W, H,
                                        model=model)
    assert set(det.circles) == {"Circle left", "Circle central"}
    turned = mirrored(det, model)
    np.testing.assert_array_equal(turned.circles["Circle right"], det.circles["Circle left"])
    np.testing.assert_array_equal(turned.circles["Circle central"], det.circles["Circle central"])
    assert "Circle left" not in turned.circles
    ann = Observations(W, H, circles={"Circle central": np.array([[10.0, 20.0], [30.0, 40.0]])})
    merged = merge_observations(ann, det, model)
    np.testing.assert_array_equal(merged.circles["Circle central"], ann.circles["Circle central"])  # the annotation wins
    # the detections' own stays (not mirrored: the annotation has no keypoint to compare with)
    np.testing.assert_array_equal(merged.circles["Circle left"], det.circles["Circle left"])


def test_the_shot_leaves_derived_keypoints_out_as_a_frame_does(model):
    ids = np.array([38, 39, 32, 5])
    obs = Observations(W, H, ids, np.zeros((4, 2)), np.zeros((4, 3)), np.array(["Kp2", "Kp2", "Kp1", "Kp"]),
                       np.zeros(4, bool), lines={"Middle line": np.zeros((2, 2)), "Side line top": np.zeros((2, 2)),
                                                 BOX: np.zeros((2, 2))},
                       circles={"Circle central": np.ones((2, 2))},
                       kp_pinned=np.array([False, True, False, False]), kp_derived=np.array([True, False, False, True]))
    dist = FrameDistances(np.array([1.0, 1.0, 1.0, 50.0]), {"Middle line": 1.0, "Side line top": 1.0, BOX: 1.0,
                                                            "Circle central": 1.0})
    calib, unmarked = CalibParams(), model.unmarked_points()
    sel = dist.selection(obs, 10.0, 10.0, calib, unmarked)
    assert sel.keypoints.tolist() == [False, True, True, False] and sel.left_out == 1  # 5 was gated out
    assert sel.circles == ("Circle central",)
    assert dist.selection(obs, 10.0, 10.0).keypoints.tolist() == [True, True, True, False]  # no rule
    three = FrameDistances(dist.keypoints, {**dist.classes, "Circle central": 99.0})  # the circle gated out
    assert three.selection(obs, 10.0, 10.0, calib, unmarked).keypoints.tolist() == [True, True, True, False]


def test_with_few_classes_a_circle_of_detected_points_counts_once(model):
    """Fewer classes than fix the camera alone: the keypoints no paint marks are fitted as
    keypoints (their place along the circle helps), and a circle made of nothing but them is not
    fitted again; a circle with a point of its own is."""
    from pnlviz.calib.pipeline import pnl_set

    det = observations_from_predictions(_detections(), W, H, model=model)
    gated = np.ones(det.n_keypoints, bool)
    kp, lines, circles = pnl_set(det, CalibParams(), gated, list(det.lines), list(det.circles),
                                 model.unmarked_points())
    assert kp.tolist() == gated.tolist() and circles == [] and lines == [BOX]  # the box line has its own ends
    more = replace(det, circles={"Circle central": np.vstack([det.circles["Circle central"], [[100.0, 100.0]]])})
    assert pnl_set(more, CalibParams(), gated, list(more.lines), list(more.circles),
                   model.unmarked_points())[2] == ["Circle central"]
    four = ["Middle line", "Side line top", "Side line left", BOX]
    many = replace(det, lines={k: np.zeros((2, 2)) for k in four})
    kp4, _, circles4 = pnl_set(many, CalibParams(), gated, four, ["Circle central"], model.unmarked_points())
    assert circles4 == ["Circle central"] and kp4.tolist() == (~many.derived).tolist()  # lines alone


def test_on_the_wc14_detections_the_rule_gains(shared_dir, model, monkeypatch):
    """FS@5 on WC14's development half from PnLCalib's published detections, with and without
    the rule (0.9393 without, 0.9429 with, when written)."""
    from pnlviz.data import read_predictions
    from pnlviz.metrics.soccernet import evaluate_dataset

    data = shared_dir / "data" / "wc14_test_half"
    preds = read_predictions(data / "detections_pnlcalib.zip")

    def fs() -> float:
        obs = {s: observations_from_predictions(p, W, H, model=model) for s, p in preds.items()}
        cams = {s: r.camera for s, r in ((s, calibrate(o, CalibParams())) for s, o in obs.items()) if r.ok}
        return evaluate_dataset(data / "annotations.zip", cams, progress=False).final_score

    with_rule = fs()
    monkeypatch.setattr(FieldModel, "unmarked_points", lambda self: {})
    without = fs()
    assert with_rule > without + 0.002


def test_the_shot_finds_each_circle_points_closest_segment_as_a_full_search_does(model):
    """The shot's pruned search (blocks of segments inside discs) finds the segment a search of
    every segment finds, the first of equally close ones, on random views of the centre circle
    (115 segments) and a penalty arc (33: blocks that do not fill up), several views per call, points
    1-30 px off and points on the vertices (where two segments are equally close)."""
    from pnlviz.calib.shot_circles import _closest_segments, _distances
    from pnlviz.geometry.camera import Camera

    rng = np.random.default_rng(5)
    for name, S in (("Circle central", 116), ("Circle left", 34)):
        arc = model.circles[name]
        world = arc.point_at(np.linspace(np.radians(arc.start_deg), np.radians(arc.end_deg), S))
        for trial in range(20):
            views = [Camera.from_look_at((rng.uniform(-20, 20), rng.uniform(35, 70), -rng.uniform(8, 25)),
                                         (rng.uniform(-10, 10), rng.uniform(-5, 5), 0.0),
                                         hfov_deg=rng.uniform(10, 50), width=W, height=H) for _ in range(3)]
            poly = np.stack([cam.project(world) for cam in views])  # (3, S, 2)
            item = rng.integers(0, 3, 60)
            pts = poly[item, rng.integers(0, S, 60)]
            pts[:40] += rng.normal(0.0, [1.0, 5.0, 30.0][trial % 3], (40, 2))  # the last 20 on vertices
            j, t, off = _closest_segments(poly, item, pts)
            d2 = _distances(poly, item, pts, np.zeros(60, int), S - 1)[3]
            np.testing.assert_array_equal(j, np.argmin(d2, axis=1))
            np.testing.assert_array_equal(np.square(off).sum(axis=1), d2.min(axis=1))
            a, b = poly[item, j], poly[item, j + 1]
            np.testing.assert_allclose(a + t[:, None] * (b - a) + off, pts, atol=1e-9)


def test_the_card_names_the_points_held_to_their_marking(model):
    from pnlviz.app.cards import _left_out

    unmarked = model.unmarked_points()
    assert _left_out([3, 4, 37, 46], unmarked) == (", fitted without the 2 keypoints derived from them and 2 that no "
                                                   "paint marks (37, 46: held to their marking only)")
    assert _left_out([37], unmarked) == ", fitted without 1 that no paint marks (37: held to their marking only)"
    assert _left_out([3], unmarked) == ", fitted without the 1 keypoint derived from them"
    assert _left_out([], unmarked) == ""
