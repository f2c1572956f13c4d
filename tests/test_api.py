"""The Python API (``pnlviz.calibrate``, ``pnlviz.Camera``, ``pnlviz.top_view``...): exact round
trips on known cameras, and errors that name the argument."""

import numpy as np
import pytest

import pnlviz
from pnlviz import ArgumentError


def cameras():
    plain = pnlviz.Camera.from_look_at((-10.0, 50.0, -18.0), (5.0, 0.0, 0.0), hfov_deg=45, width=1920, height=1080,
                                       roll_deg=1.5)
    lens = pnlviz.Camera.from_look_at((20.0, 60.0, -25.0), (-10.0, 3.0, 0.0), hfov_deg=70, width=1280, height=720,
                                      k1=-0.18)
    return [plain, lens]


@pytest.mark.parametrize("cam", cameras(), ids=["no k1", "k1"])
def test_image_to_pitch_undoes_project_to_a_millimetre(cam):
    gx, gy = np.meshgrid(np.linspace(-52.5, 52.5, 43), np.linspace(-34, 34, 29))
    ground = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], axis=1)
    uv = cam.project(ground)
    xc = cam.to_camera(ground)
    r2 = np.sum((xc[:, :2] / xc[:, 2:]) ** 2, axis=1)
    # in the image, and where the lens is one-to-one (beyond r^2 = 1 / (3 |k1|) a strong barrel
    # lens folds points far outside the view back in)
    seen = cam.in_image(np.nan_to_num(uv, nan=-1.0)) & (xc[:, 2] > 0) & (r2 * 3 * abs(cam.radial[0]) < 1)
    assert seen.sum() > 100  # the grid is well inside the view
    back = cam.image_to_pitch(uv[seen])
    assert np.max(np.abs(back - ground[seen, :2])) < 1e-3
    # the homography maps the ground to the pixels the lens would give without distortion
    H = cam.homography()
    h = np.c_[ground[seen, :2], np.ones(seen.sum())] @ H.T
    np.testing.assert_allclose(h[:, :2] / h[:, 2:], cam.project(ground[seen], distort=False), atol=1e-6)


def test_a_pixel_above_the_horizon_is_nowhere_on_the_pitch():
    cam = cameras()[0]
    assert np.all(np.isnan(cam.image_to_pitch([[960.0, -5000.0]])))


def test_image_to_pitch_takes_one_pixel_or_n_and_refuses_other_shapes():
    cam = cameras()[0]
    many = cam.image_to_pitch([[960.0, 540.0], [100.0, 900.0]])
    np.testing.assert_allclose(cam.image_to_pitch((100.0, 900.0)), many[1])  # one pixel: one point
    with pytest.raises(ValueError, match=r"uv: expected pixels \(N, 2\).*shape \(2, 3\)"):
        cam.image_to_pitch([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]])  # it read these as 3 pixels


def test_calibrate_recovers_the_camera_the_keypoints_came_from():
    cam = cameras()[0]
    world = pnlviz.keypoints()
    uv = cam.project(np.array(list(world.values())))
    pixels = {k: p for k, p in zip(world, uv) if cam.in_image(np.nan_to_num(p[None], nan=-1.0))[0]}
    res = pnlviz.calibrate(pixels, image_size=(int(cam.width), int(cam.height)))
    assert res.ok and res.reason is None
    assert np.linalg.norm(res.camera.C - cam.C) < 0.05
    assert abs(res.camera.fx / cam.fx - 1) < 1e-3
    assert max(res.point_residuals.values()) < 0.1


def test_calibrate_from_lines_alone():
    cam = cameras()[0]
    model_lines = {}
    from pnlviz.field.model import load_field_model

    for name, pts in load_field_model().sample_polylines(1.0, 0.5).items():
        uv = cam.project(pts)
        uv = uv[cam.in_image(np.nan_to_num(uv, nan=-1.0))]
        if len(uv) >= 2:
            model_lines[name] = uv
    res = pnlviz.calibrate(lines=model_lines, image_size=(1920, 1080))
    assert res.ok, res.reason
    assert np.linalg.norm(res.camera.C - cam.C) < 0.5
    # the keypoints derived from those lines repeat them: with 4 classes or more they are left out
    assert len(res.pnl_lines) >= 4 and res.lines_alone and set(res.lines_alone) <= set(res.point_residuals)
    # a keypoint given is a measurement: never left out, while the others still are
    given = res.lines_alone[0]
    again = pnlviz.calibrate({given: cam.project(np.array([pnlviz.keypoints()[given]]))[0]}, model_lines,
                             image_size=(1920, 1080))
    assert again.ok and given not in again.lines_alone and set(again.lines_alone) == set(res.lines_alone) - {given}


def test_a_frame_that_cannot_be_calibrated_says_why():
    res = pnlviz.calibrate({1: (10.0, 10.0), 2: (500.0, 12.0)}, image_size=(1280, 720))
    assert res.camera is None and res.reason and not res.ok


@pytest.mark.parametrize("kwargs, named", [
    (dict(keypoints={99: (1, 2)}, image_size=(1280, 720)), "keypoints[99]"),
    (dict(keypoints={True: (1, 2)}, image_size=(1280, 720)), "keypoints"),
    (dict(keypoints={"7": (1, 2)}, image_size=(1280, 720)), "keypoints"),
    (dict(keypoints={7: (1, float("nan"))}, image_size=(1280, 720)), "keypoints[7]"),
    (dict(keypoints={7: (1, 2, 3)}, image_size=(1280, 720)), "keypoints[7]"),
    (dict(keypoints=[(1, 2)], image_size=(1280, 720)), "keypoints"),
    (dict(lines={"Side line north": [(0, 0), (1, 1)]}, image_size=(1280, 720)), "lines['Side line north']"),
    (dict(lines={"Side line top": [(0, 0)]}, image_size=(1280, 720)), "lines['Side line top']"),
    (dict(image_size=(0, 720)), "image_size"),
    (dict(image_size=(1280.5, 720)), "image_size"),
    (dict(image_size="1280x720"), "image_size"),
    (dict(image_size=(1280, 720), alpha=2.0), "alpha"),
])
def test_bad_arguments_are_named(kwargs, named):
    with pytest.raises(ArgumentError) as err:
        pnlviz.calibrate(**kwargs)
    assert str(err.value).startswith(named)


def test_the_top_view_shades_what_the_camera_sees():
    cam = cameras()[0]
    px_per_m = 8.0
    view = pnlviz.top_view(cam, points=[[960.0, 900.0]], px_per_m=px_per_m)
    plain = pnlviz.top_view(None, px_per_m=px_per_m)
    assert view.shape == plain.shape and view.dtype == np.uint8
    # the ground under the image centre is shaded; a corner of the pitch far behind the view is not
    centre = cam.image_to_pitch([[960.0, 540.0]])[0]

    def at(xy):
        x, y = ((np.asarray(xy) + [52.5 + 6, 34 + 6]) * px_per_m).astype(int)
        return view[y, x].astype(int), plain[y, x].astype(int)

    shaded, bare = at(centre)
    assert np.abs(shaded - bare).sum() > 60
    outside = [-55.0, -36.0] if cam.project([[-55.0, -36.0, 0.0]])[0][0] < 0 else [55.0, -36.0]
    assert not cam.in_image(np.nan_to_num(cam.project([[*outside, 0.0]]), nan=-1.0))[0]
    shaded, bare = at(outside)
    assert np.abs(shaded - bare).sum() == 0
    # the player's feet: a red disc where image_to_pitch puts them
    feet = cam.image_to_pitch([[960.0, 900.0]])[0]
    b, g, r = at(feet)[0]
    assert r > 150 and g < 120 and b < 120


@pytest.mark.parametrize("cam", cameras(), ids=["no k1", "k1"])
def test_the_footprint_is_the_ground_the_camera_puts_in_its_image(cam):
    """The footprint polygon against the definition, pixel by pixel: a ground point is seen when
    its projection lands in the image and that pixel's ray comes back to it (else the projection is
    a fold of the distortion model, not a ray of the camera)."""
    import cv2

    from pnlviz.geometry.footprint import ground_footprint

    ppm = 4.0
    gx, gy = np.meshgrid((np.arange(int(117 * ppm)) + 0.5) / ppm - 58.5, (np.arange(int(80 * ppm)) + 0.5) / ppm - 40)
    ground = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], axis=1)
    uv = cam.project(ground)
    inside = cam.in_image(np.nan_to_num(uv, nan=-1.0))
    back = np.full_like(uv, np.nan)
    back[inside] = cam.image_to_pitch(uv[inside])
    truth = (inside & (np.linalg.norm(np.nan_to_num(back, nan=1e9) - ground[:, :2], axis=1) < 0.01)).reshape(gx.shape)
    seen = np.zeros(gx.shape, np.uint8)
    poly = (ground_footprint(cam) + [58.5, 40]) * ppm - 0.5
    cv2.fillPoly(seen, [np.round(poly * 16).astype(np.int32)], 1, cv2.LINE_8, shift=4)
    assert truth.sum() > 1000 and abs(int(seen.sum()) - int(truth.sum())) < 0.02 * truth.sum()
    near = np.ones((3, 3), np.uint8)  # pixels straddling the border may go either way, no other
    assert not (truth & ~cv2.dilate(seen, near).astype(bool)).any()
    extra = (seen.astype(bool) & ~cv2.dilate(truth.astype(np.uint8), near).astype(bool)).ravel()
    # else only where the border's samples are far apart on the ground: a few pixels off the image
    off = np.maximum(np.maximum(-uv[extra], uv[extra] - [cam.width, cam.height]), 0).max(axis=1, initial=0)
    assert extra.sum() < 10 and np.all(off < 4)


def test_a_camera_above_the_pitch_looking_up_has_no_footprint():
    from pnlviz.geometry.footprint import ground_footprint

    sky = pnlviz.Camera.from_look_at((0.0, 50.0, -20.0), (0.0, 0.0, -60.0), hfov_deg=20, width=960, height=540)
    assert ground_footprint(sky).shape == (0, 2)
    bare = pnlviz.top_view(None, px_per_m=3.0)
    view = pnlviz.top_view(sky, px_per_m=3.0)
    changed = np.any(view != bare, axis=2)
    ys, xs = np.nonzero(changed)
    # only the camera's mark (a disc of radius 5 at its position) differs
    assert changed.sum() < 150 and np.ptp(xs) <= 16 and np.ptp(ys) <= 16


def test_the_top_view_draws_a_trackers_metres_and_the_picture_on_the_ground():
    cam = cameras()[0]
    ppm = 8.0
    W, H = int(cam.width), int(cam.height)
    picture = np.zeros((H // 2, W // 2, 3), np.uint8)  # the picture at half size: scaled, not refused
    picture[:, : W // 4] = (255, 0, 0)  # the image's left half blue, the right half red (BGR)
    picture[:, W // 4:] = (0, 0, 255)
    view = pnlviz.top_view(cam, picture, points_pitch=[[30.0, -20.0]], px_per_m=ppm)

    def at(xy):
        x, y = ((np.asarray(xy) + [58.5, 40]) * ppm).astype(int)
        return view[y, x].astype(int)

    left, right = cam.image_to_pitch([[W * 0.2, H * 0.7], [W * 0.8, H * 0.7]])
    assert tuple(at(left)) == (255, 0, 0) and tuple(at(right)) == (0, 0, 255)
    b, g, r = at([30.0, -20.0])  # the tracker's player, a red disc where its metres are
    assert r > 150 and g < 120 and b < 120
    outside = view[2, 2].astype(int)  # the corner of the canvas, far behind the view: grass
    assert tuple(outside) == (40, 92, 46)
    # without a camera the metres are still drawn
    alone = pnlviz.top_view(None, points_pitch=np.array([[30.0, -20.0]]), px_per_m=ppm)
    x, y = ((np.array([30.0, -20.0]) + [58.5, 40]) * ppm).astype(int)
    assert alone[y, x, 2] > 150


def test_top_view_arguments_are_named():
    with pytest.raises(ArgumentError, match="^camera"):
        pnlviz.top_view({"x_focal_length": 1})
    with pytest.raises(ArgumentError, match="^px_per_m"):
        pnlviz.top_view(None, px_per_m=0)
    cam = cameras()[0]
    with pytest.raises(ArgumentError, match="^points_pitch: expected an array \\(N, 2\\), got shape \\(3,\\)"):
        pnlviz.top_view(cam, points_pitch=[1.0, 2.0, 3.0])
    with pytest.raises(ArgumentError, match="^points_image: image points need the camera"):
        pnlviz.top_view(None, points_image=[[1.0, 2.0]])
    with pytest.raises(ArgumentError, match="^image: 1080x1920 is not the camera's aspect"):
        pnlviz.top_view(cam, np.zeros((1920, 1080, 3), np.uint8))  # a picture given as (W, H)
    with pytest.raises(ArgumentError, match="^image: a picture needs the camera"):
        pnlviz.top_view(None, np.zeros((1080, 1920, 3), np.uint8))


def test_open_dataset_names_a_missing_path(tmp_path):
    with pytest.raises(ArgumentError, match="^path"):
        pnlviz.open_dataset(tmp_path / "nothing")
    ds = pnlviz.open_dataset(pnlviz.SAMPLE_DIR)
    assert len(ds.stems) == len({p.stem for p in pnlviz.SAMPLE_DIR.glob("*.*") if p.suffix in (".jpg", ".json")}) > 30


def test_detect_finds_what_calibrate_takes():
    pytest.importorskip("torch")
    import cv2

    image = cv2.imread(str(pnlviz.SAMPLE_DIR / "00000.jpg"))
    found = pnlviz.detect(image)
    assert len(found["keypoints"]) >= 4
    assert all(0 <= x < image.shape[1] and 0 <= y < image.shape[0] and 0.1 <= p <= 1
               for x, y, p in found["keypoints"].values())
    res = pnlviz.calibrate(**found, image_size=image.shape[1::-1])  # what detect gives, as it is
    assert res.ok, res.reason
    plain = pnlviz.calibrate({k: (x, y) for k, (x, y, _) in found["keypoints"].items()}, found["lines"],
                             image_size=image.shape[1::-1])
    assert np.allclose(res.camera.P, plain.camera.P)  # every detected keypoint is over the threshold
    with pytest.raises(ArgumentError, match="^image"):
        pnlviz.detect(image[:, :, 0])


def test_calibrate_clip_fits_one_broadcast_camera_per_shot():
    """A camera panning across the pitch over 10 frames (one position, one lens): the clip's cameras
    come back on the truth, as one shot."""
    world = pnlviz.keypoints()
    truth = [pnlviz.Camera.from_look_at((0.0, 55.0, -20.0), (x, 0.0, 0.0), hfov_deg=40, width=1280, height=720)
             for x in np.linspace(-20, 20, 10)]
    frames = []
    for cam in truth:
        uv = cam.project(np.array(list(world.values())))
        frames.append({"keypoints": {k: p for k, p in zip(world, uv)
                                     if cam.in_image(np.nan_to_num(p[None], nan=-1.0))[0]}})
    frames[4] = {}  # a frame where nothing was seen
    clip = pnlviz.calibrate_clip(frames, image_size=(1280, 720))
    assert clip.shots == (tuple(range(10)),)
    assert clip.cameras[4] is None
    for t, cam in enumerate(clip.cameras):
        if cam is not None:
            assert np.linalg.norm(cam.C - truth[t].C) < 0.5 and abs(cam.fx / truth[t].fx - 1) < 0.01
    with pytest.raises(ArgumentError, match=r"^frames\[1\]\.keypoints\[99\]"):
        pnlviz.calibrate_clip([{}, {"keypoints": {99: (1, 2)}}], image_size=(1280, 720))
    with pytest.raises(ArgumentError, match=r"^frames\[0\]"):
        pnlviz.calibrate_clip([{"points": {}}], image_size=(1280, 720))


def test_the_api_reference_page_is_current():
    """docs/api.md is written from the docstrings by scripts/api_reference.py: a docstring changed
    without the page written again fails here."""
    import subprocess
    import sys
    from pathlib import Path

    script = Path(__file__).resolve().parents[1] / "scripts" / "api_reference.py"
    run = subprocess.run([sys.executable, str(script), "--check"], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr


def test_every_entry_of_the_api_page_has_an_example_and_they_all_run():
    """docs/api.md, the docs as the API: each function, class and method has a ``>>>`` example,
    and every example gives what the page says, run from the page itself."""
    import doctest
    import re
    from pathlib import Path

    torch = pytest.importorskip("torch")  # pnlviz.detect's example runs the light model
    torch.set_num_threads(1)
    page = (Path(__file__).resolve().parents[1] / "docs" / "api.md").read_text()
    sections = re.split(r"^(#{2,3} `[^`]+`)$", page, flags=re.M)[1:]
    entries = dict(zip(sections[::2], sections[1::2]))
    assert len(entries) >= 20 and any("pitch_to_image" in h for h in entries)
    assert [h for h, body in entries.items() if ">>>" not in body] == []
    parser, runner = doctest.DocTestParser(), doctest.DocTestRunner(optionflags=doctest.ELLIPSIS)
    for head, body in entries.items():
        globs = {"np": np, "pnlviz": pnlviz, "Camera": pnlviz.Camera}
        test = parser.get_doctest(body, globs, head, "docs/api.md", 0)
        result = runner.run(test)
        assert result.attempted > 0 and result.failed == 0, head


def test_calibrate_takes_keypoints_with_scores_as_detect_gives_them():
    cam = cameras()[0]
    ids = [k for k in pnlviz.keypoints() if k <= 57]
    world = np.array([pnlviz.keypoints()[k] for k in ids])
    uv = cam.project(world)
    seen = {k: (float(x), float(y)) for k, (x, y) in zip(ids, uv) if cam.in_image(np.array([[x, y]]))[0]}
    assert len(seen) >= 6
    plain = pnlviz.calibrate(seen, image_size=(1920, 1080))
    scored = {k: (x, y, 0.9) for k, (x, y) in seen.items()}
    wrong = next(iter(seen))
    scored[wrong] = (seen[wrong][0] + 300.0, seen[wrong][1], 0.05)  # far off, but scored under the threshold
    with_scores = pnlviz.calibrate(keypoints=scored, lines={}, image_size=(1920, 1080))
    assert plain.camera is not None and with_scores.camera is not None
    assert wrong not in with_scores.point_residuals and wrong in plain.point_residuals
    probe = np.array([[0.0, 0.0, 0.0], [30.0, 20.0, 0.0]])
    assert np.abs(with_scores.camera.project(probe) - cam.project(probe)).max() < 0.5
    with pytest.raises(ArgumentError, match=r"^keypoints\[\d+\]: a score is in \[0, 1\], got 1.5"):
        pnlviz.calibrate({wrong: (10.0, 10.0, 1.5)}, image_size=(1920, 1080))


def test_a_soccernet_camera_is_scaled_to_the_image_it_is_used_on():
    cam = cameras()[1]  # 1280x720, with a lens
    d = cam.scaled(960, 540).to_soccernet()  # written at 960x540, as pnlviz and PnLCalib write them
    full = pnlviz.Camera.from_soccernet(d, image_size=(1280, 720))
    assert full.allclose(cam, atol=1e-6)
    assert pnlviz.Camera.from_soccernet(d, 1280, 720).allclose(cam, atol=1e-6)  # the positional form agrees
    assert pnlviz.Camera.from_soccernet(d, (1280, 720)) == full  # the size as one positional argument
    ground = np.array([[0.0, 0.0, 0.0], [-20.0, 10.0, 0.0]])
    assert np.abs(full.project(ground) - cam.project(ground)).max() < 1e-6
    assert pnlviz.Camera.from_soccernet(d) == pnlviz.Camera.from_soccernet(d, image_size=(960, 540))
    with pytest.raises(ArgumentError, match=r"^image_size: 720x1280 is not the aspect"):
        pnlviz.Camera.from_soccernet(d, image_size=(720, 1280))  # (height, width) swapped
    with pytest.raises(ArgumentError, match="^image_size: give the size once"):
        pnlviz.Camera.from_soccernet(d, 1280, image_size=(1280, 720))
    with pytest.raises(ArgumentError, match="^image_size: expected a positive"):
        pnlviz.Camera.from_soccernet(d, image_size=(0, 720))


def test_cameras_compare_hash_and_compare_within_a_tolerance():
    a, lens = cameras()
    same = pnlviz.Camera.from_look_at((-10.0, 50.0, -18.0), (5.0, 0.0, 0.0), hfov_deg=45, width=1920, height=1080,
                                      roll_deg=1.5)
    assert a == same and hash(a) == hash(same) and len({a, same, lens}) == 2
    assert a != lens and a != "a camera"
    round_trip = pnlviz.Camera.from_soccernet(a.to_soccernet())  # through degrees: equal to ~1e-12, not exactly
    assert round_trip.allclose(a, atol=1e-6) and not lens.allclose(a)
    nudged = a.scaled(1920.0, 1080.0 * (1 + 1e-7))
    assert nudged != a and nudged.allclose(a, rtol=1e-6) and not nudged.allclose(a, rtol=1e-9, atol=0)
    with pytest.raises(ArgumentError, match="^other: expected a Camera"):
        a.allclose(a.to_soccernet())
    with pytest.raises(Exception):
        a.fx = 1.0  # immutable: what makes it hashable


def test_project_gives_pixels_and_refuses_other_shapes_by_name():
    cam = cameras()[1]
    world = np.array([[0.0, 0.0, 0.0], [-20.0, 10.0, 0.0], [5.0, -30.0, -2.44]])
    uv = cam.project(world)
    assert uv.shape == (3, 2)
    pixels, depth = cam.project_with_depth(world)
    assert np.array_equal(pixels, uv) and depth.shape == (3,) and np.all(depth > 0)
    assert np.array_equal(cam.project(world[1]), uv[1])  # one point: one pixel (2,)
    assert np.allclose(cam.pitch_to_image(world[:2, :2]), uv[:2])
    assert np.allclose(cam.image_to_pitch(cam.pitch_to_image(world[:2, :2])), world[:2, :2], atol=1e-6)
    assert cam.pitch_to_image([-20.0, 10.0]).shape == (2,)
    behind = cam.C + 5.0 * (cam.C - np.array([0.0, 0.0, 0.0])) / np.linalg.norm(cam.C)
    assert np.all(np.isnan(cam.project(behind)))
    with pytest.raises(ArgumentError, match=r"^world: expected points \(N, 3\) in metres, got an array of shape \(3, 2\)"):
        cam.project(world[:, :2])  # (N, 2) pitch positions: refused, not read as fewer points
    with pytest.raises(ArgumentError, match=r"^world: .*shape \(2, 3, 1\)"):
        cam.project(world[:2, :, None])
    with pytest.raises(ArgumentError, match=r"^xy: expected pitch positions \(N, 2\)"):
        cam.pitch_to_image(world)
