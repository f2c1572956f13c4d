"""Metrics: the SoccerNet calibration score against the official package on real frames, the
homography metrics, and the camera <- ground homography decomposition."""

from __future__ import annotations

import argparse
import contextlib
import csv
import json
import math
import warnings
import zipfile
from pathlib import Path

import numpy as np
import pytest

from pnlviz.data import open_dataset, read_homographies
from pnlviz.field import MIRROR, load_field_model
from pnlviz.geometry import Camera, visible_pitch
from pnlviz.geometry.homography import (
    apply_homography, camera_from_ground_homography, field_to_image_from_template, normalize_homography,
)
from pnlviz.metrics.homography import (
    clip_polygon_to_box, evaluate_homographies, evaluate_homography, homography_from_camera, iou_whole,
    visible_field_pixels,
)
from pnlviz.data.cameras import read_cameras
from pnlviz.metrics.soccernet import (
    evaluate_dataset, evaluate_frame, point_to_polyline_distance,
)

MODEL = load_field_model()
T = MODEL.template_to_field_matrix
shared = Path(__file__).resolve().parents[2] / "shared"
DATA = shared / "data"
THRESHOLDS = (5.0, 10.0, 20.0)


def random_camera(rng, width=960, height=540, k1=0.0):
    """Broadcast-like cameras (the ranges of test_geometry.random_camera)."""
    pos = np.array([rng.uniform(-30, 30), rng.uniform(35, 70), -rng.uniform(6, 30)])
    if rng.random() < 0.2:
        pos[1] *= -1
    target = np.array([rng.uniform(-55, 55), rng.uniform(-30, 30), 0.0])
    return Camera.from_look_at(pos, target, hfov_deg=rng.uniform(8, 80), width=width, height=height,
                               roll_deg=rng.normal(0, 2), k1=k1)


def run_cli(*argv) -> int:
    from pnlviz.commands.evaluate import add_eval_parser

    parser = argparse.ArgumentParser()
    add_eval_parser(parser.add_subparsers())
    args = parser.parse_args(["eval", *map(str, argv)])
    return args.func(args)


# ============================================================== camera <- ground homography
def test_camera_from_ground_homography_recovers_random_cameras():
    rng = np.random.default_rng(11)
    for i in range(200):
        cam = random_camera(rng, *( (1280, 720) if i % 2 else (960, 540) ))
        H = cam.ground_homography() * rng.choice([-1, 1]) * 10 ** rng.uniform(-4, 4)
        got = camera_from_ground_homography(H, cam.width, cam.height)
        assert got is not None
        assert got.fx == pytest.approx(cam.fx, rel=1e-6) and got.fy == got.fx
        assert (got.cx, got.cy, got.width, got.height) == (cam.width / 2, cam.height / 2, cam.width, cam.height)
        np.testing.assert_allclose(got.R, cam.R, atol=1e-6)
        np.testing.assert_allclose(got.C, cam.C, rtol=1e-6, atol=1e-6 * np.linalg.norm(cam.C))
        assert np.linalg.det(got.R) == pytest.approx(1.0)
        if i % 10 == 0:  # the refinement keeps an exact camera exact
            ref = camera_from_ground_homography(H, cam.width, cam.height, refine=True)
            assert ref.fx == pytest.approx(cam.fx, rel=1e-6)
            np.testing.assert_allclose(ref.C, cam.C, rtol=1e-6, atol=1e-6 * np.linalg.norm(cam.C))


def test_camera_from_ground_homography_rejects_degenerate_input():
    assert camera_from_ground_homography(np.zeros((3, 3)), 960, 540) is None
    assert camera_from_ground_homography(np.full((3, 3), np.nan), 960, 540) is None
    # looking straight down: the focal length is not observable from a fronto-parallel plane
    nadir = Camera(1000, 1000, 480, 270, np.diag([1.0, -1.0, -1.0]), np.array([0, 0, -30.0]), 960, 540)
    assert camera_from_ground_homography(nadir.ground_homography(), 960, 540) is None
    # an affine map that no pinhole camera produces (f^2 would be negative)
    assert camera_from_ground_homography(np.array([[1, 0.9, 480], [0, 1, 270], [0, 0, 1.0]]), 960, 540) is None


# ============================================================================ distances
def _official():
    return pytest.importorskip("SoccerNet.Evaluation.utils_calibration")


def _as_dicts(arr):
    return [{"x": float(x), "y": float(y)} for x, y in arr]


def test_point_to_polyline_distance_is_bit_identical_to_the_official_one():
    sn = _official()
    rng = np.random.default_rng(5)
    cases = []
    for _ in range(60):
        m = int(rng.integers(1, 12))
        poly = np.cumsum(rng.normal(0, 40, (m, 2)), axis=0) + 400
        if m > 2 and rng.random() < 0.3:
            poly[1] = poly[0]  # a degenerate segment
        pts = np.vstack([rng.uniform(poly.min(0) - 50, poly.max(0) + 50, (8, 2)), poly[:2] + 1e-9])
        cases.append((pts, poly))
    # points exactly on a segment, at its ends, and on its perpendicular through an end
    cases.append((np.array([[5.0, 0.0], [0.0, 0.0], [10.0, 0.0], [0.0, 3.0], [10.0, -3.0]]),
                  np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]])))
    with warnings.catch_warnings(), np.errstate(all="ignore"):
        warnings.simplefilter("ignore", RuntimeWarning)
        for pts, poly in cases:
            theirs = [sn.distance_to_polyline(p, _as_dicts(poly)) for p in _as_dicts(pts)]
            np.testing.assert_array_equal(point_to_polyline_distance(pts, poly), theirs)


# ====================================================================== frame-level logic
def test_frames_scored_without_a_stem_have_no_split():
    """``evaluate_frame`` takes no stem by default: such frames sum up as they are, in no split
    (by_split raised AttributeError on them)."""
    from pnlviz.metrics.soccernet import Summary

    cam = Camera.from_look_at([0, 60, -20], [-30, 0, 0], hfov_deg=50, width=960, height=540)
    ann = {n: p[[0, -1]] / [959.0, 539.0] for n, p in visible_pitch(cam, evaluator_precision=True).items()}
    frames = [evaluate_frame(cam, ann), evaluate_frame(cam, ann, stem="valid/00001")]
    splits = Summary(frames[0].thresholds, frames).by_split()
    assert list(splits) == ["valid"] and [f.stem for f in splits["valid"].frames] == ["valid/00001"]


def test_frame_scores_follow_the_official_rules_on_a_synthetic_frame():
    cam = Camera.from_look_at([0, 60, -20], [-30, 0, 0], hfov_deg=50, width=960, height=540)
    projected = visible_pitch(cam, evaluator_precision=True)
    scale = np.array([959.0, 539.0])
    # annotation = 3 points on each projected polyline -> every class within 1e-9 px
    ann = {n: p[[0, len(p) // 2, -1]] / scale for n, p in projected.items()}
    res = evaluate_frame(cam, ann)
    for t in THRESHOLDS:
        s = res.score(t)
        assert (s.accuracy, s.tp, s.fp, s.fn, s.mirrored) == (1.0, len(ann), 0, 0, False)
    # the same frame labelled mirrored is scored under its mirror labels
    mirrored = evaluate_frame(cam.to_soccernet(), {MIRROR[n]: v for n, v in ann.items()})
    assert mirrored.score(5).mirrored and mirrored.accuracy(5) == 1.0
    # move one class 7 px: TP at 10 and 20 px, counted as a false positive at 5 px
    name = next(iter(ann))
    moved = dict(ann, **{name: ann[name] + np.array([0.0, 7.0]) / scale})
    r = evaluate_frame(cam, moved)
    assert r.score(5).fp == 1 and r.score(5).tp == len(ann) - 1 and r.score(10).tp == len(ann)
    assert r.matching(5).class_status(5)[name] == "far"
    assert r.matching(5).max_distance(name) == pytest.approx(7.0, abs=0.5)
    # an unknown class and an empty class: FN and dropped, as in the official scale_points
    r = evaluate_frame(cam, dict(ann, **{"Line unknown": np.array([[0.5, 0.5]]), "Goal unknown": np.zeros((0, 2))}))
    assert r.score(5).fn == 1 and r.accuracy(5) == pytest.approx(len(ann) / (len(ann) + 1), rel=1e-6)
    # nothing projected, nothing annotated: accuracy 0, mirrored (the evaluator's tie rule)
    sky = Camera.from_look_at([0, 50, -20], [0, 150, -80], hfov_deg=30, width=960, height=540)
    r = evaluate_frame(sky, {})
    assert r.score(5).empty and r.accuracy(5) == 0.0 and r.score(5).mirrored
    assert not evaluate_frame(None, ann).calibrated


# ========================================================= the official evaluator as oracle
@contextlib.contextmanager
def fast_official():
    """The official functions, with two exact accelerations so that hundreds of frames fit in
    the test budget (the official distance loop costs ~0.3 s per frame):

    * ``get_polylines`` is memoised on its arguments (it is a pure function);
    * ``distance_to_polyline(point, polyline)`` calls the official function on each segment that
      can hold the minimum (as a 2-point polyline: the same arithmetic as inside its loop) and
      memoises the result. A segment is left out only when a lower bound of its distance
      (distance to its midpoint minus half its length) exceeds the distance to the nearest
      vertex by 1e-6 px, so the official minimum is unchanged.
    """
    sn = _official()
    orig_poly, orig_dist = sn.get_polylines, sn.distance_to_polyline
    poly_cache, dist_cache, arrays = {}, {}, {}

    def get_polylines(camera, width, height, sampling_factor=0.2):
        key = (json.dumps(camera, sort_keys=True), width, height, sampling_factor)
        if key not in poly_cache:
            poly_cache[key] = orig_poly(camera, width, height, sampling_factor=sampling_factor)
        return poly_cache[key]

    def distance_to_polyline(point, polyline):
        key = (point["x"], point["y"], id(polyline))
        if key in dist_cache:
            return dist_cache[key]
        if len(polyline) < 3:
            d = orig_dist(point, polyline)
        else:
            if id(polyline) not in arrays:  # the polyline is kept alive by the cache: ids stay unique
                arrays[id(polyline)] = (polyline, np.array([[q["x"], q["y"]] for q in polyline]))
            P = arrays[id(polyline)][1]
            p = np.array([point["x"], point["y"]])
            upper = np.min(np.hypot(*(P - p).T))
            mid, half = (P[1:] + P[:-1]) / 2, np.hypot(*(P[1:] - P[:-1]).T) / 2
            lower = np.hypot(*(mid - p).T) - half
            kept = np.flatnonzero(lower <= upper + 1e-6)
            d = min(orig_dist(point, polyline[i:i + 2]) for i in kept)
        dist_cache[key] = d
        return d

    sn.get_polylines, sn.distance_to_polyline = get_polylines, distance_to_polyline
    cc = pytest.importorskip("SoccerNet.Evaluation.CameraCalibration")
    cc_poly = cc.get_polylines
    cc.get_polylines = get_polylines  # CameraCalibration imported the name itself
    try:
        with warnings.catch_warnings(), np.errstate(all="ignore"):
            warnings.simplefilter("ignore", RuntimeWarning)
            yield sn, cc
    finally:
        sn.get_polylines, sn.distance_to_polyline, cc.get_polylines = orig_poly, orig_dist, cc_poly


def write_gt_zip(path: Path, frames: dict[str, bytes]) -> None:
    """The layout CameraCalibration.evaluate expects: ``split/<stem>.json`` members only."""
    with zipfile.ZipFile(path, "w") as zf:
        for stem, data in frames.items():
            zf.writestr(f"test/{stem}.json", data)


def write_pred_zip(path: Path, cameras: dict[str, dict]) -> None:
    with zipfile.ZipFile(path, "w") as zf:
        for stem, cam in cameras.items():
            zf.writestr(f"camera_{stem}.json", json.dumps(cam))


def official_frame(sn, camera: dict, gt_json: dict, t: float):
    """The official per-frame result with its mirror logic (as in CameraCalibration.evaluate)."""
    projected = sn.get_polylines(camera, 960, 540, sampling_factor=0.9)
    gt = sn.scale_points(gt_json, 960, 540)
    c1, pc1, _ = sn.evaluate_camera_prediction(projected, gt, t)
    c2, pc2, _ = sn.evaluate_camera_prediction(projected, sn.mirror_labels(gt), t)
    a1 = c1[0, 0] / c1.sum() if c1.sum() > 0 else 0.0
    a2 = c2[0, 0] / c2.sum() if c2.sum() > 0 else 0.0
    return (a1, c1, pc1, False) if a1 > a2 else (a2, c2, pc2, True)


def compare_with_official(tmp_path, gt_frames: dict[str, bytes], cameras: dict[str, dict], per_class=True):
    gt_zip, pred_zip = tmp_path / "gt.zip", tmp_path / "pred.zip"
    write_gt_zip(gt_zip, gt_frames)
    write_pred_zip(pred_zip, cameras)
    ours = evaluate_dataset(gt_zip, pred_zip, THRESHOLDS, progress=False)
    assert ours.n_frames == len(gt_frames) and not ours.skipped_annotations and not ours.skipped_cameras
    by_stem = {f.stem: f for f in ours.frames}
    counts = np.zeros(4, int)  # tp, far, fp, fn over frames at 5 px, to show the test bites
    with fast_official() as (sn, cc):
        for t in THRESHOLDS:
            theirs = cc.evaluate(gt_zip, pred_zip, threshold=t)
            assert abs(ours.jac(t) - theirs["meanAccuracies"]) <= 1e-9
            assert abs(ours.completeness - theirs["completeness"]) <= 1e-9
            assert abs(ours.precision(t) - theirs["meanPrecision"]) <= 1e-9
            assert abs(ours.recall(t) - theirs["meanRecall"]) <= 1e-9
            if t == 5:
                # the package has no final score; CR x JaC@5 in float64 (a float32 JaC would
                # otherwise make the product float32 under numpy 2's promotion rules)
                assert abs(ours.final_score - float(theirs["completeness"]) * float(theirs["meanAccuracies"])) <= 1e-9
            if per_class:
                for name, v in ours.per_class(t).items():
                    for k in ("accuracy", "precision", "recall"):
                        np.testing.assert_allclose(v[k], theirs[f"{name}{k.capitalize()}"], rtol=0, atol=1e-12)
            for stem, data in gt_frames.items():
                mine = by_stem[stem]
                if stem not in cameras:
                    assert not mine.calibrated
                    continue
                acc, conf, pcc, mirrored = official_frame(sn, cameras[stem], json.loads(data), t)
                s = mine.score(t)
                assert abs(s.accuracy - acc) <= 1e-9, (stem, t)
                assert (s.tp, s.fp, s.fn, s.mirrored) == (conf[0, 0], conf[0, 1], conf[1, 0], mirrored), (stem, t)
                mine_pc = mine.matching(t).class_confusion(t)
                assert set(mine_pc) == set(pcc)
                for name, m in pcc.items():
                    np.testing.assert_array_equal(mine_pc[name], m)
                if t == 5:
                    status = list(mine.matching(t).class_status(t).values())
                    counts += [status.count(k) for k in ("tp", "far", "fp", "fn")]
    return ours, counts


@pytest.fixture(scope="module")
def wc14(shared_dir):
    ds = open_dataset(DATA / "wc14_test_half" / "annotations.zip")
    Hs = read_homographies(DATA / "wc14_test_half" / "homographies.json")
    raw = {s: ds._read(ds.frame(s).annotation_path) for s in ds.stems}
    cams = {}
    for s in ds.stems:
        cam = camera_from_ground_homography(field_to_image_from_template(Hs[s], T), 1280, 720, refine=True)
        cams[s] = cam.scaled(960, 540)
    return ds, Hs, raw, cams


def perturbed(cam: Camera, rng, k1=0.0, turned=False) -> dict:
    """Small pose/focal noise (a few pixels at 960x540): many classes end up near 5-10 px.
    ``turned``: the camera also turned half a turn about the centre spot, so that it sees the
    same picture with every label mirrored."""
    from scipy.spatial.transform import Rotation

    half_turn = np.diag([-1.0, -1.0, 1.0]) if turned else np.eye(3)
    R = Rotation.from_rotvec(rng.normal(0, np.radians(0.08), 3)).as_matrix() @ cam.R @ half_turn
    C = half_turn @ cam.C + rng.normal(0, 0.15, 3)
    f = cam.fx * (1 + rng.normal(0, 0.01))
    radial = np.zeros(6)
    radial[0] = k1
    return Camera(f, f, cam.cx, cam.cy, R, C, cam.width, cam.height, radial).to_soccernet()


def test_wc14_cameras_from_ground_truth_homographies_match_the_official_score(tmp_path, wc14):
    ds, _, raw, cams = wc14
    cameras = {s: c.to_soccernet() for s, c in cams.items()}
    ours, counts = compare_with_official(tmp_path, raw, cameras)
    assert ours.completeness == 1.0 and ours.jac(20) > 0.8
    assert counts[0] > 100 and counts[1] > 20  # both kinds of matched class at 5 px


def test_wc14_perturbed_and_distorted_cameras_match_the_official_score(tmp_path, wc14):
    ds, _, raw, cams = wc14
    rng = np.random.default_rng(2024)
    cameras, frames = {}, {}
    for i, s in enumerate(ds.stems):
        if i % 11 == 5:
            frames[s] = raw[s]  # no camera: not calibrated
            continue
        frames[s] = raw[s]
        cameras[s] = perturbed(cams[s], rng, k1=rng.uniform(-0.5, 0.5) if i % 3 == 0 else 0.0, turned=i % 4 == 1)
    ours, counts = compare_with_official(tmp_path, frames, cameras)
    assert ours.completeness < 1
    turned = [f for i, f in enumerate(ours.frames) if f.calibrated and i % 4 == 1]
    assert sum(f.score(10).mirrored and f.score(10).tp > 3 for f in turned) > 0.8 * len(turned)
    assert counts[0] > 50 and counts[1] > 50, counts  # borderline: plenty of both at 5 px
    assert 0.1 < ours.jac(5) < ours.jac(10) < ours.jac(20)


def test_sn22_with_cameras_that_do_not_fit_matches_the_official_score(tmp_path, wc14):
    _, _, _, cams = wc14
    ds = open_dataset(DATA / "sn22_test_subset" / "annotations.zip")
    frames = {s: ds._read(ds.frame(s).annotation_path) for s in ds.stems}
    wc = list(cams.values())
    cameras = {s: wc[i % len(wc)].to_soccernet() for i, s in enumerate(ds.stems) if i % 17}
    # crafted frames: unknown classes (official: false negatives), an empty class, an empty
    # annotation seen by a camera that sees no pitch (the evaluator's plain 0.0 accuracy)
    first = json.loads(frames[ds.stems[0]])
    first["Line unknown"] = [{"x": 0.5, "y": 0.5}, {"x": 0.6, "y": 0.5}]
    first["Goal unknown"] = []
    frames["99990"] = json.dumps(first).encode()
    cameras["99990"] = wc[0].to_soccernet()
    frames["99991"] = b"{}"
    cameras["99991"] = Camera.from_look_at([0, 50, -20], [0, 150, -80], hfov_deg=30, width=960,
                                           height=540).to_soccernet()
    ours, counts = compare_with_official(tmp_path, frames, cameras)
    assert counts[2] > 500 and counts[3] > 500  # false positives and negatives galore
    assert sum(f.calibrated and f.score(20).tp > 0 for f in ours.frames) > 20
    assert ours.jac(5) < 0.3


def test_unaccelerated_official_evaluator_agrees_on_a_few_frames(tmp_path, wc14):
    """The complete official code path, without the test's accelerations, on 6 frames."""
    ds, _, raw, cams = wc14
    _official()
    from SoccerNet.Evaluation.CameraCalibration import evaluate as official_evaluate

    rng = np.random.default_rng(9)
    stems = ds.stems[:6]
    frames = {s: raw[s] for s in stems}
    cameras = {s: perturbed(cams[s], rng) for s in stems[1:]}
    write_gt_zip(tmp_path / "gt.zip", frames)
    write_pred_zip(tmp_path / "pred.zip", cameras)
    ours = evaluate_dataset(tmp_path / "gt.zip", tmp_path / "pred.zip", (5,), progress=False)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        theirs = official_evaluate(tmp_path / "gt.zip", tmp_path / "pred.zip", threshold=5)
    assert abs(ours.jac(5) - theirs["meanAccuracies"]) <= 1e-9
    assert ours.completeness == theirs["completeness"] == 5 / 6


def test_evaluate_dataset_reports_and_skips_bad_files(tmp_path, wc14):
    ds, _, raw, cams = wc14
    stems = ds.stems[:5]
    gt = tmp_path / "gt"
    gt.mkdir()
    for s in stems:
        (gt / f"{s}.json").write_bytes(raw[s])
    (gt / "bad.json").write_text('{"Side line top": [{"x": 0.1}]}')
    pred = tmp_path / "pred.zip"
    with zipfile.ZipFile(pred, "w") as zf:
        for s in stems[:3]:
            zf.writestr(f"camera_{s}.json", json.dumps(cams[s].to_soccernet()))
        zf.writestr(f"camera_{stems[3]}.json", "{not json")
        zf.writestr("camera_extra.json", json.dumps(cams[stems[0]].to_soccernet()))
    lines = []
    summary = evaluate_dataset(gt, pred, progress=False, on_error=lines.append)
    assert summary.n_frames == 5 and summary.n_calibrated == 3 and summary.completeness == 0.6
    assert len(summary.skipped_annotations) == 1 and "bad.json" in summary.skipped_annotations[0]
    assert len(summary.skipped_cameras) == 1 and f"camera_{stems[3]}.json" in summary.skipped_cameras[0]
    assert summary.unmatched_cameras == ["extra"] and len(lines) == 2
    assert all("\n" not in line for line in lines)
    # the same with Camera objects, and in two processes
    from pnlviz.commands.batch import map_items  # what pnlviz eval --workers 2 runs it with

    direct = evaluate_dataset(gt, {s: cams[s] for s in stems[:3]}, progress=False,
                              run=lambda fn, chunks: map_items(fn, chunks, processes=2, desc="eval", progress=False))
    assert [f.accuracy(5) for f in direct.frames if f.calibrated] == \
           [f.accuracy(5) for f in summary.frames if f.calibrated]
    cams_read, problems = read_cameras(pred)
    assert set(cams_read) == set(stems[:3]) | {"extra"} and len(problems) == 1


def test_eval_command_prints_scores_and_writes_the_csv(tmp_path, wc14, capsys):
    ds, Hs, raw, cams = wc14
    stems = ds.stems[:8]
    write_gt_zip(tmp_path / "gt.zip", {s: raw[s] for s in stems})
    with zipfile.ZipFile(tmp_path / "pred.zip", "w") as zf:
        for s in stems[:6]:
            zf.writestr(f"camera_{s}.json", json.dumps(cams[s].to_soccernet()))
        zf.writestr(f"camera_{stems[6]}.json", "[]")
    (tmp_path / "gt_h.json").write_text(json.dumps({s: Hs[s].tolist() for s in stems}))
    (tmp_path / "pred_h.json").write_text(json.dumps({**{s: Hs[s].tolist() for s in stems[:4]}, stems[4]: "x"}))
    rc = run_cli("--gt", tmp_path / "gt.zip", "--pred", tmp_path / "pred.zip", "--csv", tmp_path / "f.csv",
                 "--homographies", tmp_path / "gt_h.json", "--no-progress")
    out, err = capsys.readouterr()
    assert rc == 0
    assert "frames 8, calibrated 6" in out and "completeness CR 0.7500" in out and "final score" in out
    assert "IoU part" in out and "proj. error (m)" in out
    assert err.count("skipped:") == 1 and f"camera_{stems[6]}.json" in err
    rows = list(csv.DictReader((tmp_path / "f.csv").open()))
    assert [r["stem"] for r in rows] == list(stems)
    assert list(rows[0]) == ["stem", "calibrated", "acc@5", "acc@10", "acc@20", "mirrored@5", "tp@5", "fp@5", "fn@5"]
    assert rows[7]["calibrated"] == "0" and rows[7]["acc@5"] == ""
    rc = run_cli("--homographies", tmp_path / "gt_h.json", "--pred-homographies", tmp_path / "pred_h.json",
                 "--thresholds", "10", "--no-progress")
    out, err = capsys.readouterr()
    assert rc == 0 and "without prediction 4" in out and err.count("skipped:") == 1
    assert run_cli("--gt", tmp_path / "gt.zip") == 2


# ============================================================================ homography metrics
@pytest.fixture(scope="module")
def gt_h(shared_dir):
    return read_homographies(DATA / "wc14_test_half" / "homographies.json")


def test_identical_homographies_score_perfectly(gt_h):
    for H in list(gt_h.values())[:10]:
        r = evaluate_homography(H, -3.0 * H)  # scale and sign do not matter
        assert r.iou_part == 1.0 and r.iou_whole == pytest.approx(1.0, abs=1e-12)
        assert r.proj_error_m == pytest.approx(0.0, abs=1e-9) and r.reproj_error == pytest.approx(0.0, abs=1e-9)


def test_a_one_yard_shift_gives_the_expected_errors(gt_h):
    shift = np.array([[1.0, 0, 1.0], [0, 1.0, 0], [0, 0, 1.0]])  # template x + 1 yd
    for H in list(gt_h.values())[:10]:
        r = evaluate_homography(H, H @ shift)
        assert r.proj_error_m == pytest.approx(1 / 1.09361, rel=1e-9)  # 0.9144 m
        assert r.iou_whole == pytest.approx(114 / 116, rel=1e-9)
        assert 0.85 < r.iou_part < 1.0
        assert 0 < r.reproj_error < 0.2


def test_failures_and_missing_predictions_are_counted_apart(gt_h):
    stems = list(gt_h)[:6]
    H = gt_h[stems[0]]
    tilt = np.array([[1, 0, 0], [0, 1, 0], [0.0, -0.05, 1.0]])  # w = 1 - 0.05 y: zero at y = 20 yd
    # a prediction whose horizon cuts through the visible field: pixels showing template y > 20
    # lie above it, their predicted back-projection is behind the camera
    bad = H @ np.linalg.inv(tilt)
    r = evaluate_homography(H, bad)
    assert math.isnan(r.proj_error_m)
    assert 0 < r.iou_whole < 1 and 0 < r.iou_part < 1 and r.reproj_error > 0.1  # the template itself is in front
    # a prediction that sends the template beyond the ground-truth horizon: unbounded, no IoU whole
    r = evaluate_homography(H, H @ tilt)
    assert math.isnan(r.iou_whole) and np.isfinite(r.proj_error_m)
    pred = {stems[0]: bad, stems[1]: gt_h[stems[1]], stems[2]: np.zeros((3, 3))}
    s = evaluate_homographies({k: gt_h[k] for k in stems}, pred)
    assert s.n_frames == 6 and s.n_missing == 3
    assert s.n_failed("proj_error_m") == 2 and s.mean("proj_error_m") == pytest.approx(0.0, abs=1e-9)
    assert len(s.values("iou_part")) == 2 and s.median("iou_part") == pytest.approx(s.mean("iou_part"))
    assert "failed" in s.table() and s.as_dict()["missing"] == 3


def test_visible_pixels_are_seeded_and_on_the_field(gt_h):
    H = next(iter(gt_h.values()))
    a, b = visible_field_pixels(H, seed=3), visible_field_pixels(H, seed=3)
    assert len(a) == 2500 and np.array_equal(a, b) and not np.array_equal(a, visible_field_pixels(H, seed=4))
    xy = apply_homography(np.linalg.inv(H), a)
    assert np.all((xy >= 0) & (xy <= [115, 74]))
    assert np.all(a == np.round(a)) and np.all((a >= 0) & (a < [1280, 720]))


def test_polygon_clipping_areas():
    from pnlviz.metrics.homography import _area

    sq = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
    assert abs(_area(clip_polygon_to_box(sq, 0, 0, 5, 5))) == pytest.approx(1.0)
    assert abs(_area(clip_polygon_to_box(sq[::-1], 0, 0, 5, 5))) == pytest.approx(1.0)
    assert len(clip_polygon_to_box(sq + 10, 0, 0, 5, 5)) == 0
    L = np.array([[0, 0], [4, 0], [4, 1], [1, 1], [1, 4], [0, 4.0]])  # non-convex, area 7
    assert abs(_area(clip_polygon_to_box(L, 0, 0, 2, 2))) == pytest.approx(3.0)
    assert abs(_area(clip_polygon_to_box(L, -1, -1, 9, 9))) == pytest.approx(7.0)
    # IoU whole of a pure template scaling: the rectangle shrunk to half its size
    H = homography_from_camera(random_camera(np.random.default_rng(1)))
    half = np.diag([0.5, 0.5, 1.0])
    assert iou_whole(H, H @ half) == pytest.approx(0.25, rel=1e-9)


def test_homography_from_camera_round_trips_through_the_decomposition():
    rng = np.random.default_rng(21)
    for _ in range(30):
        cam = random_camera(rng)  # 960 x 540
        H = homography_from_camera(cam, MODEL)
        assert np.linalg.det(H) > 0
        # the 960x540 camera rescaled: template points land at 4/3 of their 960x540 pixels
        X = np.array([[10.0, 20.0], [60.0, 40.0], [100.0, 70.0]])
        uv, depth = cam.project_with_depth(np.hstack([MODEL.template_to_field(X), np.zeros((3, 1))]), distort=False)
        front = depth > 0
        np.testing.assert_allclose(apply_homography(H, X)[front], uv[front] * 4 / 3, rtol=1e-9)
        back = camera_from_ground_homography(field_to_image_from_template(H, T), 1280, 720)
        np.testing.assert_allclose(normalize_homography(homography_from_camera(back, MODEL)),
                                   normalize_homography(H), atol=1e-9)
        assert homography_from_camera(cam.to_soccernet()) == pytest.approx(H)
        r = evaluate_homography(H, homography_from_camera(back))
        assert (r.iou_part, r.proj_error_m < 1e-6) == (1.0, True)
    # a PnLCalib-style principal point ((W - 1) / 2): the true size is given explicitly
    d = dict(cam.to_soccernet(), principal_point=[479.5, 269.5])
    assert homography_from_camera(d, source_size=(959, 539)) == pytest.approx(
        homography_from_camera(Camera.from_soccernet(d, 959, 539)))


def test_wc14_ground_truth_homographies_survive_the_camera_decomposition(gt_h):
    """WC14 homographies are hand-annotated, not exactly a centred square-pixel camera's: the
    closed-form decomposition is approximate, its refinement close to exact."""
    results = {}
    for refine in (False, True):
        pred = {}
        for s, H in gt_h.items():
            cam = camera_from_ground_homography(field_to_image_from_template(H, T), 1280, 720, refine=refine)
            assert cam is not None
            pred[s] = homography_from_camera(cam, MODEL)
        results[refine] = evaluate_homographies(gt_h, pred)
    closed, refined = results[False], results[True]
    assert closed.n_failed("iou_part") == refined.n_failed("iou_part") == 0
    assert closed.median("iou_part") > 0.94 and refined.median("iou_part") > 0.985
    assert refined.mean("iou_part") > 0.985 and refined.median("proj_error_m") < 0.2
    assert refined.median("reproj_error") < closed.median("reproj_error") / 5


def test_the_package_exports_load_lazily():
    import subprocess
    import sys

    # a fresh interpreter: importing the package loads neither its modules nor OpenCV...
    code = ("import sys; import pnlviz.metrics as m; "
            "assert 'pnlviz.metrics.soccernet' not in sys.modules and 'cv2' not in sys.modules; "
            "m.evaluate_frame; assert 'pnlviz.metrics.soccernet' in sys.modules; "
            "assert 'pnlviz.metrics.homography' not in sys.modules; print('ok')")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and out.stdout.strip() == "ok", out.stderr
    # ...and the first use gives the module's own object
    import pnlviz.metrics as metrics
    from pnlviz.metrics import soccernet

    assert metrics.evaluate_frame is soccernet.evaluate_frame and "iou_part" in dir(metrics)
    with pytest.raises(AttributeError):
        metrics.no_such_metric
