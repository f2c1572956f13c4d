"""Training labels land where the picture shows the point, whatever size the picture was made at
(:mod:`pnlviz.labels.resize`): a resized image (pixel centres move by half a pixel), a synthetic
frame rendered at the network's input size (the projection scales), a homography made for
another size."""

import cv2
import numpy as np
import pytest

from pnlviz.detect.peaks import extract_keypoints
from pnlviz.field import load_field_model
from pnlviz.labels.from_homography import homography_for_size, template_homography
from pnlviz.labels.resize import resize_annotation, resize_matrix

torch = pytest.importorskip("torch")

from pnlviz.detect.train import FrameCache, _annotation_arrays  # noqa: E402
from pnlviz.detect.train_data import View, annotation_example  # noqa: E402

INPUT = (480, 272)


def _blob(size, centre, sigma=3.0):
    """A float image of ``size`` with a Gaussian blob at sub-pixel ``centre`` (pixel (c, r) at x = c)."""
    w, h = size
    x, y = np.meshgrid(np.arange(w), np.arange(h))
    return np.exp(-((x - centre[0]) ** 2 + (y - centre[1]) ** 2) / (2 * sigma ** 2)).astype(np.float32)


def _centroid(img):
    y, x = np.mgrid[: img.shape[0], : img.shape[1]]
    return np.array([(img * x).sum(), (img * y).sum()]) / img.sum()


@pytest.mark.parametrize("size, interpolation", [((480, 272), cv2.INTER_AREA), ((1280, 720), cv2.INTER_LINEAR)])
def test_resize_matrix_follows_cv2_resize(size, interpolation):
    """A blob at a sub-pixel place of a 960x540 image is where ``resize_matrix`` sends it once the
    image is resized as the training and the detector resize (down by area, up bilinearly); the
    projection-scaling map (``index``) misses it by the half-pixel shift."""
    for centre in ((123.3, 77.8), (700.6, 401.2)):
        img = cv2.resize(_blob((960, 540), centre), size, interpolation=interpolation)
        found = _centroid(img)
        p = resize_matrix((960, 540), size) @ np.array([*centre, 1.0])
        q = resize_matrix((960, 540), size, "index") @ np.array([*centre, 1.0])
        assert np.hypot(*(found - p[:2])) < 0.02
        assert np.hypot(*(found - q[:2])) > 0.2


def _target_peaks(kp):
    """Keypoint id -> its target's peak in input pixels (the targets are drawn at half size by
    index, and a log-refined Gaussian peak is exact)."""
    found = extract_keypoints(kp, threshold=0.5, refine="log")
    return {k: np.array([2 * x, 2 * y]) for k, (x, y, _) in found.items()}


def _ground_ids(cam, model, size):
    """Line intersections on the ground in view of ``cam`` (well inside the picture): the keypoints
    a synthetic annotation fixes exactly."""
    ids = [k for k in model.keypoints if k <= 30 and abs(model.keypoints[k].xyz[2]) < 1e-9]
    uv, z = cam.project_with_depth(model.keypoint_xyz(ids))
    w, h = size
    inside = (z > 0) & (uv[:, 0] > 8) & (uv[:, 0] < w - 9) & (uv[:, 1] > 8) & (uv[:, 1] < h - 9)
    return {k: uv[i] for i, k in enumerate(ids) if inside[i]}


def test_synthetic_frames_rendered_at_the_input_size_train_on_their_own_projections():
    """``pnlviz train`` renders its synthetic frames at the input size; their annotation is made at
    960x540. The targets' peaks are the render camera's projections (a frame before the fix was
    labelled up to 0.45 input px above and left of them: the annotation read at the new size)."""
    from pnlviz.geometry.camera import Camera
    from pnlviz.synth import make_frame

    model = load_field_model()
    cache = FrameCache(4, seed=5, size=INPUT, progress=False)
    checked = 0
    for i in range(4):
        cam = Camera.from_soccernet(make_frame(i, 5, INPUT)["camera"]).scaled(*INPUT)
        _, kp, *_ = cache.sample(i, INPUT, 2.0, View())
        peaks = _target_peaks(kp)
        for k, uv in _ground_ids(cam, model, INPUT).items():
            if k in peaks:
                assert np.hypot(*(peaks[k] - uv)) < 0.05, (i, k, peaks[k], uv)
                checked += 1
    assert checked >= 8


def test_a_resized_frame_trains_on_where_the_resize_puts_its_points():
    """A 960x540 frame trained at 480x272: the targets' peaks are the camera's projections moved by
    the resize (half a pixel of the source less than the projection scaled)."""
    from pnlviz.geometry.camera import Camera
    from pnlviz.synth import make_frame

    model = load_field_model()
    checked = 0
    for i in range(3):
        f = make_frame(i, 8, (960, 540))
        cam = Camera.from_soccernet(f["camera"], (960, 540))
        _, kp, *_ = annotation_example(f["image"], _annotation_arrays(f["annotation"]), INPUT, 2.0, View())
        peaks = _target_peaks(kp)
        S = resize_matrix((960, 540), INPUT)
        for k, uv in _ground_ids(cam, model, (960, 540)).items():
            if k in peaks:
                want = (S @ np.array([*uv, 1.0]))[:2]
                assert np.hypot(*(peaks[k] - want)) < 0.05, (i, k, peaks[k], want)
                checked += 1
    assert checked >= 5


def test_a_homography_for_a_resized_copy_moves_pixel_centres():
    """A template -> 1280x720 homography used on a 480x272 copy: each point lands where a resize
    of the frame puts it; at the source size it is the homography itself."""
    model = load_field_model()
    H = np.array([[8.0, 0.3, 120.0], [0.1, -6.0, 650.0], [0.0, 0.0004, 1.0]])  # a template -> pixel map
    field = np.linalg.inv(model.template_to_field_matrix)
    X = np.array([[10.0, -20.0, 1.0], [-30.0, 5.0, 1.0]])  # field metres, homogeneous
    for size in ((480, 272), (960, 540), (1280, 720)):
        got = (homography_for_size(H, size) @ X.T).T
        src = (H @ field @ X.T).T
        want = (resize_matrix((1280, 720), size) @ (src / src[:, 2:]).T).T
        np.testing.assert_allclose(got[:, :2] / got[:, 2:], want[:, :2], atol=1e-9)
    np.testing.assert_allclose(homography_for_size(H, (1280, 720)), H @ field)
    for size in ((300, 300), (480, 272)):  # and back: what the paint fit stores after fitting a copy
        np.testing.assert_allclose(template_homography(homography_for_size(H, size), size), H, rtol=1e-9, atol=1e-9)


def test_resize_annotation_clips_to_the_new_picture_and_refuses_unknown_alignments():
    """A border point moved a fraction of a pixel outside the smaller picture is clipped back onto
    it along its line; same-size annotations come back unchanged; an unknown alignment is refused."""
    ann = {"Side line top": np.array([[0.0, 0.2], [1.0, 0.3]])}
    out = resize_annotation(ann, (960, 540), INPUT)["Side line top"] * np.array([479.0, 271.0])
    assert out[0, 0] == pytest.approx(0.0) and out[1, 0] == pytest.approx(479.0)
    # on the line between the moved ends
    a = (resize_matrix((960, 540), INPUT) @ np.array([0.0, 0.2 * 539, 1.0]))[:2]
    b = (resize_matrix((960, 540), INPUT) @ np.array([959.0, 0.3 * 539, 1.0]))[:2]
    d = (b - a) / np.linalg.norm(b - a)
    for p in out:
        assert abs(d[0] * (p - a)[1] - d[1] * (p - a)[0]) < 1e-9
    same = resize_annotation(ann, INPUT, INPUT)
    np.testing.assert_array_equal(same["Side line top"], ann["Side line top"])
    with pytest.raises(ValueError, match="align must be one of"):
        resize_matrix((960, 540), INPUT, "corner")
