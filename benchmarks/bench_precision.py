"""Batching and half precision of the detector: how far do the detections move, and what does each
cost? The light default model on real frames, every setting against float32 one frame at a time.

    python benchmarks/bench_precision.py [--frames 48] [--batch 8] [--threads 1] [--device cpu]

Frames: the real WC14 train/val frames of ``../shared/data/wc14_real/trainval_300`` (resized to
960x540, as ``benchmarks/eval_real.py`` does), then the bundled sample's images. For each setting
it prints, over the keypoints and line ends both runs found, the median / p99 / max distance in
pixels of the frame, how many the two runs do not share (a peak on the threshold can go either
way), and milliseconds per frame; then what the user sees: each frame calibrated from both runs'
detections, and the largest distance between the two cameras' projections of the pitch (a 5 m
grid, inside the frame), median / p95 / max over the frames. On a CPU float16 runs slower than float32 (it is there for
GPUs: half the memory, tensor cores); its figures here say how much the detections move.
"""

from __future__ import annotations

import argparse
import resource
import time
from pathlib import Path

import cv2
import numpy as np
import torch

from pnlviz.calib.frame import FrameInputs, FrameSettings, calibrate_frame
from pnlviz.detect.run import Detector, resolve_device
from pnlviz.field import load_field_model, pitch_grid

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "data"
SIZE = (960, 540)


def load_frames(n: int) -> list[np.ndarray]:
    paths = sorted((SHARED / "wc14_real" / "trainval_300").glob("*.jpg"), key=lambda p: int(p.stem))
    paths += sorted((ROOT / "examples" / "sample").glob("*.jpg"))
    frames = []
    for p in paths[:n]:
        img = cv2.imread(str(p), cv2.IMREAD_COLOR)
        if img is not None:
            frames.append(cv2.resize(img, SIZE, interpolation=cv2.INTER_LINEAR) if img.shape[:2] != SIZE[::-1] else img)
    return frames


def run(det: Detector, frames: list[np.ndarray], batch: int) -> tuple[list, float]:
    det.detect(frames[:batch])  # warm-up: first-call allocations are not the setting's cost
    t0 = time.perf_counter()
    out = []
    for i in range(0, len(frames), batch):
        out += det.detect(frames[i:i + batch])
    return out, 1e3 * (time.perf_counter() - t0) / len(frames)


def compare(ref: list, other: list) -> tuple[np.ndarray, int, int]:
    """(distances of shared points, points in only one run, points in the reference)."""
    d, unshared, total = [], 0, 0
    for a, b in zip(ref, other):
        pa, pb = a.points_px(*SIZE), b.points_px(*SIZE)
        total += len(pa)
        unshared += len(pa.keys() ^ pb.keys())
        d += [np.hypot(pa[k][0] - pb[k][0], pa[k][1] - pb[k][1]) for k in pa.keys() & pb.keys()]
    return np.asarray(d), unshared, total


def cameras(preds: list, calibration: dict) -> list:
    model, settings = load_field_model(), FrameSettings(source="detections", detection_settings=calibration)
    out = []
    for p in preds:
        fc = calibrate_frame(FrameInputs(SIZE, None, p, None), settings, model)
        out.append(fc.result.camera if fc.ok else None)
    return out


def camera_gaps(ref: list, other: list) -> tuple[np.ndarray, int]:
    """Per frame calibrated in both: the largest gap (px) between the two projections of the
    pitch grid points inside the frame; and how many frames only one run calibrated."""
    grid, gaps, one = pitch_grid(), [], 0
    for a, b in zip(ref, other):
        if (a is None) != (b is None):
            one += 1
        if a is None or b is None:
            continue
        pa, pb = a.project(grid), b.project(grid)
        inside = a.in_image(pa) & np.isfinite(pb).all(axis=1)
        if inside.any():
            gaps.append(float(np.linalg.norm(pa - pb, axis=1)[inside].max()))
    return np.asarray(gaps), one


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, default=48)
    ap.add_argument("--batch", type=int, default=8)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--device", default="cpu")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    device = resolve_device(args.device)
    frames = load_frames(args.frames)
    settings = [("float32, batch 1", 1, False), (f"float32, batch {args.batch}", args.batch, False),
                ("float16, batch 1", 1, True), (f"float16, batch {args.batch}", args.batch, True)]
    print(f"{len(frames)} real frames at {SIZE[0]}x{SIZE[1]}, light default model, device {device}, "
          f"{args.threads} torch thread(s)")
    ref = None
    for name, batch, half in settings:
        det = Detector.from_weights(None, None, device=device, half=half)
        out, ms = run(det, frames, batch)
        if ref is None:
            ref, ref_ms, ref_cams = out, ms, cameras(out, det.calibration)
            print(f"{name:18s}  reference, {ms:6.1f} ms/frame; {sum(c is not None for c in ref_cams)} frames calibrated")
            continue
        d, unshared, total = compare(ref, out)
        gaps, one = camera_gaps(ref_cams, cameras(out, det.calibration))
        print(f"{name:18s}  points moved: median {np.median(d):.4f} px, p99 {np.percentile(d, 99):.4f}, "
              f"max {d.max():.4f}, {np.sum(d > 1)} over 1 px; {unshared} of {total} not in both; "
              f"{ms:6.1f} ms/frame ({ms / ref_ms:.2f}x)")
        print(f"{'':18s}  pitch projections moved: median {np.median(gaps):.3f} px, p95 {np.percentile(gaps, 95):.3f}, "
              f"max {gaps.max():.3f} over {len(gaps)} frames, {np.sum(gaps > 1)} over 1 px; "
              f"{one} calibrated by one run only")
    print(f"peak memory: {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB")


if __name__ == "__main__":
    main()
