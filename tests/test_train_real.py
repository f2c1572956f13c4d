"""Training on real frames (issue #13): labels from ground-truth homographies, the masked non-planar
channels, the label-exact augmentations, the mixed-source loader, ``--init`` and the guard on the
shipped model."""

import json
import zipfile

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from pnlviz.detect.train import FrameCache, Source, build_sources, epoch_plan, train  # noqa: E402
from pnlviz.detect.train_config import TrainConfig  # noqa: E402
from pnlviz.detect.train_data import (AnnotatedFrames, ExportedFrames, HomographyFrames, View,  # noqa: E402
                                      clip_annotation, draw_view)
from pnlviz.labels import LabelParams, keypoints_from_annotation, training_targets  # noqa: E402
from pnlviz.labels.from_homography import (NON_PLANAR_KEYPOINT_IDS, NON_PLANAR_LINE_IDS,  # noqa: E402
                                           annotation_from_homography, homography_for_size, labels_from_homography)

SMALL = (160, 96)


def _peaks(kp: np.ndarray) -> dict[int, tuple[int, int]]:
    """Keypoint id -> (x, y) output pixel of its target's peak, for channels with one."""
    out = {}
    for c in range(kp.shape[0] - 1):
        if kp[c].max() > 0.5:
            y, x = np.unravel_index(int(kp[c].argmax()), kp[c].shape)
            out[c + 1] = (int(x), int(y))
    return out


def test_homography_labels_agree_with_the_annotation_labels(shared_dir):
    """The 93 WC14 test frames have both a ground-truth homography and a SoccerNet line
    annotation, made independently. The keypoints projected through the homography and those the
    label generator finds in the annotation agree (same ids, same left-right decision) to a few
    pixels at 960x540: measured median 3.9 px, 90th percentile 8.6 px."""
    from pnlviz.data import read_homographies

    data = shared_dir / "data" / "wc14_test_half"
    gt = read_homographies(data / "homographies.json")
    W, H = 960, 540
    gaps, wrong_gaps, same_side, frames = [], [], 0, 0
    with zipfile.ZipFile(data / "annotations.zip") as z:
        for stem, Ht in gt.items():
            ann = {k: np.array([[p["x"], p["y"]] for p in v]) for k, v in json.loads(z.read(f"{stem}.json")).items()}
            lab = keypoints_from_annotation(ann, W, H, LabelParams(lr_disambiguation=True))
            hl = labels_from_homography(homography_for_size(Ht, (W, H)), W, H)
            # the wrong convention: the homography of the 1280x720 frame used at 960x540
            wrong = labels_from_homography(homography_for_size(Ht, (1280, 720)), W, H).labels.keypoints
            wrong_gaps += [np.hypot(a.x - wrong[k].x, a.y - wrong[k].y) for k, a in lab.keypoints.items()
                           if a.visible and k in wrong]
            frames += 1
            same_side += lab.mirrored == hl.labels.mirrored
            for k, a in lab.keypoints.items():
                if a.visible and k in hl.labels.keypoints:
                    b = hl.labels.keypoints[k]
                    gaps.append(np.hypot(a.x - b.x, a.y - b.y))
    gaps = np.array(gaps)
    print(f"homography vs annotation labels: {len(gaps)} keypoints, median {np.median(gaps):.2f} px, "
          f"p90 {np.percentile(gaps, 90):.2f} px")
    assert frames == 93 and same_side == 93
    assert len(gaps) > 1000
    assert np.median(gaps) < 5.0 and np.percentile(gaps, 90) < 12.0
    assert np.median(wrong_gaps) > 4 * np.median(gaps)


def test_annotation_from_a_homography_reproduces_the_projected_labels():
    """A synthetic frame's exact camera gives a ground homography; the annotation written from it,
    run through the label generator, finds the projected ground keypoints again (sub-pixel)."""
    from pnlviz.synth import make_frame

    f = make_frame(2, 11, (960, 540))
    ann_truth = {k: np.array([[p["x"], p["y"]] for p in v]) for k, v in f["annotation"].items()}
    lab_truth = keypoints_from_annotation(ann_truth, 960, 540)
    Hf = lab_truth.homography
    assert Hf is not None
    ann = annotation_from_homography(Hf, 960, 540)
    arrays = {k: np.array([[p["x"], p["y"]] for p in v]) for k, v in ann.items()}
    lab = keypoints_from_annotation(arrays, 960, 540)
    hl = labels_from_homography(Hf, 960, 540, lr_disambiguation=False)
    common = [k for k, v in lab.keypoints.items() if v.visible and v.set == "Kp" and k in hl.labels.keypoints]
    assert len(common) >= 4
    for k in common:
        assert np.hypot(lab.keypoints[k].x - hl.labels.keypoints[k].x, lab.keypoints[k].y - hl.labels.keypoints[k].y) < 0.5


def test_non_planar_channels_are_masked_and_never_positive(shared_dir):
    """Goal-frame corners (z = -2.44 m) and the post / crossbar lines are unknown from a ground
    homography: masked out of the loss, and no target peak is drawn for them."""
    hf = HomographyFrames(shared_dir / "data" / "wc14_real" / "trainval_300", stems=["16"])
    x, kp, kpm, ln, lnm = hf.sample(0, SMALL, 2.0)
    assert set(NON_PLANAR_KEYPOINT_IDS) == {12, 15, 16, 19} and set(NON_PLANAR_LINE_IDS) == set(range(7, 13))
    assert all(kpm[k - 1] == 0 for k in NON_PLANAR_KEYPOINT_IDS) and kpm.sum() == 58 - 4
    assert all(lnm[i - 1] == 0 for i in NON_PLANAR_LINE_IDS) and lnm[23] == 0 and lnm.sum() == 24 - 7
    assert all(kp[k - 1].max() == 0 for k in NON_PLANAR_KEYPOINT_IDS)
    assert all(ln[i - 1].max() == 0 for i in NON_PLANAR_LINE_IDS)
    # the frame shows a goal: ground keypoints and ground lines are there
    assert len(_peaks(kp)) >= 8 and sum(ln[i].max() > 0.9 for i in range(23)) >= 4
    # the annotation path (posts and crossbars annotated) keeps those channels
    _, _, t = training_targets({}, *SMALL)
    assert all(t.keypoint_mask[k - 1] == 1 for k in NON_PLANAR_KEYPOINT_IDS) and t.line_mask.sum() == 24


def test_views_keep_homography_labels_exact(shared_dir):
    """A flip, a 1.5x zoom, blur and JPEG move the targets exactly as the image: each keypoint's
    peak after the view is where the view's affine map sends its peak before (to the output grid's
    rounding), under the reflected id for a flip."""
    hf = HomographyFrames(shared_dir / "data" / "wc14_real" / "trainval_300", stems=["16"])
    W, Hh = 480, 272
    Hf = hf.field_homography(0, (W, Hh))
    base = labels_from_homography(Hf, W, Hh).labels.keypoints
    view = View(crop=(60.0, 40.0, 1.5), down=(0.5, 0.9), jpeg=40)
    A = view.affine(W, Hh)
    _, kp, *_ = hf.sample(0, (W, Hh), 2.0, view)
    peaks = _peaks(kp)
    moved = {}
    for k, v in base.items():
        p = A @ np.array([v.x, v.y, 1.0])
        if 0 <= p[0] <= W - 1 and 0 <= p[1] <= Hh - 1:
            moved[k] = p[:2]
    assert len(moved) >= 4 and set(moved) == set(peaks)
    for k, p in moved.items():
        assert np.hypot(peaks[k][0] * 2 - p[0], peaks[k][1] * 2 - p[1]) <= 1.5
    # a flip: the same ground points at mirrored x (under the ids of the reflected pitch)
    _, kpf, *_ = hf.sample(0, (W, Hh), 2.0, View(flip=True))
    pf = _peaks(kpf)
    assert len(pf) == len(base) and set(pf) != set(base)
    ours = sorted((2 * x, 2 * y) for x, y in pf.values())
    truth = sorted((W - 1 - v.x, v.y) for v in base.values())
    assert all(np.hypot(a[0] - b[0], a[1] - b[1]) <= 1.5 for a, b in zip(ours, truth))


def test_zoomed_synthetic_annotation_keeps_labels_exact():
    """An annotation mapped through a zoom and clipped to the window gives the keypoints of the
    original mapped by the zoom (the label generator on the clipped lines)."""
    cache = FrameCache(1, seed=21, size=(480, 272), progress=False)
    ann = cache.annotations[0]
    W, H = 480, 272
    view = View(crop=(80.0, 50.0, 1.4))
    A = view.affine(W, H)
    before = keypoints_from_annotation(ann, W, H)
    after = keypoints_from_annotation(clip_annotation(ann, A, W, H), W, H)
    checked = 0
    for k, v in before.keypoints.items():
        if v.set != "Kp":
            continue
        p = A @ np.array([v.x, v.y, 1.0])
        if 2 <= p[0] <= W - 3 and 2 <= p[1] <= H - 3 and k in after.keypoints:
            assert np.hypot(after.keypoints[k].x - p[0], after.keypoints[k].y - p[1]) < 0.5
            checked += 1
    assert checked >= 3


def test_draw_view_without_new_keys_draws_only_flips():
    rng_a, rng_b = np.random.default_rng(3), np.random.default_rng(3)
    views = [draw_view({"flip": 0.5, "brightness": 0.3}, rng_a, SMALL) for _ in range(20)]
    assert all(v.crop is None and v.down is None and v.jpeg is None for v in views)
    assert [v.flip for v in views] == list(rng_b.random(20) < 0.5)  # the stream of the flip-only recipe
    rich = [draw_view({"zoom": 1.6, "zoom_p": 1.0, "downscale": 0.5, "downscale_p": 1.0, "jpeg": 30, "jpeg_p": 1.0},
                      np.random.default_rng(4), SMALL) for _ in range(20)]
    assert all(1.0 <= v.crop[2] <= 1.6 and 0.5 <= v.down[0] <= 1.0 and 30 <= v.jpeg <= 95 for v in rich)


class _Frames:
    def __init__(self, n, tag):
        self.n, self.tag = n, tag

    def __len__(self):
        return self.n


def test_epoch_plan_mixes_sources_by_weight():
    rng = np.random.default_rng(0)
    sources = [Source("a", _Frames(100, "a"), 0.25, {}), Source("b", _Frames(10, "b"), 0.75, {})]
    plan = epoch_plan(sources, rng, 400)
    counts = np.bincount([k for k, _ in plan], minlength=2)
    assert counts.tolist() == [100, 300]
    b = [i for k, i in plan if k == 1]
    assert sorted(set(b)) == list(range(10)) and max(np.bincount(b)) - min(np.bincount(b)) <= 1  # cycled evenly
    a = [i for k, i in plan if k == 0]
    assert sorted(a) == list(range(100))
    assert [k for k, _ in plan[:20]] != sorted(k for k, _ in plan[:20])  # shuffled, not in blocks
    one = epoch_plan(sources[:1], np.random.default_rng(5))
    assert [i for _, i in one] == np.random.default_rng(5).permutation(100).tolist()


def test_mixed_sources_train_together(tmp_path, shared_dir):
    """A synthetic source, a homography folder and a SoccerNet folder in one config: every source
    is loaded, a short run trains on all three (the sidecar lists them)."""
    from pnlviz.synth import generate

    sn = tmp_path / "sn"
    generate(sn, 3, 31, size=SMALL, progress=False)
    cfg = TrainConfig(frames=4, size=SMALL, input_size=SMALL, epochs=1, batch_size=4, seed=1, epoch_frames=12,
                      real=[{"kind": "homography", "path": str(shared_dir / "data" / "wc14_real" / "trainval_300"),
                             "weight": 1.0, "augment": {"zoom": 1.5, "zoom_p": 1.0}},
                            {"kind": "soccernet", "path": str(sn), "weight": 1.0}])
    sources = build_sources(cfg, progress=False)
    assert [len(s) for s in sources] == [4, 209, 3]
    assert isinstance(sources[1].frames, HomographyFrames) and isinstance(sources[2].frames, AnnotatedFrames)
    assert sources[1].augment["zoom"] == 1.5 and "zoom" not in sources[0].augment
    res = train(cfg, tmp_path / "m.pt", progress=False, log=None)
    side = json.loads((tmp_path / "m.json").read_text())
    assert res.steps == 3 and [s["frames"] for s in side["sources"]] == [4, 209, 3]
    with pytest.raises(ValueError, match="unknown kind"):
        build_sources(TrainConfig(frames=0, real=[{"kind": "video", "path": "x"}]), progress=False)
    with pytest.raises(ValueError, match="no training frames"):
        build_sources(TrainConfig(frames=0), progress=False)


def test_init_starts_from_the_given_weights(tmp_path):
    """With --init and a zero learning rate, the trained parameters are exactly the given ones
    (a random start would differ); the sidecar records the init file and its hash."""
    from pnlviz.detect.checkpoint import save_checkpoint
    from pnlviz.detect.light import LightNet

    torch.manual_seed(123)
    start = LightNet()
    save_checkpoint(start, tmp_path / "start.pt")
    cfg = TrainConfig(frames=2, size=SMALL, input_size=SMALL, epochs=1, batch_size=2, lr=0.0, lr_final=0.0, seed=9)
    cache = FrameCache(2, seed=3, size=SMALL, progress=False)
    train(cfg, tmp_path / "a.pt", progress=False, log=None, cache=cache, init=tmp_path / "start.pt")
    train(cfg, tmp_path / "b.pt", progress=False, log=None, cache=cache)
    a = torch.load(tmp_path / "a.pt", weights_only=True)
    b = torch.load(tmp_path / "b.pt", weights_only=True)
    params = dict(start.named_parameters())
    assert all(torch.equal(a[k], params[k].detach()) for k in params)
    assert not all(torch.equal(b[k], params[k].detach()) for k in params)
    side = json.loads((tmp_path / "a.json").read_text())
    assert side["init"]["path"].endswith("start.pt") and len(side["init"]["sha256"]) == 64
    assert json.loads((tmp_path / "b.json").read_text())["init"] is None


def test_train_cli_refuses_to_overwrite_the_shipped_model(tmp_path, capsys):
    import argparse

    from pnlviz.commands.train import add_train_parser
    from pnlviz.detect.default import DEFAULT_MODEL

    parser = argparse.ArgumentParser()
    add_train_parser(parser.add_subparsers(dest="command"))
    before = DEFAULT_MODEL.stat().st_mtime_ns
    args = parser.parse_args(["train", "--out", str(DEFAULT_MODEL), "--frames", "1", "--epochs", "1"])
    assert args.func(args) == 2 and "--replace-default" in capsys.readouterr().err
    assert DEFAULT_MODEL.stat().st_mtime_ns == before
    args = parser.parse_args(["train"])
    assert args.out.name == "light.pt" and not args.out.is_absolute()  # ./light.pt, not the shipped file
    args = parser.parse_args(["train", "--init", str(tmp_path / "none.pt"), "--out", str(tmp_path / "x.pt")])
    assert args.func(args) == 2 and "no such file" in capsys.readouterr().err
    args = parser.parse_args(["train", "--data", str(tmp_path / "nowhere"), "--out", str(tmp_path / "x.pt")])
    assert args.func(args) == 2 and "no such folder" in capsys.readouterr().err


def test_exported_labels_train_as_corrected(tmp_path):
    """The loop "correct in the app -> export -> fine-tune": `pnlviz export` of a dataset, read back
    with the dataset's images, gives the label generator's keypoints as targets; a keypoint moved
    in the export (as a drag in the app would) moves its target peak by the same amount."""
    from pnlviz.cli import main as cli
    from pnlviz.synth import generate

    W, H = 320, 180
    data = tmp_path / "frames"
    generate(data, 2, 41, size=(W, H), progress=False)
    out = tmp_path / "export"
    assert cli(["export", "--data", str(data), "--out", str(out), "--all"]) == 0
    frames = ExportedFrames(out, data)
    assert frames.stems == sorted(frames.stems) and len(frames) == 2
    _, kp, kpm, ln, _ = frames.sample(0, (W, H), 2.0)
    ann = frames.dataset.annotation(frames.stems[0])
    _, ref_kp, _, ref_ln, _ = AnnotatedFrames(data).sample(0, (W, H), 2.0)
    ours, ref = _peaks(kp), _peaks(ref_kp)
    common = [k for k in ref if k in ours]
    assert len(common) >= 0.8 * len(ref) and len(ref) >= 4
    assert all(abs(ours[k][0] - ref[k][0]) <= 1 and abs(ours[k][1] - ref[k][1]) <= 1 for k in common)
    assert np.array_equal(ln[:23] > 0.9, ref_ln[:23] > 0.9) and ann
    # move one keypoint by (+12, -8) px in the exported file
    path = out / "keypoints" / f"{frames.stems[0]}.json"
    doc = json.loads(path.read_text())
    k = common[0]
    doc["keypoints"][str(k)]["x"] += 12.0
    doc["keypoints"][str(k)]["y"] -= 8.0
    path.write_text(json.dumps(doc))
    _, kp2, *_ = ExportedFrames(out, data).sample(0, (W, H), 2.0)
    moved = _peaks(kp2)
    assert abs(moved[k][0] - ours[k][0] - 6) <= 1 and abs(moved[k][1] - ours[k][1] + 4) <= 1
    assert all(moved[j] == ours[j] for j in ours if j != k)


def test_the_shipped_recipe_names_what_it_was_trained_from(shared_dir):
    """assets/models/light_config.json (stage 2) starts from the shipped stage-1 model, trains on the
    WC14 train/val frames less the 30 held out (never a test frame), and the shipped sidecar
    records exactly that start (same file hash) and those sources."""
    import hashlib

    from pnlviz.detect.default import DEFAULT_MODEL
    from pnlviz.detect.light import read_sidecar
    from pnlviz.detect.train_config import DEFAULT_CONFIG_PATH, load_config, resolve_path

    cfg = load_config(DEFAULT_CONFIG_PATH)
    init = resolve_path(cfg.init, cfg.base_dir)
    side = read_sidecar(DEFAULT_MODEL)
    assert init.is_file() and side["init"]["sha256"] == hashlib.sha256(init.read_bytes()).hexdigest()
    real = cfg.real[0]
    folder = resolve_path(real["path"], cfg.base_dir)
    assert folder.resolve() == (shared_dir / "data" / "wc14_real" / "trainval_300").resolve()
    held_out = set(real["exclude"])
    assert len(held_out) == 30
    frames = HomographyFrames(folder, exclude=real["exclude"])
    assert len(frames) == 179 and not held_out & set(frames.stems)
    assert [s["frames"] for s in side["sources"]] == [cfg.frames, 179]


def test_train_cli_fine_tunes_on_exported_labels(tmp_path, capsys):
    """`pnlviz train --init W --data DIR --labels EXPORT`: the exported labels of DIR's frames
    replace the config's real sources, training starts from W, and the sidecar says so."""
    from pnlviz.cli import main
    from pnlviz.detect.checkpoint import save_checkpoint
    from pnlviz.detect.light import LightNet
    from pnlviz.synth import generate

    data = tmp_path / "frames"
    generate(data, 2, 43, size=SMALL, progress=False)
    export = tmp_path / "corrected.zip"
    assert main(["export", "--data", str(data), "--out", str(export), "--all"]) == 0
    save_checkpoint(LightNet(), tmp_path / "start.pt")
    config = tmp_path / "config.json"
    config.write_text(json.dumps({"data": {"seed": 1, "frames": 2, "size": list(SMALL)}, "input_size": list(SMALL),
                                  "epochs": 1, "batch_size": 2, "epoch_frames": 4, "threads": 1,
                                  "real": [{"kind": "homography", "path": "nowhere", "weight": 3.0}]}))
    out = tmp_path / "mine.pt"
    capsys.readouterr()
    assert main(["train", "--config", str(config), "--init", str(tmp_path / "start.pt"), "--data", str(data),
                 "--labels", str(export), "--out", str(out), "--no-progress"]) == 0
    side = json.loads(out.with_suffix(".json").read_text())
    assert [s["frames"] for s in side["sources"]] == [2, 2] and side["sources"][1]["name"].startswith("labels")
    assert side["sources"][1]["weight"] == 3.0 and side["init"]["path"].endswith("start.pt")
    assert side["steps"] == 2
    assert main(["train", "--config", str(config), "--labels", str(export), "--out", str(out)]) == 2
    assert "--labels needs --data" in capsys.readouterr().err


def test_worn_paint_hides_stretches_of_lines_and_keeps_the_targets():
    """`wear`: grass painted over stretches of the annotated lines; the targets are those of the
    unworn frame (the geometry is where it was), and only pixels on the lines change."""
    import cv2

    from pnlviz.detect.train_data import annotation_example

    cache = FrameCache(1, seed=5, size=(480, 272), progress=False)
    plain = annotation_example(cache.images[0], cache.annotations[0], (480, 272), 2.0, View())
    worn = annotation_example(cache.images[0], cache.annotations[0], (480, 272), 2.0, View(wear=3))
    assert all(np.array_equal(a, b) for a, b in zip(plain[1:], worn[1:]))
    changed = np.abs(plain[0] - worn[0]).sum(axis=0) > 0.1
    assert changed.sum() > 100
    near = np.zeros((272, 480), np.uint8)
    for pts in cache.annotations[0].values():
        px = np.round(np.asarray(pts) * [479, 271]).astype(np.int32)
        cv2.polylines(near, [px.reshape(-1, 1, 2)], False, 1, 9)
    assert changed[near == 0].sum() <= 0.02 * changed.sum()
    views = [draw_view({"wear": 1.0}, np.random.default_rng(k), SMALL) for k in range(5)]
    assert all(v.wear is not None for v in views)
