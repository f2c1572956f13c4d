"""Keypoint labels, line extremities, heatmap targets and ``pnlviz labels``.

Synthetic frames are exact oracles: a known camera projects the pitch model with the evaluator's
``visible_pitch`` at 960x540, annotation points are taken on the visible polylines (2-6 per
straight class as in real SoccerNet files, 6-20 per circle), and every label must sit on the
projection of its catalogue world point.
"""

from __future__ import annotations

import argparse
import json
import math
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pnlviz.field.model import load_field_model
from pnlviz.field.names import CLASS_TO_LINE_ID, MIRROR
from pnlviz.geometry.camera import Camera
from pnlviz.geometry.polylines import visible_pitch
from pnlviz.labels import (
    SETS, LabelParams, get_catalogue, heatmap_targets, keypoint_mask, keypoints_from_annotation,
    labels_from_dict, labels_to_dict, line_extremities, lr_decision, mirror_annotation, training_targets,
    viewing_azimuth_deg,
)
from pnlviz.commands.labels import add_labels_parser, run_labels
from pnlviz.labels.fitting import fit_homography, orientation_ok, orientation_outliers
from helpers import needs_shared

W, H = 960, 540
SHARED = Path(__file__).resolve().parents[2] / "shared"
SN22 = SHARED / "data" / "sn22_test_subset" / "annotations.zip"
TOL = {"Kp": 0.5, "Kpe": 0.5, "Kp3": 0.5, "Kp1": 1.0, "Kp2": 1.0}
MODEL = load_field_model()


# ------------------------------------------------------------------------------ synthetic data
def broadcast_camera(rng: np.random.Generator, side: float = 1.0) -> Camera:
    """Main-camera-like pose (y 40-70 m on ``side``, 8-25 m high, FOV 15-60 degrees) aiming at a
    random point of the pitch."""
    pos = np.array([rng.uniform(-30, 30), side * rng.uniform(40, 70), -rng.uniform(8, 25)])
    target = np.array([rng.uniform(-52.5, 52.5), rng.uniform(-34, 34), 0.0])
    return Camera.from_look_at(pos, target, hfov_deg=rng.uniform(15, 60), width=W, height=H,
                               roll_deg=rng.normal(0, 1))


def behind_goal_camera(rng: np.random.Generator, end: float) -> Camera:
    """A camera behind the goal at x = ``end`` * (55..70) looking back along the pitch."""
    pos = np.array([end * rng.uniform(55, 70), rng.uniform(-10, 10), -rng.uniform(5, 15)])
    target = np.array([end * rng.uniform(10, 40), rng.uniform(-15, 15), 0.0])
    return Camera.from_look_at(pos, target, hfov_deg=rng.uniform(30, 60), width=W, height=H,
                               roll_deg=rng.normal(0, 1))


def synth_annotation(cam: Camera, rng: np.random.Generator, noise: float = 0.0) -> dict[str, np.ndarray]:
    """Normalised SoccerNet annotation of what ``cam`` sees: points on the visible polylines."""
    ann = {}
    for name, pts in visible_pitch(cam, W, H).items():
        if len(pts) < 2:
            continue
        m = int(rng.integers(6, 21)) if name.startswith("Circle") else int(rng.integers(2, 7))
        if len(pts) > m:
            inner = np.sort(rng.choice(np.arange(1, len(pts) - 1), m - 2, replace=False))
            pts = pts[np.r_[0, inner, len(pts) - 1]]
        if noise:
            pts = pts + rng.normal(0.0, noise, pts.shape)
        ann[name] = pts / np.array([W - 1, H - 1])
    return ann


def true_pixels(cam: Camera, ids, *, mirrored: bool = False) -> np.ndarray:
    xyz = MODEL.keypoint_xyz(list(ids))
    if mirrored:  # the evaluator's left/right mirror is the central symmetry of the pitch
        xyz = xyz * np.array([-1.0, -1.0, 1.0])
    return cam.project(xyz, distort=False)


def label_errors(cam, labels, *, mirrored=False):
    ids = labels.ids()
    if not ids:
        return {}
    true = true_pixels(cam, ids, mirrored=mirrored)
    return {k: float(np.linalg.norm(labels.keypoints[k].xy - t)) for k, t in zip(ids, true)}


@pytest.fixture(scope="module")
def exact_frames():
    rng = np.random.default_rng(2024)
    frames = []
    for i in range(40):
        cam = broadcast_camera(rng, side=-1.0 if i % 4 == 3 else 1.0)  # 10 of 40 from the other side
        ann = synth_annotation(cam, rng)
        frames.append((cam, ann, keypoints_from_annotation(ann, W, H)))
    return frames


# ------------------------------------------------------------------------------ catalogue
def test_catalogue_constructions_match_keypoints():
    cat = get_catalogue()
    assert len(cat.kp) == 30 and len(cat.kpe) == 16 and len(cat.kp3) == 13
    assert sorted(k for p in cat.kp1 for k in p.ids if k) == list(range(31, 37))
    assert sorted(k for p in cat.kp2 for k in p.ids if k) == list(range(37, 45))
    for pair in cat.kp1 + cat.kp2:
        for kid, w in zip(pair.ids, pair.world):
            if kid is not None:
                assert np.allclose(MODEL.keypoints[kid].xyz[:2], w, atol=1e-6)
    assert set(range(1, 74)) - cat.ground_ids == {12, 15, 16, 19}


# ------------------------------------------------------------------------------ accuracy
def test_exact_annotations_give_exact_labels(exact_frames):
    counts: Counter[str] = Counter()
    worst = dict.fromkeys(SETS, 0.0)
    for cam, _, labels in exact_frames:
        for kid, err in label_errors(cam, labels).items():
            s = labels.keypoints[kid].set
            counts[s] += 1
            worst[s] = max(worst[s], err)
            assert err <= TOL[s], f"id {kid} ({s}) is {err:.3f} px from its projection"
    print("\nexact synthetic labels, count / worst error px:",
          {s: (counts[s], round(worst[s], 4)) for s in SETS})
    assert all(counts[s] > 0 for s in SETS), counts
    assert sum(counts.values()) >= 30 * 8


def test_exact_labels_recall(exact_frames):
    """Line-line points of annotated classes that are in view are found (unless rejected as
    ill-conditioned, which the diagnostics say)."""
    cat = get_catalogue()
    expected = found = 0
    for cam, ann, labels in exact_frames:
        rejected = {r.id for r in labels.rejected}
        for pair in cat.kp:
            if not all(n in ann for n in pair.lines):
                continue
            p = true_pixels(cam, [pair.id])[0]
            if 5 <= p[0] <= W - 6 and 5 <= p[1] <= H - 6:
                expected += 1
                found += pair.id in labels.keypoints
                assert pair.id in labels.keypoints or pair.id in rejected
    print(f"\nKp recall on exact synthetic frames: {found}/{expected}")
    assert found >= 0.95 * expected


def test_kpe_respects_the_half_image_rule(exact_frames):
    n = 0
    for _, _, labels in exact_frames:
        for kp in labels.keypoints.values():
            if kp.set == "Kpe":
                n += 1
                assert -0.5 * W <= kp.x <= 1.5 * W - 1 and -0.5 * H <= kp.y <= 1.5 * H - 1
            if kp.set in ("Kp1", "Kp2", "Kp3"):
                assert kp.visible
    assert n > 0


def test_labels_with_annotation_noise():
    rng = np.random.default_rng(7)
    errs: dict[str, list[float]] = {s: [] for s in SETS}
    wrong = []
    ids_all = np.arange(1, 74)
    for i in range(40):
        cam = broadcast_camera(rng, side=-1.0 if i % 4 == 3 else 1.0)
        labels = keypoints_from_annotation(synth_annotation(cam, rng, noise=1.0), W, H)
        all_true = true_pixels(cam, ids_all)
        for kid, err in label_errors(cam, labels).items():
            errs[labels.keypoints[kid].set].append(err)
            d = np.linalg.norm(all_true - labels.keypoints[kid].xy, axis=1)
            d[kid - 1] = np.inf
            if err > 5.0 and np.nanmin(d) < 3.0:  # sits on another keypoint: a wrong id
                wrong.append((i, kid, err))
    med = {s: round(float(np.median(e)), 2) for s, e in errs.items() if e}
    p95 = {s: round(float(np.percentile(e, 95)), 2) for s, e in errs.items() if e}
    print(f"\n1 px annotation noise: median error px {med}, 95th percentile {p95}")
    assert not wrong, wrong
    assert all(m <= 3.0 for m in med.values()), med
    assert all(p <= 12.0 for p in p95.values()), p95


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(x=st.floats(-30, 30), y=st.floats(40, 70), h=st.floats(8, 25), fov=st.floats(15, 60),
       tx=st.floats(-50, 50), ty=st.floats(-30, 30), other_side=st.booleans(), seed=st.integers(0, 2**16))
def test_property_exact_labels(x, y, h, fov, tx, ty, other_side, seed):
    side = -1.0 if other_side else 1.0
    cam = Camera.from_look_at([x, side * y, -h], [tx, ty, 0.0], hfov_deg=fov, width=W, height=H)
    labels = keypoints_from_annotation(synth_annotation(cam, np.random.default_rng(seed)), W, H)
    for kid, err in label_errors(cam, labels).items():
        assert err <= TOL[labels.keypoints[kid].set]


def test_pixel_input_matches_normalised(exact_frames):
    _, ann, labels = exact_frames[1]
    px = {k: v * np.array([W - 1, H - 1]) for k, v in ann.items()}
    again = keypoints_from_annotation(px, W, H, pixels=True)
    assert again.keypoints.keys() == labels.keypoints.keys()
    for kid, kp in labels.keypoints.items():
        assert np.allclose(again.keypoints[kid].xy, kp.xy, atol=1e-6)


def test_never_raises_on_bad_annotations():
    """Heavy noise, dropped and mislabelled classes, duplicated points: labels are produced (maybe
    none), never an exception or a numpy warning."""
    import warnings

    from pnlviz.field.names import MODEL_CLASSES

    rng = np.random.default_rng(1)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for i in range(120):
            cam = broadcast_camera(rng, side=float(rng.choice([-1.0, 1.0])))
            ann = synth_annotation(cam, rng, noise=float(rng.choice([0.0, 2.0, 5.0, 15.0])))
            for k in list(ann):
                r = rng.random()
                if r < 0.1:
                    ann.pop(k)
                elif r < 0.2:
                    ann[str(rng.choice(MODEL_CLASSES))] = ann.pop(k)
                elif r < 0.25:
                    ann[k] = np.repeat(ann[k][:1], 3, axis=0)
            params = LabelParams(kp3_all=bool(i % 2), lr_disambiguation=bool(i % 3 == 0))
            labels = keypoints_from_annotation(ann, W, H, params)
            for kp in labels.keypoints.values():
                assert math.isfinite(kp.x) and math.isfinite(kp.y)
            if i % 20 == 0:
                heatmap_targets(labels, line_extremities(ann, W, H), W, H)
    assert keypoints_from_annotation({}, W, H).keypoints == {}
    ignored = {"Goal unknown": np.zeros((3, 2)), "Line unknown": np.ones((2, 2))}
    assert keypoints_from_annotation(ignored, W, H).keypoints == {}


def test_kp3_all_completes_missing_ground_points(exact_frames):
    params = LabelParams(kp3_all=True)
    extra = 0
    for cam, ann, base in exact_frames[:15]:
        labels = keypoints_from_annotation(ann, W, H, params)
        assert set(base.keypoints) <= set(labels.keypoints)
        for kid, err in label_errors(cam, labels).items():
            assert err <= TOL[labels.keypoints[kid].set]
            assert kid not in (12, 15, 16, 19) or labels.keypoints[kid].set == "Kp"
        extra += len(labels.keypoints) - len(base.keypoints)
    assert extra > 0


def test_goal_frame_corners_are_not_in_homographies(exact_frames):
    seen = 0
    for cam, _, labels in exact_frames:
        for kid in (12, 15, 16, 19):
            if kid in labels.keypoints:
                seen += 1
                assert labels.keypoints[kid].set == "Kp"
                assert kid not in labels.reprojection_errors
    assert seen > 0


# ------------------------------------------------------------------------------ disambiguation
def test_orientation_convention_on_both_sides():
    """A camera above the ground keeps the sign of world cross products, from either side; the
    mirror assignment (a "bottom view") flips it."""
    rng = np.random.default_rng(3)
    world = np.array([[-36.0, -20.16], [-36.0, 20.16], [-52.5, -20.16], [-52.5, 20.16], [-41.5, 0.0]])
    for side in (1.0, -1.0):
        for _ in range(10):
            pos = [rng.uniform(-20, 20), side * rng.uniform(40, 70), -rng.uniform(8, 25)]
            cam = Camera.from_look_at(pos, [-44.0, 0.0, 0.0], hfov_deg=50, width=W, height=H)
            img = cam.project(np.c_[world, np.zeros(len(world))], distort=False)
            Hm = fit_homography(world, img)
            assert Hm is not None and orientation_ok(Hm, world)
            assert orientation_outliers(world, img) == []
            mirrored = world * np.array([1.0, -1.0])  # y -> -y: swaps top and bottom
            Hb = fit_homography(mirrored, img)
            assert Hb is not None and not orientation_ok(Hb, mirrored)
            swapped = img.copy()
            swapped[[0, 1]] = swapped[[1, 0]]  # one mislabelled pair
            assert set(orientation_outliers(world, swapped)) & {0, 1}


def test_grid_search_disambiguates_circle_only_views():
    """Few line-line points: Kp1/Kp2 candidates are resolved by the set-wise grid search and the
    orientation check (the swapped tangent points fit as well, but mirrored)."""
    rng = np.random.default_rng(11)
    hits = 0
    for _ in range(60):
        cam = Camera.from_look_at([rng.uniform(-8, 8), rng.uniform(40, 60), -rng.uniform(10, 20)],
                                  [rng.uniform(-3, 3), rng.uniform(-20, -10), 0], hfov_deg=rng.uniform(30, 45),
                                  width=W, height=H)
        ann = synth_annotation(cam, rng)
        ann = {k: v for k, v in ann.items() if k in ("Middle line", "Circle central", "Side line top")}
        labels = keypoints_from_annotation(ann, W, H)
        for kid, err in label_errors(cam, labels).items():
            assert err <= TOL[labels.keypoints[kid].set]
        if labels.disambiguation == "grid" and any(k.set in ("Kp1", "Kp2") for k in labels.keypoints.values()):
            hits += 1
    assert hits >= 5


def test_wrong_line_label_is_rejected():
    """A mislabelled line produces an inconsistent point that validation rejects."""
    rng = np.random.default_rng(5)
    checked = 0
    for _ in range(30):
        cam = broadcast_camera(rng)
        ann = synth_annotation(cam, rng)
        if not {"Big rect. left main", "Small rect. left main", "Big rect. left top"} <= set(ann):
            continue
        base = keypoints_from_annotation(ann, W, H)
        if base.homography is None or len(base.reprojection_errors) < 8:
            continue
        bad = dict(ann)
        bad["Big rect. left main"] = ann["Small rect. left main"]  # two box lines swapped
        bad["Small rect. left main"] = ann["Big rect. left main"]
        labels = keypoints_from_annotation(bad, W, H)
        wrong = {k: e for k, e in label_errors(cam, labels).items() if e > 5}
        assert not wrong, wrong
        assert any("far from the ends" in r.reason for r in labels.rejected)
        checked += 1
    assert checked >= 4


# ------------------------------------------------------------------------------ left-right
def test_left_right_disambiguation():
    rng = np.random.default_rng(9)
    params = LabelParams(lr_disambiguation=True)
    decided = Counter()
    for i in range(24):
        end = 1.0 if i % 2 else -1.0  # behind the right goal (looks towards -x) or the left one
        cam = behind_goal_camera(rng, end)
        ann = synth_annotation(cam, rng)
        labels = keypoints_from_annotation(ann, W, H, params)
        if labels.homography is None:
            continue
        assert labels.mirrored == (end > 0)
        decided[end] += 1
        for kid, err in label_errors(cam, labels, mirrored=labels.mirrored).items():
            assert err <= TOL[labels.keypoints[kid].set]
        ext = line_extremities(ann, W, H, mirror=labels.mirrored)
        assert set(ext) == {CLASS_TO_LINE_ID[MIRROR[c] if labels.mirrored else c]
                            for c in ann if c in CLASS_TO_LINE_ID}
    assert decided[1.0] >= 6 and decided[-1.0] >= 6
    for _ in range(20):  # side cameras looking across the pitch are never mirrored
        cam = Camera.from_look_at([rng.uniform(-10, 10), rng.uniform(40, 70), -rng.uniform(10, 25)],
                                  [rng.uniform(-35, 35), rng.uniform(-20, 20), 0], hfov_deg=40, width=W, height=H)
        labels = keypoints_from_annotation(synth_annotation(cam, rng), W, H, params)
        assert not labels.mirrored


def test_viewing_azimuth_and_mirror_table():
    cam = Camera.from_look_at([0, 55, -15], [-30, 0, 0], hfov_deg=40, width=W, height=H)
    az = viewing_azimuth_deg(cam.ground_homography(), np.array([480.0, 400.0]))
    ground = cam.back_project_to_ground(np.array([[480.0, 400.0]]))[0]
    d = ground[:2] - cam.C[:2]
    assert az == pytest.approx(math.degrees(math.atan2(abs(d[1]), d[0])), abs=0.5)
    assert not lr_decision(None).mirror
    ann = {"Goal left post left": np.zeros((2, 2)), "Side line top": np.ones((2, 2))}
    assert set(mirror_annotation(ann)) == {"Goal right post left", "Side line bottom"}


# ------------------------------------------------------------------------------ heatmaps
def test_heatmap_targets_layout_and_peaks(exact_frames):
    for cam, ann, labels in exact_frames[:8]:
        ext = line_extremities(ann, W, H)
        t = heatmap_targets(labels, ext, W, H)
        assert t.keypoints.shape == (58, H // 2, W // 2) and t.keypoints.dtype == np.float32
        assert t.lines.shape == (24, H // 2, W // 2) and t.lines.dtype == np.float32
        assert t.keypoint_mask.shape == (58,) and t.line_mask.shape == (24,)
        np.testing.assert_allclose(t.keypoints[57], 1.0 - t.keypoints[:57].max(axis=0), atol=1e-6)
        drawn = set()
        for kid, kp in labels.keypoints.items():
            if kid > 57 or not kp.visible:
                continue
            drawn.add(kid)
            ch = t.keypoints[kid - 1]
            r, c = np.unravel_index(np.argmax(ch), ch.shape)
            assert abs(c - kp.x / 2) <= 0.5 + 1e-9 and abs(r - kp.y / 2) <= 0.5 + 1e-9
            assert ch.max() > 0.88
        for kid in set(range(1, 58)) - drawn:
            assert t.keypoints[kid - 1].max() == 0.0
        for lid, e in ext.items():
            ch = t.lines[lid - 1]
            for p in (e.p1, e.p2):
                q = np.clip(np.round(p / 2).astype(int), 0, [W // 2 - 1, H // 2 - 1])
                if 0 <= p[0] <= W - 1 and 0 <= p[1] <= H - 1:
                    assert ch[q[1], q[0]] > 0.85
            mid = np.round((e.p1 + e.p2) / 4).astype(int)  # on the line (straight, no distortion)
            if 0 <= mid[0] < W // 2 and 0 <= mid[1] < H // 2:
                assert t.lines[23][mid[1], mid[0]] > 0.85
        assert not set(range(1, 24)) - set(ext) & {lid for lid in range(1, 24) if t.lines[lid - 1].any()}


def test_keypoint_mask_rules():
    cam = Camera.from_look_at([0, 50, -15], [0, -15, 0], hfov_deg=35, width=W, height=H)
    ann = synth_annotation(cam, np.random.default_rng(1))
    only_circle = {k: v for k, v in ann.items() if k in ("Circle central", "Middle line")}
    labels = keypoints_from_annotation(only_circle, W, H)
    assert labels.homography is None and not labels.keypoints
    mask = keypoint_mask(labels)
    for kid in (32, 35, 38, 39, 42, 43, 48, 49, 50, 51, 52, 53, 54):  # their classes are annotated
        assert mask[kid - 1] == 0.0
    for kid in (1, 5, 31, 34, 45):  # not in view: a background target is right
        assert mask[kid - 1] == 1.0
    assert mask[57] == 1.0
    full = keypoints_from_annotation(ann, W, H)
    assert full.homography is not None
    mask = keypoint_mask(full)
    for kid in (37, 40, 41, 44):  # external points 5, 6, 25, 26 are not in view
        assert mask[kid - 1] == 0.0
    assert mask[:36].all() and mask[44:].all()


def test_training_targets_mirror_lines_with_keypoints():
    rng = np.random.default_rng(4)
    cam = behind_goal_camera(rng, 1.0)
    ann = synth_annotation(cam, rng)
    labels, ext, targets = training_targets(ann, W, H)
    assert labels.mirrored
    assert {e.name for e in ext.values()} == {MIRROR[c] for c in ann if c in CLASS_TO_LINE_ID}
    assert targets.keypoints.shape == (58, 270, 480)
    for kid, kp in labels.keypoints.items():  # the heatmaps follow the mirrored labels
        if kid <= 57 and kp.visible:
            ch = targets.keypoints[kid - 1]
            r, c = np.unravel_index(np.argmax(ch), ch.shape)
            assert abs(c - kp.x / 2) <= 0.5 + 1e-9 and abs(r - kp.y / 2) <= 0.5 + 1e-9


# ------------------------------------------------------------------------------ JSON
def test_json_round_trip(exact_frames, tmp_path):
    from pnlviz.labels import read_labels, write_labels

    cam, ann, labels = exact_frames[0]
    ext = line_extremities(ann, W, H)
    path = tmp_path / "00001.json"
    write_labels(path, labels, ext)
    d = json.loads(path.read_text())
    assert d["image_size"] == [W, H] and set(d) >= {"image_size", "keypoints", "lines"}
    for kid, v in d["keypoints"].items():
        assert set(v) == {"x", "y", "visible", "set"}
    back, ext_back = read_labels(path)
    assert back.keypoints == labels.keypoints
    assert set(ext_back) == set(ext)
    assert labels_to_dict(labels_from_dict(labels_to_dict(labels, ext))[0]) == labels_to_dict(labels)


# ------------------------------------------------------------------------------ real data
@needs_shared
def test_sn22_annotations_all_label():
    from pnlviz.data import open_dataset

    ds = open_dataset(SN22)
    totals: Counter[str] = Counter()
    n = with_h = 0
    for _, ann in ds.iter_annotations():
        labels = keypoints_from_annotation(ann, W, H)
        n += 1
        with_h += labels.homography is not None
        totals.update(labels.count_by_set())
        for kp in labels.keypoints.values():
            assert math.isfinite(kp.x) and math.isfinite(kp.y)
        ext = line_extremities(ann, W, H)
        heatmap_targets(labels, ext, W, H) if n <= 20 else None
    assert n == 400 and not ds.skipped
    per_set = {s: round(totals[s] / n, 2) for s in SETS}
    print(f"\nSN22 subset: {n} frames, keypoints per frame by set {per_set}, "
          f"total {sum(totals.values()) / n:.2f}, homography in {with_h / n:.0%}")
    assert per_set["Kp"] >= 6 and sum(totals.values()) / n >= 12
    assert with_h / n >= 0.85


# ------------------------------------------------------------------------------ CLI
def _cli_args(argv):
    parser = argparse.ArgumentParser(prog="pnlviz")
    add_labels_parser(parser.add_subparsers(dest="command"))
    return parser.parse_args(["labels", *argv])


@pytest.mark.parametrize("workers", [1, 2])
def test_cli_writes_one_json_per_frame(tmp_path, capsys, workers):
    data = tmp_path / "data"
    data.mkdir()
    rng = np.random.default_rng(21)
    good = []
    for i in range(4):
        stem = f"{i + 1:05d}"
        ann = synth_annotation(broadcast_camera(rng), rng)
        payload = {k: [{"x": float(x), "y": float(y)} for x, y in v] for k, v in ann.items()}
        (data / f"{stem}.json").write_text(json.dumps(payload))
        good.append(stem)
    (data / "00005.json").write_text('{"Side line top": [{"x": 0.1}]}')  # bad frame
    (data / "00006.json").write_text("{not json")
    out = tmp_path / "labels"
    args = _cli_args(["--data", str(data), "--out", str(out), "--workers", str(workers), "--kp3-all"])
    assert args.func is run_labels
    assert run_labels(args) == 0
    captured = capsys.readouterr()
    assert sorted(p.stem for p in out.glob("*.json")) == good
    assert "00005.json" in captured.err and "00006.json" in captured.err
    assert "2 skipped" in captured.out and "keypoints per frame" in captured.out
    d = json.loads((out / "00001.json").read_text())
    assert d["image_size"] == [960, 540]


def test_cli_size_option_and_refuses_to_overwrite_annotations(tmp_path, capsys):
    data = tmp_path / "d"
    data.mkdir()
    rng = np.random.default_rng(2)
    ann = synth_annotation(broadcast_camera(rng), rng)
    (data / "1.json").write_text(json.dumps({k: [{"x": x, "y": y} for x, y in v.tolist()] for k, v in ann.items()}))
    assert run_labels(_cli_args(["--data", str(data), "--out", str(tmp_path / "o"), "--size", "1920x1080"])) == 0
    d = json.loads((tmp_path / "o" / "1.json").read_text())
    assert d["image_size"] == [1920, 1080]
    assert max(v["x"] for v in d["keypoints"].values()) > 960 or len(d["keypoints"]) == 0
    assert run_labels(_cli_args(["--data", str(data), "--out", str(data)])) == 2
    with pytest.raises(SystemExit):
        _cli_args(["--data", str(data), "--out", "x", "--size", "big"])


def test_flipped_annotation_gives_the_reflected_labels(exact_frames):
    """The labels of a horizontally flipped image (flip_annotation) are the labels of the original
    at x -> W - 1 - x, each under the id of the keypoint reflected in the halfway line."""
    from pnlviz.labels import flip_annotation

    ids = MODEL.keypoint_ids
    xyz = MODEL.keypoint_xyz(ids)
    reflected = {}
    for k, p in zip(ids, xyz):
        d = np.linalg.norm(xyz - p * np.array([-1.0, 1.0, 1.0]), axis=1)
        reflected[int(k)] = int(ids[np.argmin(d)])
        assert d.min() < 1e-6
    compared = 0
    for cam, ann, labels in exact_frames[:12]:
        flipped = keypoints_from_annotation(flip_annotation(ann), W, H)
        assert set(flipped.keypoints) == {reflected[k] for k in labels.keypoints}
        for k, lab in labels.keypoints.items():
            f = flipped.keypoints[reflected[k]]
            assert f.xy == pytest.approx([W - 1 - lab.x, lab.y], abs=0.05)
            compared += 1
    assert compared > 100
    as_dicts = flip_annotation({"Goal left post left": [{"x": 0.25, "y": 0.5}]})
    assert as_dicts == {"Goal right post right": [{"x": 0.75, "y": 0.5}]}
