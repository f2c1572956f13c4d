"""The pitch model: every catalogue keypoint sits on what defines it, sampling equals the
evaluator's, meshes are where the model says."""

import json
import math

import numpy as np
import pytest

from pnlviz.field import MODEL_CLASSES, FieldModelError, load_field_model
from pnlviz.field.meshes import goals_mesh, markings_mesh, nets_mesh
from pnlviz.field.model import DEFAULT_MODEL_PATH, parse_field_model
from pnlviz.field.names import canonical_class_name, close_class_names

MM = 1e-3
MODEL = load_field_model()


def dist_to_segment(p, seg):
    a, b = seg.start, seg.end
    t = np.clip(np.dot(p - a, b - a) / np.dot(b - a, b - a), 0, 1)
    return np.linalg.norm(p - (a + t * (b - a)))


def dist_to_line(p, seg):  # infinite line (extended intersections)
    a, b = seg.start, seg.end
    d = (b - a) / np.linalg.norm(b - a)
    v = p - a
    return np.linalg.norm(v - np.dot(v, d) * d)


def dist_to_arc(p, arc):
    v = p[:2] - arc.center[:2]
    on_arc = arc.contains_angle(np.arctan2(v[1], v[0]))
    radial = abs(np.linalg.norm(v) - arc.radius)
    return radial if on_arc else np.inf


def test_catalogue_has_73_keypoints_in_paper_groups():
    groups = {g: MODEL.keypoints_in_group(g) for g in ("Kp", "Kpe", "Kp1", "Kp2", "Kp3")}
    assert groups["Kp"] == list(range(1, 31))
    assert groups["Kp1"] == list(range(31, 37))
    assert groups["Kp2"] == list(range(37, 45))
    assert groups["Kp3"] == list(range(45, 58))
    assert groups["Kpe"] == list(range(58, 74))


@pytest.mark.parametrize("kid", range(1, 74))
def test_keypoint_lies_on_its_defining_classes(kid):
    kp = MODEL.keypoints[kid]
    d = kp.definition
    p = kp.xyz
    if d["kind"] == "line_line":  # a real corner: on both painted segments
        for name in d["lines"]:
            assert dist_to_segment(p, MODEL.lines[name]) < MM, name
    elif d["kind"] == "extended_line_line":  # on both lines extended, and off at least one segment
        for name in d["lines"]:
            assert dist_to_line(p, MODEL.lines[name]) < MM, name
        assert max(dist_to_segment(p, MODEL.lines[n]) for n in d["lines"]) > 1.0
    elif d["kind"] == "line_circle":
        assert dist_to_segment(p, MODEL.lines[d["line"]]) < MM
        assert dist_to_arc(p, MODEL.circles[d["circle"]]) < MM
    elif d["kind"] == "tangent":
        arc = MODEL.circles[d["circle"]]
        assert dist_to_arc(p, arc) < MM
        ext = MODEL.keypoints[d["from_keypoint"]].xyz
        # tangent: the radius at the touching point is perpendicular to the line from the external point
        radius_dir = (p - arc.center)[:2]
        assert abs(np.dot(radius_dir, (ext - p)[:2])) / (np.linalg.norm(radius_dir) * np.linalg.norm((ext - p)[:2])) < 1e-6
    elif d["kind"] == "additional":
        for on in d["on"]:
            if on == "axis":
                assert abs(p[1]) < MM
            elif on == "diagonal":
                assert abs(abs(p[0]) - abs(p[1])) < MM
            elif on.startswith("penalty mark"):
                sign = -1 if "left" in on else 1
                assert np.allclose(p, [sign * 41.5, 0, 0], atol=MM)
            elif on in MODEL.circles:
                assert dist_to_arc(p, MODEL.circles[on]) < MM
            else:
                assert dist_to_segment(p, MODEL.lines[on]) < MM
    else:  # pragma: no cover
        pytest.fail(f"unknown definition {d}")


def test_only_id_52_moves_for_pnlcalib_networks():
    ids = MODEL.keypoint_ids
    moved = ids[np.any(MODEL.keypoint_xyz(ids) != MODEL.keypoint_xyz(ids, pnlcalib=True), axis=1)]
    assert moved.tolist() == [52]
    assert MODEL.keypoint_xyz([52], pnlcalib=True)[0, 0] == 9.0
    assert MODEL.keypoint_xyz([52])[0, 0] == pytest.approx(9.15)


def test_catalogue_matches_published_reference_to_rounding(shared_dir):
    ref = json.loads((shared_dir / "reference" / "pnlcalib_keypoints.json").read_text())
    for k in ref["keypoints"]:
        ours = MODEL.keypoints[k["id"]]
        assert ours.group == k["group"]
        assert np.linalg.norm(ours.xyz - [k["x"], k["y"], k["z"]]) < 0.015, k["id"]


@pytest.mark.parametrize("spacing", [0.1, 0.9, 0.37])
def test_sampling_equals_official_evaluator(spacing):
    SoccerPitch = pytest.importorskip("SoccerNet.Evaluation.utils_calibration").SoccerPitch
    theirs = SoccerPitch().sample_field_points(spacing)
    ours = MODEL.sample_polylines(spacing)
    assert set(ours) == set(theirs) == set(MODEL_CLASSES)
    for name in ours:
        np.testing.assert_allclose(ours[name], np.array(theirs[name]), atol=1e-9, err_msg=name)


def test_sampled_points_lie_on_their_class():
    for name, pts in MODEL.sample_polylines(0.5).items():
        if name in MODEL.circles:
            arc = MODEL.circles[name]
            r = np.linalg.norm(pts[:, :2] - arc.center[:2], axis=1)
            np.testing.assert_allclose(r, arc.radius, atol=1e-9)
        else:
            assert max(dist_to_segment(p, MODEL.lines[name]) for p in pts) < 1e-9


def test_template_mapping_round_trips_and_puts_origin_at_far_left_corner():
    corners = np.array([[-52.5, -34.0], [52.5, 34.0]])
    t = MODEL.field_to_template(corners)
    np.testing.assert_allclose(t[0], [0, 0])
    np.testing.assert_allclose(t[1], [105 * 1.09361, 68 * 1.09361])
    np.testing.assert_allclose(MODEL.template_to_field(t), corners)
    h = MODEL.template_to_field_matrix @ np.array([*t[1], 1.0])
    np.testing.assert_allclose(h[:2], corners[1])


def test_invalid_model_files_are_rejected_with_the_reason():
    data = json.loads(DEFAULT_MODEL_PATH.read_text())
    bad = json.loads(json.dumps(data))
    del bad["lines"]["Middle line"]
    with pytest.raises(FieldModelError, match="missing classes.*Middle line"):
        parse_field_model(bad)
    bad = json.loads(json.dumps(data))
    bad["keypoints"][3]["defined_by"]["lines"][0] = "Side line middle"
    with pytest.raises(FieldModelError, match="unknown class 'Side line middle'"):
        parse_field_model(bad)
    bad = json.loads(json.dumps(data))
    bad["keypoints"].pop()
    with pytest.raises(FieldModelError, match="1..73"):
        parse_field_model(bad)


def test_class_names_accept_the_goal_post_with_or_without_its_trailing_space():
    assert canonical_class_name("Goal left post left") == "Goal left post left "
    assert canonical_class_name("Goal left post left ") == "Goal left post left "
    assert canonical_class_name("Goal middle post") is None
    assert close_class_names("Big rect left mian")[0] == "Big rect. left main"


def test_meshes_sit_where_the_model_says():
    m = markings_mesh()
    half_w = MODEL.dimensions["line_width"] / 2
    np.testing.assert_allclose(m.bounds[:, :2], [[-52.5 - half_w, -34 - half_w], [52.5 + half_w, 34 + half_w]], atol=1e-6)
    # painted area = total marking length x 12 cm (+ corner overlaps and spots, within 2%)
    length = sum(s.length for s in MODEL.lines.values() if s.plane == "ground")
    length += sum(a.radius * math.radians(a.end_deg - a.start_deg) for a in MODEL.circles.values())
    assert m.area == pytest.approx(length * 0.12, rel=0.02)
    g = goals_mesh()
    assert g.bounds[0, 2] == pytest.approx(-2.44 - 0.06, abs=1e-3)  # crossbar top (z down)
    n = nets_mesh()
    assert n.bounds[0, 0] == pytest.approx(-54.5) and n.bounds[1, 0] == pytest.approx(54.5)


def test_flip_table_is_the_reflection_in_the_halfway_line():
    """FLIP_X renames every class to the one at its place after x -> -x (checked on the model's
    sampled geometry), is its own inverse, and covers every class the evaluator knows."""
    from pnlviz.field.names import ALL_CLASSES, FLIP_X

    assert set(FLIP_X) == set(ALL_CLASSES) and all(FLIP_X[FLIP_X[c]] == c for c in FLIP_X)
    samples = MODEL.sample_polylines()
    for name in MODEL_CLASSES:
        reflected = samples[name] * np.array([-1.0, 1.0, 1.0])
        target = samples[FLIP_X[name]]
        gaps = np.linalg.norm(reflected[:, None, :] - target[None, :, :], axis=2).min(axis=1)
        assert gaps.max() < 0.15, name  # within the sampling step: the same curve


def test_keypoint_names_are_distinct_and_say_the_side():
    names = load_field_model().keypoint_names()
    assert len(names) == 73 and len(set(names.values())) == 73
    assert names[33].endswith("(top)") and names[36].endswith("(bottom)")  # once both "Big rect. right main x Circle right"
    assert names[38].endswith("(left)") and names[39].endswith("(right)")


def test_keypoint_map_draws_every_id_at_its_place_in_its_set_colour():
    from pnlviz.viz import SET_RGB, _map_position, keypoint_map

    model = load_field_model()
    image = keypoint_map(model, px_per_m=10.0)
    margin = 6.0
    for kid in model.keypoint_ids:
        x, y = (_map_position(model.keypoints[kid].xyz) + [52.5 + margin, 34 + margin]) * 10.0
        rgb = SET_RGB[model.keypoints[kid].group]
        assert tuple(image[int(round(y)), int(round(x))][::-1]) == rgb, kid
    ringed = keypoint_map(model, px_per_m=10.0, highlight=45)
    changed = np.argwhere(np.any(ringed != image, axis=2))
    centre = (_map_position(model.keypoints[45].xyz) + [52.5 + margin, 34 + margin]) * 10.0
    # only around id 45 (its ring, its label) and on the two guide lines through it
    near = np.abs(changed[:, ::-1] - centre).max(axis=1) < 60
    on_guides = np.abs(changed[:, ::-1] - centre).min(axis=1) <= 2
    assert near.sum() > 50 and np.all(near | on_guides)
    assert on_guides.sum() > 500  # the guides cross the map
