"""The light default detector: LightNet's output contract, a short training run that learns, and
``pnlviz train`` (issue #5)."""

import json

import cv2
import numpy as np
import pytest

torch = pytest.importorskip("torch")

from pnlviz.detect.light import LightNet, load_light, read_sidecar  # noqa: E402
from pnlviz.detect.run import light_detector  # noqa: E402
from pnlviz.detect.train_data import View  # noqa: E402
from pnlviz.detect.train import FrameCache, train  # noqa: E402
from pnlviz.detect.train_config import TrainConfig, load_config  # noqa: E402
from pnlviz.detect.train_loss import focal_heatmap_loss, loss_fn, masked_mse, peak_pixels  # noqa: E402

SMOKE_SIZE = (160, 96)


@pytest.fixture(scope="module")
def tiny_cache():
    return FrameCache(8, seed=3, size=SMOKE_SIZE, progress=False)


def test_output_shapes_and_activations_odd_size():
    torch.manual_seed(0)
    net = LightNet().eval()
    x = torch.rand(2, 3, 101, 203)
    with torch.inference_mode():
        kp, lines = net(x)
    assert kp.shape == (2, 58, 51, 102) and lines.shape == (2, 24, 51, 102)
    assert torch.allclose(kp.sum(dim=1), torch.ones(2, 51, 102), atol=1e-5)
    assert float(kp.min()) >= 0.0 and float(lines.min()) >= 0.0 and float(lines.max()) <= 1.0
    # the two head views give the same heatmaps as the full forward, computed once per input
    kp_view, line_view = net.kp_head_module(), net.line_head_module()
    with torch.inference_mode():
        assert torch.equal(kp_view(x), kp) and torch.equal(line_view(x), lines)
        assert net._cache is None
        assert torch.equal(line_view(x), lines) and torch.equal(line_view(x), lines)  # same head twice


def test_even_size_matches_published_contract():
    net = LightNet().eval()
    with torch.inference_mode():
        kp, lines = net(torch.rand(1, 3, 96, 160))
    assert kp.shape[-2:] == (48, 80) and lines.shape[-2:] == (48, 80)


def test_masked_mse_ignores_masked_channels():
    pred = torch.zeros(1, 3, 4, 4)
    target = torch.zeros(1, 3, 4, 4)
    target[0, 1] = 5.0
    assert float(masked_mse(pred, target, torch.tensor([[1.0, 0.0, 1.0]]))) == 0.0
    assert float(masked_mse(pred, target, torch.tensor([[1.0, 1.0, 1.0]]))) == pytest.approx(25.0 / 3)


def _gaussian(h, w, cx, cy, sigma=2.0):
    ys, xs = torch.meshgrid(torch.arange(h, dtype=torch.float32), torch.arange(w, dtype=torch.float32),
                            indexing="ij")
    return torch.exp(-((xs - cx) ** 2 + (ys - cy) ** 2) / (2 * sigma ** 2))


def test_peak_pixels_one_per_gaussian_nearest_the_centre():
    t = torch.zeros(1, 2, 20, 30)
    t[0, 0] = _gaussian(20, 30, 7.3, 5.6)
    t[0, 1] = torch.maximum(_gaussian(20, 30, 3.0, 4.0), _gaussian(20, 30, 25.8, 14.2))  # a line: two ends
    pos = peak_pixels(t)
    assert torch.nonzero(pos[0, 0]).tolist() == [[6, 7]]
    assert torch.nonzero(pos[0, 1]).tolist() == [[4, 3], [14, 26]]
    assert not peak_pixels(t * 0.4).any()  # a Gaussian cut off by the border below the floor: no positive


def test_focal_loss_prefers_peaks_to_an_empty_map_unlike_the_mse():
    """The reason for the focal loss: with the MSE an empty map is nearly optimal (the first full
    training collapsed to it); the focal loss ranks the empty map far below the right peaks."""
    t = torch.zeros(1, 1, 40, 60)
    t[0, 0] = _gaussian(40, 60, 20.0, 15.0)
    mask, pos = torch.ones(1, 1), peak_pixels(t)

    def focal(p):
        p = p.clamp(1e-6, 1 - 1e-6)
        return float(focal_heatmap_loss(p, p.log(), (1 - p).log(), t, mask, pos))

    empty, peaked, wrong = torch.full_like(t, 0.01), t.clone(), torch.roll(t, 10, dims=3)
    assert focal(peaked) < 0.1 * focal(empty)  # 0.31 vs 4.5
    assert focal(wrong) > focal(empty)  # a peak in the wrong place is worse than none
    assert float(masked_mse(empty, t, mask)) < 0.01  # the MSE barely sees the difference
    # masked channels contribute nothing
    assert focal_heatmap_loss(t * 0 + 0.5, torch.full_like(t, np.log(0.5)), torch.full_like(t, np.log(0.5)), t,
                              torch.zeros(1, 1), pos) == 0


def test_loss_fn_kinds(tiny_cache):
    net = LightNet()
    x, kp, kpm, ln, lnm = (torch.from_numpy(np.stack(c)) for c in zip(*[tiny_cache.sample(0, SMOKE_SIZE)]))
    focal, mse = loss_fn(net, x, kp, kpm, ln, lnm), loss_fn(net, x, kp, kpm, ln, lnm, "mse")
    assert torch.isfinite(focal) and focal > 1.0 and 0 < mse < 0.1  # untrained: p ~ 0.01 everywhere
    with pytest.raises(ValueError, match="unknown loss"):
        loss_fn(net, x, kp, kpm, ln, lnm, "l1")


def test_targets_have_the_network_output_size(tiny_cache):
    x, kp, kp_mask, lines, line_mask = tiny_cache.sample(0, (101, 63))  # odd: padded to ceil
    assert x.shape == (3, 63, 101) and kp.shape == (58, 32, 51) and lines.shape == (24, 32, 51)
    assert kp_mask.shape == (58,) and line_mask.shape == (24,)
    # padded last row / column (the targets are H/2 floor): background only, no lines
    for border in (kp[:, -1, :], kp[:, :, -1]):
        assert np.all(border[-1] == 1.0) and np.all(border[:-1] == 0.0)
    assert np.all(lines[:, -1, :] == 0.0) and np.all(lines[:, :, -1] == 0.0)
    x2, kp2, *_ = tiny_cache.sample(0, SMOKE_SIZE)  # even: the label generator's targets as they are
    assert kp2.shape == (58, 48, 80) and kp2[:57].max() > 0.9


def test_training_smoke_loss_drops_and_detector_loads(tiny_cache, tmp_path):
    cfg = TrainConfig(frames=8, size=SMOKE_SIZE, input_size=SMOKE_SIZE, epochs=25, batch_size=4, lr=3e-3,
                      lr_final=1e-3, seed=1, threads=1)  # one thread: two spin-wait under load (12x slower)
    before = torch.get_num_threads()
    out = tmp_path / "light.pt"
    res = train(cfg, out, progress=False, log=None, cache=tiny_cache)  # 50 steps, no time bound: load-independent
    assert torch.get_num_threads() == before  # the process's own setting back
    assert len(res.history) >= 5
    first, last = res.history[0], res.history[-1]
    assert last < 0.5 * first, res.history
    side = read_sidecar(out)
    assert side["model"] == "LightNet" and side["input_size"] == list(SMOKE_SIZE)
    assert side["final_loss"] == pytest.approx(last) and side["frames"] == 8 and side["seed"] == 1
    assert side["config"]["data"]["size"] == list(SMOKE_SIZE) and "date" in side
    # a plain state dict, loaded strictly, run through the Detector (both heads, one network)
    assert all(isinstance(v, torch.Tensor) for v in torch.load(out, weights_only=True).values())
    det = light_detector(out, kp_threshold=0.0)
    assert det.input_size == SMOKE_SIZE
    assert det.refine == side["peak_refine"] == cfg.peak_refine and det.centre_aligned_resize
    assert light_detector(out, refine="raw").refine == "raw"
    preds = det.detect([tiny_cache.images[0], tiny_cache.images[1]])
    assert len(preds) == 2 and len(preds[0].keypoints) > 0
    with torch.inference_mode():
        ref_kp, ref_lines = load_light(out)(torch.from_numpy(
            np.ascontiguousarray(tiny_cache.images[0][:, :, ::-1].transpose(2, 0, 1), dtype=np.float32)[None] / 255))
    kp, lines = det.heatmaps([tiny_cache.images[0]])
    assert np.allclose(kp[0], ref_kp[0].numpy(), atol=1e-5) and np.allclose(lines[0], ref_lines[0].numpy(), atol=1e-5)


def test_default_config_reads():
    cfg = load_config()
    assert cfg.frames > 0 and cfg.epochs > 0 and cfg.batch_size > 0 and cfg.lr > 0
    assert cfg.input_size == cfg.size and cfg.input_size[0] % 16 == 0 and cfg.input_size[1] % 16 == 0
    assert TrainConfig.from_dict(cfg.to_dict()) == cfg


def test_train_cli_smoke(tmp_path, capsys):
    import argparse

    from pnlviz.commands.train import add_train_parser

    from pnlviz.detect.train_config import DEFAULT_CONFIG_PATH

    cfg = load_config(DEFAULT_CONFIG_PATH.with_name("light_synth_config.json")).to_dict()  # stage 1: synthetic only
    cfg["data"]["size"] = list(SMOKE_SIZE)
    cfg["input_size"] = list(SMOKE_SIZE)
    config = tmp_path / "config.json"
    config.write_text(json.dumps(cfg))
    out = tmp_path / "m" / "light.pt"
    argv = ["train", "--config", str(config), "--out", str(out), "--frames", "4", "--epochs", "1",
            "--batch-size", "2", "--no-progress"]
    from pnlviz import cli

    parser = argparse.ArgumentParser()
    add_train_parser(parser.add_subparsers(dest="command"))
    args = parser.parse_args(argv)
    assert args.func(args) == 0
    assert out.is_file() and (tmp_path / "m" / "light.json").is_file()
    side = read_sidecar(out)
    assert side["frames"] == 4 and side["epochs"] == 1 and side["steps"] == 2
    assert "trained 1.00 epochs" in capsys.readouterr().out
    load_light(out)
    # the same through the top-level command line
    assert cli.main(argv[:4] + [str(tmp_path / "m2.pt")] + argv[5:]) == 0 and (tmp_path / "m2.pt").is_file()


def test_train_cli_rejects_bad_overrides(tmp_path, capsys):
    import argparse

    from pnlviz.commands.train import add_train_parser

    parser = argparse.ArgumentParser()
    add_train_parser(parser.add_subparsers(dest="command"))
    args = parser.parse_args(["train", "--out", str(tmp_path / "x.pt"), "--frames", "0"])
    assert args.func(args) == 2 and "--frames" in capsys.readouterr().err
    args = parser.parse_args(["train", "--config", str(tmp_path / "missing.json"), "--out", str(tmp_path / "x.pt")])
    assert args.func(args) == 2 and "cannot read training config" in capsys.readouterr().err


def test_training_is_deterministic_and_cache_folder_round_trips(tmp_path):
    first = FrameCache(3, seed=4, size=SMOKE_SIZE, cache_dir=tmp_path / "cache", progress=False)
    again = FrameCache(3, seed=4, size=SMOKE_SIZE, cache_dir=tmp_path / "cache", progress=False)  # read back
    assert len(list((tmp_path / "cache").rglob("*.npz"))) == 3
    for a, b, ann_a, ann_b in zip(first.images, again.images, first.annotations, again.annotations):
        assert np.array_equal(a, b) and ann_a.keys() == ann_b.keys()
        assert all(np.array_equal(ann_a[k], ann_b[k]) for k in ann_a)
    # One thread: the bits are only guaranteed where no reduction is split between threads. With two,
    # a CI run once gave the same loss history and different final weights (the last backward's sums
    # added in another order).
    cfg = TrainConfig(frames=3, size=SMOKE_SIZE, input_size=SMOKE_SIZE, epochs=2, batch_size=2, seed=7, threads=1)
    ra = train(cfg, tmp_path / "a.pt", progress=False, log=None, cache=first)
    rb = train(cfg, tmp_path / "b.pt", progress=False, log=None, cache=again)
    assert ra.history == rb.history
    sa, sb = torch.load(tmp_path / "a.pt", weights_only=True), torch.load(tmp_path / "b.pt", weights_only=True)
    assert all(torch.equal(sa[k], sb[k]) for k in sa)


def test_shipped_default_model_on_unseen_synthetic_frames():
    """assets/models/light.pt (what `pnlviz detect` and the app use without weights) on frames of a
    data seed it was not trained on (training: seed 5): keypoints land within 5 px of the truth and
    the cameras calibrated from its detections pass the official metric. The full figures (60
    frames) come from benchmarks/eval_light.py; this checks that the shipped file still works."""
    from pnlviz.calib.calibrate import CalibParams, calibrate
    from pnlviz.calib.inputs import observations_from_predictions
    from pnlviz.detect.run import DEFAULT_MODEL, Detector
    from pnlviz.detect.train import _annotation_arrays
    from pnlviz.labels import keypoints_from_annotation
    from pnlviz.metrics.soccernet import evaluate_frame
    from pnlviz.synth import make_frame

    assert DEFAULT_MODEL.is_file() and read_sidecar(DEFAULT_MODEL)["config"]["data"]["seed"] != 777
    det = Detector.from_weights(None, None)
    assert det.input_size == (480, 272) and det.kp_threshold == 0.3 and det.line_threshold == 0.4
    assert det.refine == "raw" and det.centre_aligned_resize
    hits = total = 0
    accuracies = []
    for i in range(6):
        f = make_frame(i, 777, (960, 540))
        pred = det.detect([f["image"]])[0]
        ann = _annotation_arrays(f["annotation"])
        truth = {k: (lab.x, lab.y) for k, lab in keypoints_from_annotation(ann, 960, 540).keypoints.items()
                 if k <= 57 and lab.visible}
        found = pred.keypoints_px(960, 540)
        total += len(truth)
        hits += sum(k in found and np.hypot(found[k][0] - x, found[k][1] - y) <= 5 for k, (x, y) in truth.items())
        res = calibrate(observations_from_predictions(pred, 960, 540), CalibParams().updated(det.calibration))
        accuracies.append(evaluate_frame(res.camera, ann, (5,)).accuracy(5) if res.ok else 0.0)
    assert total > 50 and hits / total >= 0.4, (hits, total)
    assert np.mean(accuracies) >= 0.5 and sum(a > 0 for a in accuracies) >= 5, accuracies  # measured 0.71, 6 of 6


def test_flipped_sample_mirrors_image_and_targets(tiny_cache):
    """A flipped training sample is the mirrored image with targets whose peaks sit at the
    mirrored places under the reflected ids (e.g. 'left' side-line ends become 'right')."""
    from pnlviz.field.names import CLASS_TO_LINE_ID, FLIP_X, LINE_ID_TO_CLASS

    x, kp, kpm, ln, lnm = tiny_cache.sample(1, SMOKE_SIZE)
    xf, kpf, kpmf, lnf, lnmf = tiny_cache.sample(1, SMOKE_SIZE, view=View(flip=True))
    assert np.array_equal(xf, x[:, :, ::-1])
    w = kp.shape[2]
    line_map = {i - 1: CLASS_TO_LINE_ID[FLIP_X[c]] - 1 for i, c in LINE_ID_TO_CLASS.items()}
    peaks = 0
    for c in range(23):
        if ln[c].max() < 0.9:
            continue
        mirrored = ln[c][:, ::-1]
        g = lnf[line_map[c]]
        # the extremity Gaussians land on the mirrored pixels (within the half-resolution rounding)
        ys, xs = np.nonzero(mirrored >= 0.9)
        assert all(g[max(0, y - 1):y + 2, max(0, x - 1):x + 2].max() >= 0.6 for y, x in zip(ys, xs))
        peaks += 1
    assert peaks >= 1 and kpmf.sum() == kpm.sum() and w == kpf.shape[2]


def test_detections_map_back_through_cv2_resize_exactly():
    """A blob drawn at a sub-pixel frame position, resized like the Detector does (cv2.resize,
    pixel centres aligned), found on the input grid and mapped back by
    undo_centre_aligned_resize lands where it was drawn; PnLCalib's plain x / s misses by
    (1/s - 1) / 2 px (0.5 px at 960 -> 480)."""
    from pnlviz.data.predictions import Predictions
    from pnlviz.detect.run import undo_centre_aligned_resize

    Wf, Hf, Wi, Hi = 960, 540, 480, 272
    yy, xx = np.mgrid[0:Hf, 0:Wf].astype(np.float64)
    for X, Y in ((123.3, 77.8), (700.6, 401.2), (480.0, 270.0)):
        frame = np.exp(-((xx - X) ** 2 + (yy - Y) ** 2) / (2 * 3.0 ** 2))
        small = cv2.resize(frame, (Wi, Hi), interpolation=cv2.INTER_AREA)
        w = small * (small > 1e-3)
        ys, xs = np.mgrid[0:Hi, 0:Wi]
        cx, cy = (w * xs).sum() / w.sum(), (w * ys).sum() / w.sum()  # centroid on the input grid
        pred = Predictions(keypoints={1: (cx / Wi, cy / Hi, 1.0)}, lines={2: (cx / Wi, cy / Hi, 1.0, 0.5, 0.5, 1.0)})
        back = undo_centre_aligned_resize(pred, (Wi, Hi), (Wf, Hf))
        x, y, _ = back.keypoints_px(Wf, Hf)[1]
        assert (x, y) == pytest.approx((X, Y), abs=0.02)
        assert back.lines_px(Wf, Hf)[2][:2] == pytest.approx((X, Y), abs=0.02)
        assert abs(cx / Wi * Wf - X) > 0.4  # the plain scaling is off by ~0.5 px
    assert undo_centre_aligned_resize(pred, (Wi, Hi), (Wi, Hi)) is pred
