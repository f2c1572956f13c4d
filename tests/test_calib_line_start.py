"""A first camera from a frame's straight ground lines where its keypoints are too few for a
homography (``pnlviz.calib.line_start``, ``CalibParams.line_search``)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from pnlviz.calib.calibrate import CalibParams, calibrate
from pnlviz.calib.line_start import determined, ground_lines, line_homography
from pnlviz.calib.observations import Observations
from pnlviz.field.model import load_field_model
from pnlviz.geometry.camera import Camera

MODEL = load_field_model()
#: a main-camera view of the left penalty area
CAMERA = Camera.from_look_at((-20.0, 50.0, -14.0), (-42.0, -6.0, 0.0), hfov_deg=40.0, width=960, height=540)
ACROSS = ["Big rect. left main", "Side line left", "Small rect. left main"]  # x = const
ALONG = ["Big rect. left top", "Small rect. left top"]  # y = const
#: pitch points the camera shows, to compare cameras by
PROBES = np.array([[-52.5, -20.16, 0], [-36, -20.16, 0], [-47, -9.16, 0], [-40, 0, 0], [-30, 10, 0.0]])


def pitch_line(name: str) -> np.ndarray:
    seg = MODEL.lines[name]
    return np.cross([seg.start[0], seg.start[1], 1.0], [seg.end[0], seg.end[1], 1.0])


def seen_points(cam: Camera, name: str, n: int = 30, noise: float = 0.0, seed: int = 0) -> np.ndarray:
    """Pixels of class ``name`` that ``cam`` shows inside the image (``noise``: px, Gaussian)."""
    seg = MODEL.lines[name]
    t = np.linspace(0.0, 1.0, 400)[:, None]
    uv = cam.project(seg.start + t * (seg.end - seg.start))
    inside = (uv[:, 0] >= 0) & (uv[:, 0] <= cam.width - 1) & (uv[:, 1] >= 0) & (uv[:, 1] <= cam.height - 1)
    uv = uv[inside][np.linspace(0, inside.sum() - 1, n).astype(int)]
    return uv + np.random.default_rng(seed).normal(0.0, noise, uv.shape)


def lines_only(cam: Camera, names: list[str], noise: float = 0.0, rename: dict[str, str] | None = None) -> Observations:
    """Observations of ``names`` alone (no keypoint), each stored under ``rename``'s name if given."""
    rename = rename or {}
    return Observations(960, 540, lines={rename.get(n, n): seen_points(cam, n, noise=noise, seed=i)
                                         for i, n in enumerate(names)})


def homography_of(cam: Camera) -> np.ndarray:
    """The ground homography of a distortion-free camera: pitch (x, y, 1) -> pixels."""
    K = np.array([[cam.fx, 0, cam.cx], [0, cam.fy, cam.cy], [0, 0, 1.0]])
    return K @ np.column_stack([cam.R[:, 0], cam.R[:, 1], -cam.R @ cam.C])


def mapped(H: np.ndarray, xy: np.ndarray) -> np.ndarray:
    p = (H @ np.column_stack([xy, np.ones(len(xy))]).T).T
    return p[:, :2] / p[:, 2:]


def test_the_lines_give_the_homography_exactly():
    names = ACROSS[:2] + ALONG
    obs = lines_only(CAMERA, names)
    lines = ground_lines(obs, MODEL, 20.0)
    H = line_homography(np.array([lines[n][0] for n in names]), np.array([lines[n][1] for n in names]),
                        np.zeros((0, 2)), np.zeros((0, 2)), 960)
    assert np.abs(mapped(H, PROBES[:, :2]) - CAMERA.project(PROBES)).max() < 1e-6
    # one line and three points off it do as well
    pts = PROBES[[2, 3, 4]]
    assert determined(np.array([pitch_line(ALONG[0])]), pts[:, :2])
    H2 = line_homography(np.array([lines[ALONG[0]][0]]), np.array([pitch_line(ALONG[0])]), CAMERA.project(pts),
                         pts[:, :2], 960)
    assert np.abs(mapped(H2, PROBES[:, :2]) - CAMERA.project(PROBES)).max() < 1e-6


@pytest.mark.parametrize(("across", "along", "points", "fixes"), [
    (2, 2, 0, True),   # a quadrilateral of lines
    (3, 1, 0, False),  # three parallel lines meet at one point: five equations, one line across adds two
    (3, 2, 0, True),
    (2, 0, 2, False),  # shear along the lines is left free
    (2, 1, 1, True),
    (0, 0, 4, True),   # four points, as OpenCV's homography
])
def test_which_sets_fix_the_plane(across, along, points, fixes):
    lines = np.array([pitch_line(n) for n in ACROSS[:across] + ALONG[:along]]).reshape(-1, 3)
    pts = np.array([[-20.0, 5.0], [-30.0, 12.0], [-10.0, -15.0], [5.0, 20.0]])[:points]
    assert determined(lines, pts) is fixes
    if not fixes:  # the equations from exact pixels then have a second solution: not one homography
        obs = lines_only(CAMERA, ACROSS[:across] + ALONG[:along])
        found = ground_lines(obs, MODEL, 20.0)
        rows_ok = [found[n][0] for n in ACROSS[:across] + ALONG[:along]]
        H = line_homography(np.array(rows_ok).reshape(-1, 3), lines, CAMERA.project(np.column_stack([pts, np.zeros(len(pts))])),
                            pts, 960)
        assert np.abs(mapped(H, PROBES[:, :2]) - CAMERA.project(PROBES)).max() > 1.0


def test_a_frame_of_lines_alone_gets_its_camera():
    """No keypoint at all: refused as too few before the line search, calibrated with it."""
    obs = lines_only(CAMERA, ACROSS + ALONG, noise=0.5)
    off = calibrate(obs, replace(CalibParams(), line_search=False))
    assert not off.ok and off.failure_code == "too_few_keypoints"
    res = calibrate(obs)
    assert res.ok, res.failure
    assert np.abs(res.camera.project(PROBES) - CAMERA.project(PROBES)).max() < 2.0
    assert res.subset == "lines"
    # judged by its lines (no keypoint to judge): every class it fitted within a pixel or two
    assert sorted(res.pnl_lines) == sorted(ACROSS + ALONG)
    assert max(res.line_residuals[c] for c in res.pnl_lines) < 2.5


def test_a_point_that_is_not_a_number_is_ignored():
    """Observations built by hand (the file readers refuse them) may hold a non-finite point: the
    line is fitted to the others."""
    obs = lines_only(CAMERA, ACROSS + ALONG, noise=0.5)
    clean = ground_lines(obs, MODEL, 20.0)
    obs.lines["Side line left"] = np.vstack([obs.lines["Side line left"], [[np.nan, np.inf]]])
    found = ground_lines(obs, MODEL, 20.0)
    assert found.keys() == clean.keys()
    assert all(np.array_equal(found[n][0], clean[n][0]) for n in clean)


def test_four_lines_alone_are_not_trusted():
    """Four lines fix a homography exactly, a wrong one among them as well: a camera started from
    them, with nothing else to check it, is refused (the same four lines and a fifth pass)."""
    four = ACROSS[:2] + ALONG
    res = calibrate(lines_only(CAMERA, four, noise=0.5))
    assert not res.ok and res.failure_code == "degenerate" and "nothing checks them" in res.failure
    assert calibrate(lines_only(CAMERA, four + [ACROSS[2]], noise=0.5)).ok


def test_a_wrong_class_costs_one_start_not_the_frame():
    """A side line stored under the other side line's name (as an annotator's slip or a
    detector's mix-up): the set without it gives the camera, and PnL's gate leaves it out."""
    names = ACROSS + ALONG + ["Side line top"]
    cam = CAMERA
    assert len(seen_points(cam, "Side line top")) == 30  # the camera shows it
    obs = lines_only(cam, names, noise=0.5, rename={"Side line top": "Side line bottom"})
    res = calibrate(obs)
    assert res.ok, res.failure
    assert np.abs(res.camera.project(PROBES) - cam.project(PROBES)).max() < 2.0
    assert "Side line bottom" not in res.pnl_lines


def test_frames_with_keypoints_for_a_homography_are_untouched():
    """The line search starts only where the keypoints cannot: with four ground keypoints the
    result is the same with it on or off."""
    ids = [4, 5, 9, 8]
    xyz = MODEL.keypoint_xyz(ids)
    obs = Observations.from_keypoints(960, 540, {i: tuple(p) for i, p in zip(ids, CAMERA.project(xyz))},
                                      lines={n: seen_points(CAMERA, n) for n in ACROSS + ALONG})
    on, off = calibrate(obs), calibrate(obs, replace(CalibParams(), line_search=False))
    assert on.ok and off.ok and on.subset != "lines"
    assert on.camera.allclose(off.camera)


def test_the_line_search_raises_sn22(shared_dir):
    """Set-level, as ``benchmarks/misses.py`` measures it: on the SN22 development frames (human
    line annotations) the line search gives a camera to a frame that had none (its three keypoints
    are corners of the six lines in view) and raises FS@5; frames that had a camera keep it."""
    from pnlviz.calib.inputs import observations_from_annotation
    from pnlviz.data import open_dataset
    from pnlviz.metrics.soccernet import evaluate_dataset

    gt = shared_dir / "data" / "sn22_test_subset" / "annotations.zip"
    ds = open_dataset(gt)
    obs = {s: observations_from_annotation(ds.annotation(s), 960, 540)[0] for s in ds.stems}
    off = {s: calibrate(o, replace(CalibParams(), line_search=False)) for s, o in obs.items()}
    on = {s: calibrate(o) if not off[s].ok else off[s] for s, o in obs.items()}
    gained = [s for s in obs if on[s].ok and not off[s].ok]
    assert gained and all(on[s].subset == "lines" for s in gained), gained
    for s in gained:  # each is judged by what it fitted, within the verdict's limit
        assert on[s].failure is None
    score_off = evaluate_dataset(gt, {s: r.camera for s, r in off.items() if r.ok}, progress=False)
    score_on = evaluate_dataset(gt, {s: r.camera for s, r in on.items() if r.ok}, progress=False)
    assert score_on.completeness > score_off.completeness
    assert score_on.final_score > score_off.final_score + 0.001
    # and the frames that had a camera are calibrated exactly as before with the search on
    some = [s for s in obs if off[s].ok][:40]
    assert all(calibrate(obs[s]).camera.allclose(off[s].camera) for s in some)


def test_the_app_card_says_the_camera_started_from_the_lines(shared_dir, tmp_path):
    """The app's calibration card of such a frame says where its camera came from (an annotation
    without its image: SN22 frame 01610, three corners in view and six lines)."""
    import zipfile

    from pnlviz.app.cards import calibration_card
    from pnlviz.app.state import AppState

    data = tmp_path / "set"
    data.mkdir()
    with zipfile.ZipFile(shared_dir / "data" / "sn22_test_subset" / "annotations.zip") as zf:
        name = next(n for n in zf.namelist() if n.endswith("01610.json"))
        (data / "01610.json").write_bytes(zf.read(name))
    st = AppState(data, edits=tmp_path / "edits")
    view = st.view("01610")
    assert view.result is not None and view.result.ok and view.result.subset == "lines"
    card = calibration_card(view, st)
    assert "too few keypoints for a homography: started from **its straight lines**" in card, card
