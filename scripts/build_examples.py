"""Rebuild the bundled sample in ``examples/sample`` and its contact sheet.

    python scripts/build_examples.py [--shared ../shared]

* 24 synthetic frames from ``pnlviz synth`` (seed 2026) with their ground-truth cameras;
* a few real annotated frames from ``../shared/data`` (SoccerNet 2022 test and WorldCup 2014 test,
  annotations only: they have no image, the app and ``pnlviz sheet`` draw them on a neutral
  canvas), named ``sn22_<stem>.json`` / ``wc14_<stem>.json``;
* the real WC14 frame ``wc14_trainval_16.jpg`` with a camera decomposed from its ground-truth
  homography (``cameras/camera_wc14_trainval_16.json``, at the 960x540 evaluation scale).

Then ``examples/contact_sheet.jpg``: the synthetic frames with the ground-truth pitch overlaid.
"""

from __future__ import annotations

import argparse
import json
import shutil
import zipfile
from pathlib import Path

import cv2

from pnlviz.data import read_homographies, write_camera_json
from pnlviz.field import load_field_model
from pnlviz.geometry import Camera
from pnlviz.geometry.homography import camera_from_ground_homography, field_to_image_from_template
from pnlviz.synth import generate
from pnlviz.viz import caption, contact_sheet, draw_pitch

ROOT = Path(__file__).resolve().parent.parent
SAMPLE = ROOT / "examples" / "sample"
SHEET = ROOT / "examples" / "contact_sheet.jpg"
N_SYNTH, SEED = 24, 2026
SN22_STEMS = ["00004", "00097", "00187", "00250"]  # varied views: goal mouth, centre circle, arcs
WC14_STEMS = ["3", "11", "17", "8"]


def copy_real(shared: Path) -> None:
    for zip_name, stems, prefix in (("sn22_test_subset/annotations.zip", SN22_STEMS, "sn22"),
                                    ("wc14_test_half/annotations.zip", WC14_STEMS, "wc14")):
        with zipfile.ZipFile(shared / "data" / zip_name) as zf:
            for stem in stems:
                (SAMPLE / f"{prefix}_{stem}.json").write_bytes(zf.read(f"{stem}.json"))
    frames = shared / "data" / "frames"
    shutil.copyfile(frames / "wc14_trainval_16.jpg", SAMPLE / "wc14_trainval_16.jpg")
    H_template = read_homographies(frames / "wc14_trainval_16_homography.json")["wc14_trainval_16"]
    H = field_to_image_from_template(H_template, load_field_model().template_to_field_matrix)
    cam = camera_from_ground_homography(H, 1280, 720, refine=True)
    d = cam.scaled(960, 540).to_soccernet()
    d["source"] = "decomposed from the WC14 ground-truth homography (square pixels, centred principal point)"
    write_camera_json(SAMPLE / "cameras" / "camera_wc14_trainval_16.json", d)


def make_sheet() -> None:
    tiles = []
    for i in range(12):
        stem = f"{i:05d}"
        img = cv2.imread(str(SAMPLE / f"{stem}.jpg"))
        cam_json = json.loads((SAMPLE / "cameras" / f"camera_{stem}.json").read_text())
        draw_pitch(img, Camera.from_soccernet(cam_json), thickness=2)
        tiles.append(caption(img, f"{stem} {cam_json['synth']['kind']}"))
    sheet = contact_sheet(tiles, columns=4, tile_width=400)
    cv2.imwrite(str(SHEET), sheet, [cv2.IMWRITE_JPEG_QUALITY, 85])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shared", type=Path, default=ROOT.parent / "shared")
    args = ap.parse_args()
    if SAMPLE.exists():
        shutil.rmtree(SAMPLE)
    generate(SAMPLE, N_SYNTH, SEED, progress=False)
    copy_real(args.shared)
    make_sheet()
    n = len(list(SAMPLE.glob("*.json")))
    print(f"wrote {SAMPLE} ({n} annotated frames) and {SHEET}")


if __name__ == "__main__":
    main()
