"""Heatmap peaks -> keypoints / line extremities -> Predictions (``pnlviz.detect.peaks``).

Accuracy achieved (log-space Newton step, float32 heatmaps): Gaussians of sigma 1-4, isotropic or
anisotropic and rotated, anywhere in the grid including the last half pixel, are recovered to
about 1e-6 heatmap px (asserted: 1e-3); the raw-value parabola is biased by up to ~0.03 px at
sigma 2. The SN22 round trip (labels -> heatmap_targets -> extract -> image) is within ~3e-5
image px (asserted: 0.5 px as required, and 1e-3).
"""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from pnlviz.data.predictions import Predictions, read_predictions, write_predictions
from pnlviz.detect.peaks import (
    detections_to_predictions, extract_keypoints, extract_lines, extract_predictions, find_peaks, heatmap_to_image,
    image_to_heatmap, nms_mask, refine_peaks,
)
from helpers import needs_shared  # noqa: E402

SN22 = Path(__file__).resolve().parents[2] / "shared" / "data" / "sn22_test_subset" / "annotations.zip"
H, W = 36, 52  # a small heatmap grid for the synthetic tests


def gaussian(cx, cy, sigma=2.0, h=H, w=W, sx=None, sy=None, angle=0.0):
    """float32 (h, w): exp(-d^2 / 2) for the (possibly anisotropic, rotated) Gaussian at (cx, cy)."""
    sx = sigma if sx is None else sx
    sy = sigma if sy is None else sy
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    dx, dy = xs - cx, ys - cy
    c, s = math.cos(angle), math.sin(angle)
    u, v = c * dx + s * dy, -s * dx + c * dy
    return np.exp(-0.5 * ((u / sx) ** 2 + (v / sy) ** 2)).astype(np.float32)


def kp_heatmaps(peaks, h=H, w=W):
    """(58, h, w) like the keypoint network: ``peaks = {id: (h, w) channel}``, background 1 - max."""
    a = np.zeros((58, h, w), np.float32)
    for kid, ch in peaks.items():
        a[kid - 1] = ch
    a[57] = 1.0 - a[:57].max(axis=0)
    return a


def line_heatmaps(peaks, h=H, w=W):
    a = np.zeros((24, h, w), np.float32)
    for lid, ch in peaks.items():
        a[lid - 1] = ch
    a[23] = a[:23].max(axis=0)  # something in the boundary channel, to be ignored
    return a


# ------------------------------------------------------------------------------ sub-pixel accuracy
@settings(max_examples=60, deadline=None)
@given(cx=st.floats(0.0, W - 0.5), cy=st.floats(0.0, H - 0.5), kid=st.integers(1, 57))
def test_keypoint_subpixel_sigma2_anywhere(cx, cy, kid):
    """Sigma 2, anywhere in [0, w - 0.5] (the targets' range: image x in [0, W - 1]), borders too."""
    kp = extract_keypoints(kp_heatmaps({kid: gaussian(cx, cy)}))
    assert set(kp) == {kid}
    x, y, p = kp[kid]
    assert abs(x - cx) < 1e-3 and abs(y - cy) < 1e-3  # well inside the required 0.05
    assert 0.88 < p <= 1.0


@settings(max_examples=40, deadline=None)
@given(cx=st.floats(3.0, W - 4.0), cy=st.floats(3.0, H - 4.0), sx=st.floats(1.0, 4.0), sy=st.floats(1.0, 4.0),
       angle=st.floats(0.0, math.pi))
def test_keypoint_subpixel_anisotropic_rotated(cx, cy, sx, sy, angle):
    """The log of any Gaussian is an exact quadratic: the 2D Newton step (with f_xy) is exact from
    a peak pixel less than 1 px from the centre per axis (the step is clipped to 1 px by design; a
    thin rotated Gaussian, sx=1 and sy=4, can peak on a pixel 1.06 px away)."""
    g = gaussian(cx, cy, sx=sx, sy=sy, angle=angle)
    iy, ix = np.unravel_index(int(np.argmax(g)), g.shape)
    assume(abs(ix - cx) < 0.999 and abs(iy - cy) < 0.999)
    kp = extract_keypoints(kp_heatmaps({7: g}))
    x, y, _ = kp[7]
    assert abs(x - cx) < 1e-3 and abs(y - cy) < 1e-3


def test_refine_modes():
    rng = np.random.default_rng(3)
    errs = {"log": [], "raw": [], "none": []}
    for _ in range(100):
        cx, cy = rng.uniform(3, W - 4), rng.uniform(3, H - 4)
        a = kp_heatmaps({1: gaussian(cx, cy)})
        for mode in errs:
            x, y, _ = extract_keypoints(a, refine=mode)[1]
            errs[mode].append(max(abs(x - cx), abs(y - cy)))
    assert max(errs["log"]) < 1e-4
    assert max(errs["raw"]) < 0.05 and np.mean(errs["raw"]) > 1e-3  # biased, but within 0.05 at sigma 2
    assert max(errs["none"]) <= 0.5 + 1e-9
    with pytest.raises(ValueError):
        extract_keypoints(kp_heatmaps({1: gaussian(5, 5)}), refine="cubic")


def test_refinement_is_clamped_and_finite_on_degenerate_peaks():
    a = np.zeros((58, H, W), np.float32)
    a[0, 10:14, 20:25] = 1.0  # saturated plateau: no curvature
    a[1, 5, 5] = 0.9  # a single hot pixel surrounded by zeros (log floor)
    x, y, p = extract_keypoints(a)[1]
    assert p == 1.0 and abs(x - 20) <= 1.0 and abs(y - 10) <= 1.0  # first maximum, clamped to 1 px
    x, y, _ = extract_keypoints(a)[2]
    assert abs(x - 5) < 1e-6 and abs(y - 5) < 1e-6
    rng = np.random.default_rng(0)
    noisy = rng.random((58, H, W)).astype(np.float32)
    for kid, (x, y, p) in extract_keypoints(noisy, threshold=0.0).items():
        r, c = np.unravel_index(np.argmax(noisy[kid - 1]), (H, W))
        assert abs(x - c) <= 1.0 and abs(y - r) <= 1.0 and p == noisy[kid - 1, r, c]
    tiny = np.zeros((58, 2, 2), np.float32)
    tiny[3, 1, 0] = 0.5
    assert extract_keypoints(tiny) == {4: (0.0, 1.0, 0.5)}


# ------------------------------------------------------------------------------ thresholds and NMS
def test_thresholds_background_and_empty():
    a = kp_heatmaps({3: 0.8 * gaussian(10.3, 12.7), 9: 0.05 * gaussian(30, 20)})
    kp = extract_keypoints(a, threshold=0.1)
    assert set(kp) == {3}  # channel 9 below threshold; the background channel (~1 everywhere) ignored
    assert abs(kp[3][2] - 0.8 * math.exp(-(0.3 ** 2 + 0.3 ** 2) / 8)) < 1e-6
    assert set(extract_keypoints(a, threshold=0.01)) == {3, 9}
    per_id = np.full(57, 0.1)
    per_id[2] = 0.9  # id 3 needs 0.9
    per_id[8] = 0.01
    assert set(extract_keypoints(a, threshold=per_id)) == {9}
    assert set(extract_keypoints(a, threshold=np.append(per_id, 5.0))) == {9}  # 58 values: the last ignored
    only_bg = kp_heatmaps({})
    assert only_bg[57].min() == 1.0 and extract_keypoints(only_bg) == {}
    with pytest.raises(ValueError):
        extract_keypoints(a, threshold=np.ones(10))
    with pytest.raises(ValueError):
        extract_keypoints(a, nms_kernel=4)
    with pytest.raises(ValueError):
        extract_keypoints(a[:20])


def test_two_close_peaks_keep_the_stronger():
    ch = np.maximum(gaussian(20.25, 15.5), 0.7 * gaussian(28.0, 15.5))
    kp = extract_keypoints(kp_heatmaps({12: ch}))
    x, y, p = kp[12]
    assert abs(x - 20.25) < 1e-3 and abs(y - 15.5) < 1e-3
    ch = np.maximum(0.6 * gaussian(20.25, 15.5), gaussian(28.0, 15.5))
    assert abs(extract_keypoints(kp_heatmaps({12: ch}))[12][0] - 28.0) < 1e-3


def test_nms_kernel_and_find_peaks():
    a = np.zeros((2, 20, 20), np.float32)
    a[0, 5, 5], a[0, 5, 7], a[0, 15, 15] = 0.9, 0.8, 0.5  # 2 px apart: separate peaks for 3x3, not 5x5
    peaks3 = find_peaks(a, 0.1, 3)
    peaks5 = find_peaks(a, 0.1, 5)
    assert [(r, c) for r, c, _ in peaks3[0]] == [(5, 5), (5, 7), (15, 15)] and peaks3[1] == []
    assert [(r, c) for r, c, _ in peaks5[0]] == [(5, 5), (15, 15)]
    assert [(r, c) for r, c, _ in find_peaks(a, 0.1, 3, max_peaks=2, min_separation=4)[0]] == [(5, 5), (15, 15)]
    assert [(r, c) for r, c, _ in find_peaks(a, 0.6, 3)[0]] == [(5, 5), (5, 7)]
    m = nms_mask(a, 3)
    assert m[0, 5, 5] and m[0, 5, 7] and not m[0, 5, 6] and m[1].all()  # an all-zero channel is flat


def test_torch_input_and_torch_maxpool_agree_with_numpy():
    torch = pytest.importorskip("torch")
    rng = np.random.default_rng(1)
    a = rng.random((24, 30, 40)).astype(np.float32)
    from scipy.ndimage import maximum_filter

    ref = a == maximum_filter(a, size=(1, 5, 5), mode="constant", cval=-np.inf)
    assert (nms_mask(a, 5) == ref).all()  # torch is imported here, so this used max_pool2d
    t = torch.from_numpy(a)
    assert extract_lines(t, 0.5) == extract_lines(a, 0.5)
    assert extract_lines(t[None], 0.5) == extract_lines(a, 0.5)  # batch of one


def test_import_does_not_import_torch():
    code = ("import sys, numpy as np; import pnlviz.detect.peaks as p; "
            "p.extract_lines(np.random.rand(24, 20, 30).astype(np.float32), 0.5); "
            "p.extract_keypoints(np.random.rand(58, 20, 30).astype(np.float32)); "
            "assert 'torch' not in sys.modules")
    subprocess.run([sys.executable, "-c", code], check=True)


# ------------------------------------------------------------------------------ lines
@settings(max_examples=40, deadline=None)
@given(x1=st.floats(0.0, W - 0.5), y1=st.floats(0.0, H - 0.5), x2=st.floats(0.0, W - 0.5),
       y2=st.floats(0.0, H - 0.5), lid=st.integers(1, 23))
def test_line_two_peaks_give_both_extremities(x1, y1, x2, y2, lid):
    assume(math.hypot(x2 - x1, y2 - y1) >= 6.0)
    ch = np.maximum(gaussian(x1, y1), gaussian(x2, y2))
    lines = extract_lines(line_heatmaps({lid: ch}))
    assert set(lines) == {lid}
    a1, b1, p1, a2, b2, p2 = lines[lid]
    got = [(a1, b1), (a2, b2)]
    if abs(abs(x2 - x1) - abs(y2 - y1)) < 1e-2:  # a 45-degree segment: the order hangs on sub-pixel error
        assert np.abs(np.array(sorted(got)) - np.array(sorted([(x1, y1), (x2, y2)]))).max() < 1e-3
        return
    # ordered like LineExtremities: by x when closer to horizontal, by y otherwise
    if abs(x2 - x1) >= abs(y2 - y1):
        assert a1 <= a2
        want = sorted([(x1, y1), (x2, y2)])
    else:
        assert b1 <= b2
        want = sorted([(x1, y1), (x2, y2)], key=lambda q: q[1])
    assert np.abs(np.array(got) - np.array(want)).max() < 1e-3
    assert p1 > 0.88 and p2 > 0.88


def test_line_channels_one_peak_or_merged_give_nothing():
    two = np.maximum(gaussian(10, 10), 0.6 * gaussian(30, 25))
    heat = line_heatmaps({
        1: gaussian(12.5, 8.25),  # one extremity only
        2: two,  # both
        3: np.maximum(gaussian(10, 10), 0.05 * gaussian(30, 25)),  # second below threshold
        4: np.maximum(gaussian(10, 10), gaussian(12.5, 10)),  # one blob (peaks < min_separation apart)
    })
    heat[23] = 1.0  # boundary channel: ignored
    lines = extract_lines(heat)
    assert set(lines) == {2}
    x1, y1, p1, x2, y2, p2 = lines[2]
    assert np.allclose([x1, y1, p1, x2, y2], [10, 10, 1.0, 30, 25], atol=1e-3) and abs(p2 - 0.6) < 1e-6
    assert set(extract_lines(heat, threshold=0.01)) == {2, 3}
    assert set(extract_lines(heat, min_separation=1.0)) >= {2}
    per_id = np.full(23, 0.1)
    per_id[1] = 0.7  # line 2's weaker end (0.6) now fails
    assert extract_lines(heat, threshold=per_id) == {}
    assert extract_lines(np.zeros((24, 10, 10), np.float32)) == {}


# ------------------------------------------------------------------------------ coordinates
def test_heatmap_to_image_conventions():
    hm, im = (480, 270), (960, 540)
    assert heatmap_to_image(0.0, 0.0, hm, im) == (0.0, 0.0)
    assert heatmap_to_image(479.5, 269.5, hm, im) == (959.0, 539.0)  # last image pixel <-> last half pixel
    assert heatmap_to_image(0.0, 0.0, hm, im, convention="centre") == (0.5, 0.5)
    assert heatmap_to_image(-0.25, -0.25, hm, im, convention="center") == (0.0, 0.0)
    assert heatmap_to_image(10.0, 10.0, (481, 270), (963, 541), scale=2) == (20.0, 20.0)
    xs, ys = heatmap_to_image(np.array([1.0, 2.5]), np.array([3.0, 4.0]), hm, (1920, 1080))
    assert np.allclose(xs, [4.0, 10.0]) and np.allclose(ys, [12.0, 16.0])
    for conv in ("index", "centre"):
        x, y = image_to_heatmap(*heatmap_to_image(123.4, 56.7, hm, (1280, 720), convention=conv), hm, (1280, 720),
                                convention=conv)
        assert abs(x - 123.4) < 1e-9 and abs(y - 56.7) < 1e-9
    with pytest.raises(ValueError):
        heatmap_to_image(1.0, 1.0, hm, im, convention="corner")


def test_detections_to_predictions_and_zip_round_trip(tmp_path):
    kp = {1: (10.0, 20.0, 0.9), 57: (479.5, 0.0, 0.3)}
    lines = {13: (100.0, 0.0, 0.8, 100.0, 269.5, 0.7)}
    pred = detections_to_predictions(kp, lines, (480, 270), (960, 540))
    assert isinstance(pred, Predictions)
    assert pred.keypoints[1] == pytest.approx((20.0 / 960, 40.0 / 540, 0.9))
    assert pred.keypoints[57] == pytest.approx((959.0 / 960, 0.0, 0.3))
    assert pred.lines[13] == pytest.approx((200 / 960, 0.0, 0.8, 200 / 960, 539 / 540, 0.7))
    assert pred.keypoints_px(960, 540)[1] == pytest.approx((20.0, 40.0, 0.9))
    centre = detections_to_predictions(kp, lines, (480, 270), (960, 540), convention="centre")
    assert centre.keypoints_px(960, 540)[1] == pytest.approx((20.5, 40.5, 0.9))
    path = tmp_path / "preds.zip"
    write_predictions(path, {"00001": pred, "00002": Predictions()})
    back = read_predictions(path)
    assert back == {"00001": pred, "00002": Predictions()}


# ------------------------------------------------------------------------------ real labels round trip
@needs_shared
def test_sn22_label_round_trip(tmp_path):
    from pnlviz.data import open_dataset
    from pnlviz.labels import heatmap_targets, keypoints_from_annotation, line_extremities, training_targets

    iw, ih = 960, 540
    ds = open_dataset(SN22)
    preds, n_kp, n_lines, worst = {}, 0, 0, 0.0
    for i, (stem, ann) in enumerate(ds.iter_annotations()):
        if i >= 12:
            break
        if i % 2:
            labels, ext, t = training_targets(ann, iw, ih)  # with the left-right disambiguation
        else:
            labels = keypoints_from_annotation(ann, iw, ih)
            ext = line_extremities(ann, iw, ih)
            t = heatmap_targets(labels, ext, iw, ih)
        pred = extract_predictions(t.keypoints, t.lines, (iw, ih))
        assert pred == detections_to_predictions(extract_keypoints(t.keypoints), extract_lines(t.lines),
                                                 (iw // 2, ih // 2), (iw, ih))
        drawn = {k for k, v in labels.keypoints.items() if k <= 57 and v.visible}
        assert set(pred.keypoints) == drawn
        kp_px = pred.keypoints_px(iw, ih)
        for k in drawn:
            lab = labels.keypoints[k]
            err = max(abs(kp_px[k][0] - lab.x), abs(kp_px[k][1] - lab.y))
            worst = max(worst, err)
            assert err < 0.5, (stem, k, err)
            n_kp += 1
        lines_px = pred.lines_px(iw, ih)
        for lid, e in ext.items():
            inside = all(0 <= q[0] <= iw - 1 and 0 <= q[1] <= ih - 1 for q in (e.p1, e.p2))
            if not inside or np.linalg.norm(e.p1 - e.p2) / 2 < 4.0:
                continue  # a Gaussian centred off the grid / two merged extremities are not recoverable
            x1, y1, _, x2, y2, _ = lines_px[lid]
            err = np.abs(np.array([x1, y1, x2, y2]) - np.r_[e.p1, e.p2]).max()
            worst = max(worst, err)
            assert err < 0.5, (stem, lid, err)
            n_lines += 1
        preds[stem] = pred
    assert n_kp >= 60 and n_lines >= 60
    assert worst < 1e-3
    path = tmp_path / "sn22.zip"
    write_predictions(path, preds)
    assert read_predictions(path) == preds


def test_refine_peaks_direct():
    a = gaussian(7.3, 4.6)[None]
    x, y = refine_peaks(a, [0], [5], [7])
    assert abs(x[0] - 7.3) < 1e-4 and abs(y[0] - 4.6) < 1e-4
    x, y = refine_peaks(a, [], [], [])
    assert x.shape == (0,) and y.shape == (0,)
