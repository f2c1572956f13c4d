"""``pnlviz export --format gsr``: cameras and a tracker's boxes on the pitch, in the layout of
SoccerNet Game State Reconstruction's Labels-GameState.json, read back with the SoccerNet
package's own Camera."""

from __future__ import annotations

import json
import shutil

import cv2
import numpy as np
import pytest

from pnlviz import EXAMPLES_DIR
from pnlviz.cli import main

STEMS = ("sn22_00004", "sn22_00097", "sn22_00187")
SIX = {"x_bottom_left", "y_bottom_left", "x_bottom_middle", "y_bottom_middle", "x_bottom_right", "y_bottom_right"}


@pytest.fixture()
def hd_clip(tmp_path):
    """Three annotated SoccerNet frames with 1280x720 images (the cameras are then scaled from
    the 960x540 they are calibrated at)."""
    data = tmp_path / "clip"
    data.mkdir()
    for stem in STEMS:
        shutil.copy(EXAMPLES_DIR / "sample" / f"{stem}.json", data / f"{stem}.json")
        cv2.imwrite(str(data / f"{stem}.jpg"), np.zeros((720, 1280, 3), np.uint8))
    return data


def _feet(box):
    x, y, w, h = box
    return {"left": (x, y + h), "middle": (x + w / 2, y + h), "right": (x + w, y + h)}


BOXES = {1: [(1, 500.0, 400.0, 40.0, 110.0), (2, 800.0, 300.0, 30.0, 80.0)], 2: [(1, 300.0, 450.0, 45.0, 120.0)],
         3: [(-1, 640.0, 360.0, 25.0, 70.0)]}


def test_gsr_cameras_and_boxes_read_back_with_soccernets_camera_to_a_millimetre(hd_clip, tmp_path, evaluator):
    """Every box's six bbox_pitch numbers, projected by SoccerNet's Camera built from the written
    parameters, land on the box's bottom corners and middle; and the ground points SoccerNet's own
    projection puts under those pixels (solved numerically) are the written ones to 1 mm."""
    from scipy.optimize import least_squares

    mot = tmp_path / "tracks.txt"
    mot.write_text("".join(f"{f},{t},{x},{y},{w},{h},0.9,-1,-1,-1\n" for f, rows in BOXES.items()
                           for t, x, y, w, h in rows))
    out = tmp_path / "gsr.json"
    assert main(["export", "--data", str(hd_clip), "--all", "--format", "gsr", "--boxes", str(mot), "--out", str(out),
                 "--no-progress"]) == 0
    doc = json.loads(out.read_text())
    assert [im["stem"] for im in doc["images"]] == list(STEMS)
    assert [im["image_id"] for im in doc["images"]] == ["1", "2", "3"]  # strings: MOT frame n is the n-th frame
    assert all((im["width"], im["height"]) == (1280, 720) for im in doc["images"])
    cams = {a["image_id"]: a for a in doc["annotations"] if a["supercategory"] == "camera"}
    objs = [a for a in doc["annotations"] if a["supercategory"] == "object"]
    assert set(cams) == {"1", "2", "3"} and all(a["category_id"] == 6 for a in cams.values())
    assert len(objs) == 4 and all(isinstance(a["image_id"], str) and isinstance(a["id"], str) for a in objs)
    assert [a["track_id"] for a in objs] == [1, 2, 1, None]  # MOT's -1: no track
    worst_px, worst_m = 0.0, 0.0
    for a in objs:
        cam = evaluator.Camera()
        cam.from_json_parameters(cam_params := cams[a["image_id"]]["parameters"])
        assert cam_params["principal_point"][0] * 2 == pytest.approx(1280, abs=60)  # at the frame's own size
        b = a["bbox_image"]
        assert set(a["bbox_pitch"]) == SIX
        for side, (u, v) in _feet((b["x"], b["y"], b["w"], b["h"])).items():
            X, Y = a["bbox_pitch"][f"x_bottom_{side}"], a["bbox_pitch"][f"y_bottom_{side}"]
            px = np.asarray(cam.project_point(np.array([X, Y, 0.0])))[:2]
            worst_px = max(worst_px, float(np.hypot(px[0] - u, px[1] - v)))
            # SoccerNet's own projection inverted numerically, from a point 5 m away (its pixels are
            # float32: finite differences over 0.1 mm steps, not the default's 1e-8 relative)
            sol = least_squares(lambda p: np.asarray(cam.project_point(np.array([p[0], p[1], 0.0])))[:2] - (u, v),
                                x0=[X + 5.0, Y - 5.0], diff_step=1e-5, xtol=1e-12, ftol=1e-12, gtol=1e-12)
            worst_m = max(worst_m, float(np.hypot(sol.x[0] - X, sol.x[1] - Y)))
    assert worst_px < 1e-3
    assert worst_m < 1e-3


def test_gsr_from_coco_boxes_keeps_their_image_ids_and_roles(hd_clip, tmp_path):
    """COCO boxes: images matched to frames by file name, their ids kept (as strings), roles from
    the categories or the attributes; a box on an image of no frame is counted and said."""
    coco = {"images": [{"id": 1060000002, "file_name": "sn22_00097.jpg"}, {"id": 7, "file_name": "elsewhere.jpg"}],
            "annotations": [{"image_id": 1060000002, "bbox": [300, 450, 45, 120], "category_id": 2, "track_id": 4},
                            {"image_id": 1060000002, "bbox": [600, 300, 10, 10], "category_id": 9,
                             "attributes": {"role": "ball"}},
                            {"image_id": 7, "bbox": [1, 1, 5, 5], "category_id": 1}],
            "categories": [{"id": 1, "name": "player"}, {"id": 2, "name": "goalkeeper"}, {"id": 9, "name": "sports ball"}]}
    boxes = tmp_path / "boxes.json"
    boxes.write_text(json.dumps(coco))
    out = tmp_path / "gsr.json"
    assert main(["export", "--data", str(hd_clip), "--all", "--format", "gsr", "--boxes", str(boxes), "--out", str(out),
                 "--no-progress"]) == 0
    doc = json.loads(out.read_text())
    assert [im["image_id"] for im in doc["images"]] == ["1", "1060000002", "3"]
    objs = [a for a in doc["annotations"] if a["supercategory"] == "object"]
    assert [(a["image_id"], a["category_id"], a["attributes"]["role"], a["track_id"]) for a in objs] == [
        ("1060000002", 2, "goalkeeper", 4), ("1060000002", 4, "ball", None)]
    assert all(set(a["bbox_pitch"]) == SIX for a in objs)


def test_gsr_exports_only_reviewed_frames_and_says_what_it_left(hd_clip, tmp_path, capsys):
    """Without --all only accepted or corrected frames are exported (none here): no camera is
    written, and the boxes on the frames left out are counted in a warning."""
    mot = tmp_path / "tracks.txt"
    mot.write_text("1,1,500,400,40,110\n2,1,300,450,45,120\n")
    out = tmp_path / "gsr.json"
    assert main(["export", "--data", str(hd_clip), "--format", "gsr", "--boxes", str(mot), "--out", str(out),
                 "--no-progress"]) == 0
    doc = json.loads(out.read_text())
    assert doc["images"] == [] and doc["annotations"] == []
    err = capsys.readouterr().err
    assert "2 box(es) on frames not exported" in err


@pytest.mark.parametrize("content, flags, message", [
    ("1,1,500,400,40,110\n", ["--format", "labels"], "--boxes: places a tracker's boxes on the pitch"),
    ("1,1,500,400,40,110\n", ["--format", "gsr", "--out-name", "gsr.zip"], "must end in .json with --format gsr"),
    ("1,1,500,400,-40,110\n", ["--format", "gsr"], "tracks.txt:1: a box's width and height must be positive"),
    ("1,1,500,400\n", ["--format", "gsr"], "tracks.txt:1: a MOT line has at least 6"),
    ("0,1,500,400,40,110\n", ["--format", "gsr"], "tracks.txt:1: the frame number must be a whole number from 1"),
    ("1,1,nan,400,40,110\n", ["--format", "gsr"], "a box needs four finite numbers"),
])
def test_bad_boxes_and_options_are_refused_before_anything_is_written(hd_clip, tmp_path, capsys, content, flags,
                                                                      message):
    mot = tmp_path / "tracks.txt"
    mot.write_text(content)
    name = flags[flags.index("--out-name") + 1] if "--out-name" in flags else "gsr.json"
    flags = [f for f in flags if f not in ("--out-name", name)]
    out = tmp_path / name
    before = sorted(p.name for p in tmp_path.iterdir())
    assert main(["export", "--data", str(hd_clip), "--all", "--boxes", str(mot), "--out", str(out), "--no-progress",
                 *flags]) == 2
    assert message in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == before  # nothing written
    assert mot.read_text() == content


def test_the_boxes_file_is_never_the_output(hd_clip, tmp_path, capsys):
    boxes = tmp_path / "boxes.json"
    boxes.write_text(json.dumps({"images": [], "annotations": []}))
    assert main(["export", "--data", str(hd_clip), "--all", "--format", "gsr", "--boxes", str(boxes), "--out",
                 str(boxes), "--no-progress"]) == 2
    assert "boxes.json" in capsys.readouterr().err
    assert json.loads(boxes.read_text()) == {"images": [], "annotations": []}
