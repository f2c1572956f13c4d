"""A ground homography brought onto the paint of its own image (:mod:`pnlviz.labels.paint_fit`):
back onto the true camera on synthetic frames, onto the full-resolution paint of a real frame
from its 300x300 copy, and refused where the paint says too little."""

import json

import cv2
import numpy as np

from pnlviz.field import load_field_model
from pnlviz.labels.paint_fit import fit_to_paint, paint_offsets, paint_strength
from pnlviz.labels.resize import resize_matrix


def _ground_points(model, H, size):
    """The ground keypoints (line intersections) ``H`` puts inside the image: {id: (x, y)}."""
    ids = [k for k in model.keypoints if k <= 30 and abs(model.keypoints[k].xyz[2]) < 1e-9]
    q = np.c_[model.keypoint_xyz(ids)[:, :2], np.ones(len(ids))] @ H.T
    uv = q[:, :2] / q[:, 2:]
    w, h = size
    if w is None:  # anywhere in front of the camera
        return {k: uv[i] for i, k in enumerate(ids) if q[i, 2] > 0}
    keep = (q[:, 2] > 0) & (uv[:, 0] >= 0) & (uv[:, 0] <= w - 1) & (uv[:, 1] >= 0) & (uv[:, 1] <= h - 1)
    return {k: uv[i] for i, k in enumerate(ids) if keep[i]}


def test_a_shifted_homography_comes_back_onto_a_synthetic_frame():
    """Synthetic frames (480x272, no lens distortion) with their true ground homography shifted by
    3 px across and 2 px down (and a little turned): fitted to the paint, every frame's ground
    keypoints come closer to the truth, and most of the shift goes (measured: 3.3 -> 1.2 px, the
    frames' medians; the rest is where the damping keeps what the lines in view measure weakly)."""
    from pnlviz.geometry.camera import Camera
    from pnlviz.synth import make_frame

    model = load_field_model()
    rng = np.random.default_rng(3)
    before, after = [], []
    for i in range(12):
        f = make_frame(i, 31, (480, 272))
        cam = Camera.from_soccernet(f["camera"]).scaled(480, 272)
        if cam.has_distortion:
            continue
        truth = cam.ground_homography()
        shift = np.array([[1 + rng.normal(0, 0.004), rng.normal(0, 0.004), rng.choice([-3.0, 3.0])],
                          [rng.normal(0, 0.004), 1 + rng.normal(0, 0.004), rng.choice([-2.0, 2.0])], [0, 0, 1.0]])
        bad = shift @ truth
        fit = fit_to_paint(bad, f["image"], model)
        if not fit.refined:  # kept as given, and said why
            assert fit.refused and np.array_equal(fit.H, bad)
            continue
        true_pts = _ground_points(model, truth, (480, 272))
        b, a = _ground_points(model, bad, (None, None)), _ground_points(model, fit.H, (None, None))
        before.append(np.median([np.hypot(*(b[k] - p)) for k, p in true_pts.items() if k in b]))
        after.append(np.median([np.hypot(*(a[k] - p)) for k, p in true_pts.items() if k in a]))
        assert after[-1] < before[-1], (i, before[-1], after[-1])
        assert fit.after_px < fit.before_px
    assert len(after) >= 4
    assert np.median(after) < 0.5 * np.median(before)


def test_a_real_frame_lands_on_its_full_resolution_paint(shared_dir):
    """WC14 training frame 16: its ground-truth homography is up to 6 px off the paint of the
    1280x720 frame (the near box line); fitted to the paint of the 300x300 copy alone, every line
    of the full-resolution frame is within about a pixel of its paint."""
    model = load_field_model()
    frames = shared_dir / "data" / "frames"
    full = cv2.imread(str(frames / "wc14_trainval_16.jpg"))
    H = np.array(json.loads((frames / "wc14_trainval_16_homography.json").read_text())["wc14_trainval_16"])
    field = np.linalg.inv(model.template_to_field_matrix)
    small = cv2.imread(str(shared_dir / "data" / "wc14_real" / "trainval_300" / "16.jpg"))
    S = resize_matrix((1280, 720), (300, 300))
    fit = fit_to_paint(S @ H @ field, small, model)
    assert fit.refined and fit.lines >= 3

    def worst_line(Hf):
        _, _, d, line = paint_offsets(Hf, paint_strength(full), model, half=8.0)  # 6 px off: a wider look
        return max(abs(float(np.median(d[line == k]))) for k in set(line.tolist()) if (line == k).sum() >= 8)

    before, after = worst_line(H @ field), worst_line(np.linalg.inv(S) @ fit.H)
    assert before > 4.0
    assert after < 1.5


def test_too_little_paint_keeps_the_homography_and_says_why():
    """Plain grass: nothing measured, the homography comes back as given with the reason; one line
    alone: refused as too few lines."""
    model = load_field_model()
    from pnlviz.geometry.camera import Camera

    cam = Camera.from_look_at((0.0, 60.0, -20.0), (0.0, 0.0, 0.0), hfov_deg=40, width=480, height=272)
    H = cam.ground_homography()
    grass = np.full((272, 480, 3), (40, 120, 40), np.uint8)
    fit = fit_to_paint(H, grass, model)
    assert not fit.refined and fit.refused == "the paint measures 0 points (< 40)"
    assert np.array_equal(fit.H, H)
    one = grass.copy()
    seg = model.lines["Middle line"]
    q = np.c_[np.array([seg.start[:2], seg.end[:2]]), np.ones(2)] @ H.T
    a, b = q[:, :2] / q[:, 2:]
    cv2.line(one, tuple(np.round(a).astype(int)), tuple(np.round(b).astype(int)), (230, 230, 230), 2)
    fit = fit_to_paint(H, one, model)
    assert fit.refused == "the paint measures 1 lines (< 3)"
    assert np.array_equal(fit.H, H)


def test_homography_frames_train_on_the_fitted_homographies(shared_dir):
    """``paint_fit`` on a homography source: the frames the paint measures get their fitted
    homography (their targets move), the others keep the given one bit for bit."""
    from pnlviz.detect.train_data import HomographyFrames

    folder = shared_dir / "data" / "wc14_real" / "trainval_300"
    stems = ["16", "52", "194"]
    given = HomographyFrames(folder, stems=stems)
    fitted = HomographyFrames(folder, stems=stems, paint_fit=True)
    assert len(fitted.paint_fits) == 3 and not given.paint_fits
    for i, fit in enumerate(fitted.paint_fits):
        a, b = given.field_homography(i, (480, 272)), fitted.field_homography(i, (480, 272))
        if fit.refined:
            h, w = fitted.images[i].shape[:2]
            np.testing.assert_allclose(fitted.field_homography(i, (w, h)) / fitted.field_homography(i, (w, h))[2, 2],
                                       fit.H / fit.H[2, 2], atol=1e-9)
            assert not np.allclose(a / a[2, 2], b / b[2, 2])
        else:
            np.testing.assert_array_equal(a, b)
    assert sum(f.refined for f in fitted.paint_fits) >= 2
