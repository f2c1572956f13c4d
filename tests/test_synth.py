"""Synthetic frames: determinism, the evaluator oracle, visible markings, camera sampling, layout."""

from __future__ import annotations

import argparse
import json
import re
from collections import Counter
from pathlib import Path

import cv2
import numpy as np
import pytest

from pnlviz.field.model import load_field_model
from pnlviz.geometry.camera import Camera
from pnlviz.geometry.polylines import visible_pitch
from pnlviz.synth import KINDS, annotate, annotation_to_json, generate, make_frame, render, sample_camera
from pnlviz.synth.annotate import clicks_for_class, evaluation_camera, split_runs
from pnlviz.synth.cameras import camera_problem
from pnlviz.commands.common import parse_size
from pnlviz.commands.synth import add_synth_parser
from pnlviz.synth.render import GROUND, ray_grid
from pnlviz.synth.writer import OutputFolderError


SMALL = (480, 270)
MODEL = load_field_model()


def evaluator_accuracy(sn, cam_json: dict, ann_json: dict, threshold: float = 0.5):
    """The official evaluator ``sn`` (the ``evaluator`` fixture), used directly: (TP, FP, FN, accuracy)."""
    polylines = sn.get_polylines(cam_json, 960, 540, sampling_factor=0.9)
    conf, _, _ = sn.evaluate_camera_prediction(polylines, sn.scale_points(ann_json, 960, 540), threshold)
    tp, fp, fn = float(conf[0, 0]), float(conf[0, 1]), float(conf[1, 0])
    return tp, fp, fn, tp / (tp + fp + fn)


def folder_bytes(root: Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def small_run(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("synth") / "a"
    generate(out, 3, seed=5, size=SMALL, progress=False)
    return out


# ----------------------------------------------------------------------------- (a) determinism
def test_same_seed_gives_identical_files_and_worker_count_does_not_matter(small_run, tmp_path):
    again = tmp_path / "again"
    generate(again, 3, seed=5, size=SMALL, progress=False)
    assert folder_bytes(again) == folder_bytes(small_run)
    pooled = tmp_path / "pooled"
    from pnlviz.commands.batch import map_items  # what pnlviz synth --workers 2 runs it with

    generate(pooled, 3, seed=5, size=SMALL, progress=False,
             run=lambda fn, jobs: map_items(fn, jobs, processes=2, desc="synth", progress=False))
    assert folder_bytes(pooled) == folder_bytes(small_run)


def test_different_seed_gives_different_frames(small_run, tmp_path):
    other = tmp_path / "other"
    generate(other, 3, seed=6, size=SMALL, progress=False)
    a, b = folder_bytes(small_run), folder_bytes(other)
    assert a.keys() == b.keys()
    for name in a:
        assert a[name] != b[name], name


def test_a_frame_depends_only_on_seed_and_index(small_run, tmp_path):
    part = tmp_path / "part"
    generate(part, 1, seed=5, size=SMALL, start_index=2, progress=False)
    files = folder_bytes(part)
    assert sorted(files) == ["00002.jpg", "00002.json", "cameras/camera_00002.json"]
    full = folder_bytes(small_run)
    for name, data in files.items():
        assert data == full[name]


def test_in_memory_frame_is_reproducible():
    a, b = make_frame(4, 9, SMALL), make_frame(4, 9, SMALL)
    assert np.array_equal(a["image"], b["image"])
    assert json.dumps(a["annotation"]) == json.dumps(b["annotation"])
    assert json.dumps(a["camera"]) == json.dumps(b["camera"])
    assert a["image"].shape == (SMALL[1], SMALL[0], 3) and a["image"].dtype == np.uint8


# ----------------------------------------------------------------------------- (b) the oracle
def test_oracle_ground_truth_camera_scores_perfectly_on_sampled_cameras(evaluator):
    kinds = Counter()
    for i in range(24):
        rng = np.random.default_rng([2024, i])
        kind = KINDS[i % 4] if i < 8 else None  # every kind at least twice
        camera, kind = sample_camera(rng, 960, 540, kind=kind)
        kinds[kind] += 1
        ann_json = json.loads(json.dumps(annotation_to_json(annotate(camera, rng))))
        cam_json = json.loads(json.dumps(camera.scaled(960, 540).to_soccernet()))
        tp, fp, fn, acc = evaluator_accuracy(evaluator, cam_json, ann_json)
        assert (fp, fn, acc) == (0.0, 0.0, 1.0), (i, kind, tp, fp, fn)
        assert tp == len(ann_json) >= 4
        for name, pts in ann_json.items():
            assert len(pts) >= 2, name
            if name.startswith("Circle"):
                assert 6 <= len(pts) <= 20, name
            else:  # both ends of the visible run and 0-2 clicks in between
                assert 2 <= len(pts) <= 4, name
    assert set(kinds) == set(KINDS)


def test_oracle_on_frames_written_to_disk(small_run, tmp_path, evaluator):
    full = tmp_path / "full"
    generate(full, 1, seed=77, progress=False)  # 960 x 540
    for root in (small_run, full):
        stems = sorted(p.stem for p in root.glob("*.jpg"))
        assert stems
        for stem in stems:
            ann_json = json.loads((root / f"{stem}.json").read_text())
            cam_json = json.loads((root / "cameras" / f"camera_{stem}.json").read_text())
            tp, fp, fn, acc = evaluator_accuracy(evaluator, cam_json, ann_json)
            assert (fp, fn, acc) == (0.0, 0.0, 1.0), (root, stem)
            assert "Goal left post left " in ann_json or "Goal left post left" not in ann_json
            assert cam_json["principal_point"] == [480.0, 270.0]
            image = cv2.imread(str(root / f"{stem}.jpg"))
            assert cam_json["synth"]["image_size"] == [image.shape[1], image.shape[0]]
            assert cam_json["synth"]["kind"] in KINDS


def test_annotation_is_at_evaluation_scale_whatever_the_image_size():
    rng = np.random.default_rng(3)
    camera, _ = sample_camera(rng, 960, 540)
    small = camera.scaled(*SMALL)
    a = annotate(camera, np.random.default_rng(1))
    b = annotate(small, np.random.default_rng(1))
    assert a.keys() == b.keys()
    for name in a:
        np.testing.assert_allclose(a[name], b[name], atol=1e-9)


def test_a_class_seen_as_a_single_point_still_gets_two_clicks_within_tolerance(evaluator):
    camera = evaluation_camera(Camera.from_look_at([0, 50, -15], [0, 0, 0], hfov_deg=40, width=960, height=540))
    poly = visible_pitch(camera, 960, 540, evaluator_precision=True)["Middle line"]
    single = poly[len(poly) // 2][None, :]
    clicks = clicks_for_class(camera, "Middle line", single, np.random.default_rng(0))
    assert len(clicks) == 2 and not np.array_equal(clicks[0], clicks[1])
    for x, y in clicks:
        d = evaluator.distance_to_polyline({"x": x, "y": y}, [{"x": single[0, 0], "y": single[0, 1]}])
        assert d < 0.5


def test_circle_runs_are_split_where_the_polyline_jumps():
    # Close to the centre circle: it leaves the frame at the bottom and on both sides, so the
    # evaluator's polyline is three runs joined together.
    camera = evaluation_camera(Camera.from_look_at([0, 20, -10], [0, 3, 0], hfov_deg=40, width=960, height=540))
    poly = visible_pitch(camera, 960, 540, evaluator_precision=True)["Circle central"]
    runs = split_runs(camera, "Circle central", poly)
    assert len(runs) == 3 and sum(len(r) for r in runs) == len(poly)
    for run in runs:  # inside a run, consecutive points are close on the image
        assert np.all(np.hypot(*np.diff(run, axis=0).T) < 60)


# ----------------------------------------------------------------------------- (c) markings visible
def test_rendered_frame_shows_the_markings_where_the_ground_truth_puts_them():
    model_ground = {n for n, s in MODEL.lines.items() if s.plane == "ground"} | set(MODEL.circles)
    for index in (0, 1):
        frame = make_frame(index, 31)
        rng = np.random.default_rng([31, index])  # replay the frame to get its layers
        camera, _ = sample_camera(rng, 960, 540)
        result = render(camera, rng)
        assert np.array_equal(result.image, frame["image"])
        mask = np.zeros((540, 960), np.uint8)
        for name, pts in visible_pitch(camera, 960, 540).items():
            if name in model_ground and len(pts) > 1:
                cv2.polylines(mask, [np.round(pts * 16).astype(np.int32)], False, 255, 1, cv2.LINE_8, 4)
        dist = cv2.distanceTransform(255 - mask, cv2.DIST_L2, 5)
        grey = cv2.cvtColor(result.image, cv2.COLOR_BGR2GRAY).astype(float)
        clear = (result.occluder < 0.05) & (result.surface == GROUND)
        near = clear & (dist <= 1)
        far = clear & (dist >= 5) & (dist <= 10)
        assert near.sum() > 200 and far.sum() > 200
        assert grey[near].mean() > grey[far].mean() + 12, (index, grey[near].mean(), grey[far].mean())


def _line_offsets(image: np.ndarray, occluder: np.ndarray, polylines: dict) -> tuple[np.ndarray, np.ndarray]:
    """Brightness centroids across the painted lines relative to the ground-truth polylines:
    (offsets along the normal (K,), normals (K, 2))."""
    ground = {n for n, s in MODEL.lines.items() if s.plane == "ground"} | set(MODEL.circles)
    grey = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY).astype(np.float32)
    h, w = grey.shape
    steps = np.arange(-5, 5.01, 0.5)
    offsets, normals = [], []
    for name, pts in polylines.items():
        if name not in ground:
            continue
        for a, b in zip(pts[:-1], pts[1:]):
            length = float(np.hypot(*(b - a)))
            if length < 1:
                continue
            t = (b - a) / length
            n = np.array([-t[1], t[0]])
            for s in np.arange(0.5, length, 3.0):
                c = a + s * t
                if not (8 < c[0] < w - 8 and 8 < c[1] < h - 8) or occluder[int(c[1]), int(c[0])] > 0.01:
                    continue
                p = (c[None] + steps[:, None] * n[None]).astype(np.float32)
                prof = cv2.remap(grey, p[None, :, 0], p[None, :, 1], cv2.INTER_LINEAR)[0]
                weight = np.clip(prof - np.median(np.r_[prof[:3], prof[-3:]]), 0, None)
                weight[np.abs(steps) > 3] = 0
                if weight.sum() > 20:
                    offsets.append(float((steps * weight).sum() / weight.sum()))
                    normals.append(n)
    return np.array(offsets), np.array(normals)


def test_painted_lines_are_centred_on_the_ground_truth_to_a_fraction_of_a_pixel():
    # Close views (thick lines), with and without lens distortion: the least-squares image shift
    # explaining the measured line centroids must be tiny (pixel-centre conventions agree).
    # (The cameras must be usable ones: with k1 < 0 the evaluator's lens model folds far
    # off-axis pitch points into the frame, where no renderer draws them.)
    for position, k1, seed in (([-20, 45, -14], 0.0, 1), ([-30, 70, -25], -0.05, 2), ([-20, 45, -14], 0.05, 3)):
        camera = Camera.from_look_at(position, [-40, 8, 0], hfov_deg=20, width=960, height=540, k1=k1)
        assert camera_problem(camera) is None
        result = render(camera, np.random.default_rng(seed))
        offsets, normals = _line_offsets(result.image, result.occluder, visible_pitch(camera, 960, 540))
        assert len(offsets) > 100
        shift, *_ = np.linalg.lstsq(normals, offsets, rcond=None)
        assert np.hypot(*shift) < 0.1, (k1, shift)
        assert np.median(np.abs(offsets)) < 0.4  # sensor noise spreads single profiles


def test_ray_grid_matches_pixel_rays():
    for k1 in (0.0, -0.04, 0.05):
        camera = Camera.from_look_at([5, 55, -18], [-20, 5, 0], hfov_deg=35, width=320, height=180, k1=k1)
        d = np.stack(ray_grid(camera), axis=-1).reshape(-1, 3).astype(float)
        uu, vv = np.meshgrid(np.arange(320.0), np.arange(180.0))
        ref = camera.pixel_rays(np.stack([uu.ravel(), vv.ravel()], axis=1))
        np.testing.assert_allclose(d / np.linalg.norm(d, axis=1, keepdims=True), ref, atol=2e-6)


# ----------------------------------------------------------------------------- (d) camera sampler
def test_camera_sampler_covers_all_kinds_and_every_camera_is_usable():
    rng = np.random.default_rng(123)
    kinds = Counter()
    for _ in range(200):
        camera, kind = sample_camera(rng, 960, 540)
        kinds[kind] += 1
        assert len(visible_pitch(camera, 960, 540)) >= 4
    assert set(kinds) == set(KINDS)
    assert 0.6 < kinds["main"] / 200 < 0.8
    for kind in KINDS:
        for _ in range(5):
            camera, got = sample_camera(rng, 960, 540, kind=kind)
            assert got == kind
            assert camera_problem(camera) is None
            assert len(visible_pitch(camera.scaled(960, 540), 960, 540)) >= 4
            assert not np.any(camera.radial[1:]) and not np.any(camera.tangential) and not np.any(camera.thin_prism)


# ----------------------------------------------------------------------------- (e) output folder
def test_output_folder_holds_only_images_annotations_and_cameras(small_run):
    top = sorted(p.name for p in small_run.iterdir())
    assert top == ["00000.jpg", "00000.json", "00001.jpg", "00001.json", "00002.jpg", "00002.json", "cameras"]
    assert sorted(p.name for p in (small_run / "cameras").iterdir()) == [
        "camera_00000.json", "camera_00001.json", "camera_00002.json"]
    for p in small_run.glob("*.json"):
        data = json.loads(p.read_text())
        assert all(re.fullmatch(r"[A-Za-z. ]+", k) for k in data)


def test_refuses_a_foreign_folder_unless_forced_but_extends_a_previous_output(small_run, tmp_path):
    foreign = tmp_path / "foreign"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("mine")
    with pytest.raises(OutputFolderError):
        generate(foreign, 1, seed=1, size=SMALL, progress=False)
    generate(foreign, 1, seed=1, size=SMALL, progress=False, force=True)
    assert (foreign / "notes.txt").read_text() == "mine" and (foreign / "00000.jpg").exists()
    # A previous synthetic output (with a stale temporary of a killed run) is fine.
    (small_run / ".00009.jpg.abcd.tmp").write_bytes(b"x")
    generate(small_run, 1, seed=5, size=SMALL, start_index=3, progress=False)
    assert not list(small_run.glob(".*"))
    (small_run / "00003.jpg").unlink()
    (small_run / "00003.json").unlink()
    (small_run / "cameras" / "camera_00003.json").unlink()


# ----------------------------------------------------------------------------- CLI
def _parser():
    parser = argparse.ArgumentParser(prog="pnlviz")
    add_synth_parser(parser.add_subparsers(dest="command"))
    return parser


def test_cli_parses_sizes_and_rejects_bad_ones(capsys):
    assert parse_size("960x540") == (960, 540)
    assert parse_size(" 1280X720 ") == (1280, 720)
    for bad in ("960", "960x", "x540", "960*540", "-960x540", "0x0", "960x540x3"):
        with pytest.raises(argparse.ArgumentTypeError):
            parse_size(bad)
    with pytest.raises(SystemExit):
        _parser().parse_args(["synth", "--out", "d", "-n", "2", "--size", "big"])
    assert "WIDTHxHEIGHT" in capsys.readouterr().err


def test_cli_runs_and_reports_speed(tmp_path, capsys):
    out = tmp_path / "cli"
    args = _parser().parse_args(["synth", "--out", str(out), "-n", "1", "--seed", "3", "--size", "320x180",
                                 "--no-progress"])
    assert args.func(args) == 0
    assert "frames/s" in capsys.readouterr().out
    assert (out / "00000.jpg").exists()
    (tmp_path / "cli2").mkdir()
    (tmp_path / "cli2" / "x.txt").write_text("")
    args = _parser().parse_args(["synth", "--out", str(tmp_path / "cli2"), "-n", "1", "--no-progress"])
    assert args.func(args) == 2
    assert "--force" in capsys.readouterr().err


def test_synthetic_clip_is_a_pan_tilt_zoom_video_with_cuts(tmp_path):
    """`pnlviz synth --clip`: one clip, frames named so that they group into it, every frame with
    its exact camera; within a shot one centre and one lens and a smooth motion, a cut moves the
    camera; the players run between frames."""
    import json

    from pnlviz.cli import main
    from pnlviz.data.layout import clips
    from pnlviz.geometry.camera import Camera
    from pnlviz.metrics.temporal import jitter
    from pnlviz.synth.clip import plan_clip

    out = tmp_path / "clip"
    assert main(["synth", "--clip", "-n", "45", "--seed", "4", "--size", "320x180", "--out", str(out),
                 "--no-progress"]) == 0
    stems = sorted(p.stem for p in out.glob("*.jpg"))
    assert len(stems) == 45 and list(clips(stems)) == ["clip4"]
    cams = [json.loads((out / "cameras" / f"camera_{s}.json").read_text()) for s in clips(stems)["clip4"]]
    shots = [c["synth"]["shot"] for c in cams]
    cut = shots.index(1)
    assert sorted(set(shots)) == [0, 1] and shots == sorted(shots) and 10 <= cut <= 35
    centres = np.array([c["position_meters"] for c in cams])
    assert np.allclose(centres[:cut], centres[0]) and np.allclose(centres[cut:], centres[cut])
    assert np.linalg.norm(centres[cut] - centres[0]) > 1.0
    k1 = [c["radial_distortion"][0] for c in cams]
    assert len(set(k1[:cut])) == 1
    cameras = [Camera.from_soccernet(c, 960, 540) for c in cams]
    j = jitter(cameras)
    assert np.nanmedian(j[1:cut - 1]) < 1.0  # smooth: the projected pitch barely accelerates
    plan = plan_clip(4, 45, (320, 180))
    assert np.median(np.linalg.norm(plan.feet[1] - plan.feet[0], axis=1)) > 0.02  # the players move
    # a frame renders alone, the same as in the clip
    from pnlviz.synth.clip import clip_frame

    again = clip_frame(plan, 7)
    assert again["stem"] == "clip4-IMG_0008" and again["camera"] == cams[7]


def test_a_previous_output_of_another_seed_or_size_is_refused_unless_forced(small_run, tmp_path):
    before = folder_bytes(small_run)
    with pytest.raises(OutputFolderError, match=r"holds synthetic frames of seed 5 at .*this run makes seed 6"):
        generate(small_run, 1, seed=6, size=SMALL, start_index=3, progress=False)
    with pytest.raises(OutputFolderError, match=r"this run makes seed 5 at 64x48"):
        generate(small_run, 1, seed=5, size=(64, 48), start_index=3, progress=False)
    assert folder_bytes(small_run) == before  # refused before anything was written
    generate(small_run, 1, seed=6, size=SMALL, start_index=3, progress=False, force=True)
    assert json.loads((small_run / "cameras" / "camera_00003.json").read_text())["synth"]["seed"] == 6
