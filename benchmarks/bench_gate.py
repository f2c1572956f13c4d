"""The export's outlier gate on real frames: ``pnlviz detect`` (the light default model) then
``pnlviz export --all --detections ...`` on the 93 real WC14 test-half images, resized to 1280x720.

    python benchmarks/bench_gate.py [--gate-px 10] [--keep DIR]

Prints each command's time and peak memory, how many points the export flagged, and, checked here
independently of the export (each label against the camera exported beside it): how many points
were exported as visible ground truth (COCO v = 2) farther than the gate from their frame's
camera (must be 0), and how many would have been without the gate.
Needs ``../shared/data/wc14_real/test_half_256`` (the images).
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

from pnlviz import REPO_ROOT
from pnlviz.field.model import load_field_model
from pnlviz.geometry.camera import Camera

SIZE = (1280, 720)
IMAGES = REPO_ROOT.parent / "shared" / "data" / "wc14_real" / "test_half_256"


def resized(src: Path, dst: Path) -> int:
    """The images of ``src`` at 1280x720 in ``dst``; their number."""
    dst.mkdir(parents=True, exist_ok=True)
    n = 0
    for p in sorted(src.glob("*.jpg")):
        img = cv2.imread(str(p))
        cv2.imwrite(str(dst / p.name), cv2.resize(img, SIZE, interpolation=cv2.INTER_CUBIC),
                    [cv2.IMWRITE_JPEG_QUALITY, 95])
        n += 1
    return n


#: a pnlviz command in a child process that prints its own peak memory last
CHILD = ("import resource, sys\nfrom pnlviz.cli import main\nrc = main(sys.argv[1:])\n"
         "print('PEAK', resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)\nsys.exit(rc)")


def run(cmd: list[str]) -> tuple[float, float, str]:
    """(seconds, peak MB of the command's process, what it printed) of one pnlviz command."""
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-c", CHILD, *cmd], capture_output=True, text=True)
    dt = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(f"pnlviz {' '.join(cmd)} failed ({proc.returncode}):\n{proc.stdout}\n{proc.stderr}")
    said, peak = proc.stdout.rsplit("PEAK", 1)
    return dt, int(peak) / 1024, said


def check(export: Path, gate_px: float) -> dict:
    """Every exported label against its frame's exported camera, independently of the export."""
    model = load_field_model()
    limit = gate_px * math.hypot(*SIZE) / math.hypot(960, 540)
    coco = json.loads((export / "coco_keypoints.json").read_text())
    v_of = {im["stem"]: a["keypoints"] for im, a in zip(coco["images"], coco["annotations"])}
    out = {"frames": 0, "with_camera": 0, "visible_gt": 0, "visible_gt_beyond": 0, "flagged": 0,
           "beyond_without_gate": 0, "worst_gt_residual": 0.0}
    for kp_file in sorted((export / "keypoints").glob("*.json")):
        stem = kp_file.stem
        out["frames"] += 1
        cam_file = export / "cameras" / f"camera_{stem}.json"
        labels = json.loads(kp_file.read_text())["keypoints"]
        out["flagged"] += sum(1 for k in labels.values() if k["flagged"])
        if not cam_file.is_file():
            continue
        out["with_camera"] += 1
        cam = Camera.from_soccernet(json.loads(cam_file.read_text())).scaled(*SIZE)
        for key, k in labels.items():
            kid = int(key)
            xyz = model.keypoint_xyz([kid], pnlcalib=k["provenance"] == "detection")
            uv = cam.project(xyz)
            r = float(np.hypot(*(uv[0] - [k["x"], k["y"]])))
            r = r if math.isfinite(r) else math.inf
            visible = 0 <= k["x"] < SIZE[0] and 0 <= k["y"] < SIZE[1]
            if visible and r > limit and k["provenance"] != "hand":
                out["beyond_without_gate"] += 1
            if v_of[stem][3 * (kid - 1) + 2] == 2:
                out["visible_gt"] += 1
                out["worst_gt_residual"] = max(out["worst_gt_residual"], r)
                out["visible_gt_beyond"] += r > limit
    return out


def work_folder(ap: argparse.ArgumentParser, prefix: str) -> tuple[argparse.Namespace, Path]:
    """The arguments (``--keep`` added) and the folder to work in, once the real frames are there."""
    ap.add_argument("--keep", type=Path, help="work here (kept) instead of a temporary folder")
    args = ap.parse_args()
    if not IMAGES.is_dir():
        raise SystemExit(f"needs {IMAGES} (the real WC14 test-half images)")
    return args, args.keep or Path(tempfile.mkdtemp(prefix=prefix))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--gate-px", type=float, default=10.0)
    args, tmp = work_folder(ap, "pnlviz-gate-")
    try:
        frames, preds, export = tmp / "frames", tmp / "preds.zip", tmp / "export"
        n = resized(IMAGES, frames)
        t_det, m_det, _ = run(["detect", "--data", str(frames), "--out", str(preds), "--no-progress", "--settings",
                               str(preds.with_suffix(".json"))])  # its settings beside the zip: export applies them
        shutil.rmtree(export, ignore_errors=True)
        t_exp, m_exp, said = run(["export", "--data", str(frames), "--detections", str(preds), "--edits",
                                  str(tmp / "edits"), "--out", str(export), "--all", "--no-progress",
                                  "--gate-px", str(args.gate_px)])
        c = check(export, args.gate_px)
        manifest = json.loads((export / "manifest.json").read_text())
        print(f"{n} real WC14 test-half frames at {SIZE[0]}x{SIZE[1]}, gate {args.gate_px:g} px at 960x540 "
              f"({args.gate_px * math.hypot(*SIZE) / math.hypot(960, 540):.1f} px here)")
        print(f"pnlviz detect (light default model): {t_det:.1f} s, peak {m_det:.0f} MB")
        print(f"pnlviz export --all --detections: {t_exp:.1f} s, peak {m_exp:.0f} MB; it says: {said.strip()}")
        print(f"frames exported {c['frames']}, with a camera {c['with_camera']}")
        print(f"points exported as visible ground truth: {c['visible_gt']}, farther than the gate from their "
              f"camera: {c['visible_gt_beyond']} (worst {c['worst_gt_residual']:.1f} px)")
        print(f"points flagged by the gate: {c['flagged']} (manifest: {manifest['flagged']}; frames with one: "
              f"{sum(1 for e in manifest['frames'].values() if e.get('flagged'))}); beyond the gate, checked here: "
              f"{c['beyond_without_gate']}")
    finally:
        if args.keep is None:
            shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
