"""The light default model on held-out synthetic frames and on the two real frames.

    python benchmarks/eval_light.py [--frames 60] [--seed 777] [--out picture.jpg] [--weights F]

1. ``pnlviz synth`` frames with a seed not used in training (the training recipe uses data seed 5);
2. detections with the default model -> PCK@5 / PCK@10 px (keypoints 1-57 of the label generator
   that lie in the image, at 960x540, with the left-right disambiguation the network is trained
   with) and line extremities: recall (a true line whose detected ends are both within 10 px of
   its annotated extremities, either order) and precision (detected lines that are such hits);
3. ``pnlviz calibrate --detections`` with the detector's calibration settings -> JaC / CR / FS
   under the official metric against the synthetic annotations (required: FS@5 >= 0.70);
4. with ``--out``, a picture of what it finds on ../shared/data/frames (messi_sample.png, and
   wc14_trainval_16.jpg, which the default model was trained on: see benchmarks/eval_real.py for
   real frames it has not seen).
Prints the figures and the peak memory.
"""

from __future__ import annotations

import argparse
import resource
import shutil
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

from pnlviz.calib.frame import FrameInputs, FrameSettings, calibrate_frame
from pnlviz.calib.looks import detect_kept, kept_reading
from pnlviz.data import open_dataset
from pnlviz.detect.run import DEFAULT_MODEL, Detector, light_detector
from pnlviz.labels import LabelParams, keypoints_from_annotation, line_extremities
from pnlviz.metrics.soccernet import evaluate_dataset
from pnlviz.synth import generate
from pnlviz.viz import caption, contact_sheet

ROOT = Path(__file__).resolve().parents[1]


def draw_detections(img: np.ndarray, pred, *, ids: bool = True, line_width: int = 2) -> np.ndarray:
    """A copy of ``img`` with the detected line extremities joined (white) and the keypoints
    coloured by set (with their ids unless ``ids`` is False)."""
    from pnlviz.app.overlay import SET_BGR
    from pnlviz.field import load_field_model

    model = load_field_model()
    H, W = img.shape[:2]
    out = img.copy()
    for x1, y1, p1, x2, y2, p2 in pred.lines_px(W, H).values():
        cv2.line(out, (int(x1), int(y1)), (int(x2), int(y2)), (255, 255, 255), line_width, cv2.LINE_AA)
    for kid, (x, y, p) in pred.keypoints_px(W, H).items():
        col = SET_BGR.get(model.keypoints[kid].group, (255, 255, 255))
        cv2.circle(out, (int(x), int(y)), 6, (0, 0, 0), 2, cv2.LINE_AA)
        cv2.circle(out, (int(x), int(y)), 5, col, -1, cv2.LINE_AA)
        if not ids:
            continue
        cv2.putText(out, str(kid), (int(x) + 7, int(y) - 7), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 0), 3, cv2.LINE_AA)
        cv2.putText(out, str(kid), (int(x) + 7, int(y) - 7), cv2.FONT_HERSHEY_SIMPLEX, 0.5, col, 1, cv2.LINE_AA)
    return out


def evaluate_synthetic(det: Detector, frames: int, seed: int) -> dict:
    """Steps 1-3 of the module docstring on ``frames`` frames of data seed ``seed``; prints and
    returns the figures."""
    tmp = Path(tempfile.mkdtemp())
    data = tmp / "heldout"
    generate(data, frames, seed, progress=False)
    ds = open_dataset(data)
    hits5 = hits10 = total = 0
    line_hits = line_total = line_found = 0
    cams, times = {}, []
    for stem in ds.stems:
        img = ds.image(stem)
        t0 = time.perf_counter()
        pred = det.detect([img])[0]
        times.append(time.perf_counter() - t0)
        pred = kept_reading(pred, img, det)  # the second look, where needed
        H, W = img.shape[:2]
        ann = ds.annotation(stem)
        labels = keypoints_from_annotation(ann, W, H, LabelParams(lr_disambiguation=True))
        found = pred.keypoints_px(W, H)
        lines = pred.lines_px(W, H)
        line_found += len(lines)
        for lid, ext in line_extremities(ann, W, H, mirror=labels.mirrored).items():
            line_total += 1
            if lid in lines:
                a, b = np.array(lines[lid][0:2]), np.array(lines[lid][3:5])
                err = min(max(np.linalg.norm(a - ext.p1), np.linalg.norm(b - ext.p2)),
                          max(np.linalg.norm(a - ext.p2), np.linalg.norm(b - ext.p1)))
                line_hits += err <= 10
        for kid, lab in labels.keypoints.items():
            if kid > 57 or not lab.visible:
                continue
            total += 1
            if kid in found:
                d = np.hypot(found[kid][0] - lab.x, found[kid][1] - lab.y)
                hits5 += d <= 5
                hits10 += d <= 10
        fc = calibrate_frame(FrameInputs((960, 540), detections=pred), FrameSettings(detection_settings=det.calibration))
        if fc.ok:
            cams[stem] = fc.result.camera
    s = evaluate_dataset(data, cams, progress=False)
    shutil.rmtree(tmp, ignore_errors=True)
    print(f"held-out synthetic frames: {len(ds.stems)} (seed {seed}), detection {1e3 * np.median(times):.0f} ms/frame")
    print(f"PCK@5 {hits5 / max(total, 1):.3f}  PCK@10 {hits10 / max(total, 1):.3f}  ({total} visible keypoints)")
    print(f"line extremities within 10 px: recall {line_hits / max(line_total, 1):.3f} ({line_total} true lines), "
          f"precision {line_hits / max(line_found, 1):.3f} ({line_found} detected)")
    print(f"calibration from detections: JaC@5 {s.jac(5):.3f} @10 {s.jac(10):.3f} @20 {s.jac(20):.3f} "
          f"CR {s.completeness:.3f} FS@5 {s.final_score:.3f}")
    return {"pck5": hits5 / max(total, 1), "pck10": hits10 / max(total, 1), "fs5": s.final_score}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--seed", type=int, default=777)
    ap.add_argument("--out", type=Path, default=None, help="write a picture of the detections on ../shared/data/frames")
    ap.add_argument("--shared", type=Path, default=ROOT.parent / "shared")
    ap.add_argument("--weights", type=Path, default=None, help=f"a LightNet checkpoint (default {DEFAULT_MODEL})")
    args = ap.parse_args()
    det = light_detector(args.weights) if args.weights else Detector.from_weights(None, None)
    print(f"model: {args.weights or DEFAULT_MODEL} (input {det.input_size[0]}x{det.input_size[1]})")
    evaluate_synthetic(det, args.frames, args.seed)
    tiles = []
    for name in ("messi_sample.png", "wc14_trainval_16.jpg") if args.out is not None else ():
        img = cv2.imread(str(args.shared / "data" / "frames" / name))
        if img is None:
            continue
        pred = detect_kept(det, img)
        tiles.append(caption(draw_detections(img, pred), f"{name}: {len(pred.keypoints)} keypoints, "
                                                          f"{len(pred.lines)} lines"))
    if tiles:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        cv2.imwrite(str(args.out), contact_sheet(tiles, columns=2, tile_width=800), [cv2.IMWRITE_JPEG_QUALITY, 85])
        print(f"wrote {args.out}")
    print(f"peak memory (ru_maxrss): {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB")


if __name__ == "__main__":
    main()
