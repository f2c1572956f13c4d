"""Where the shot model's robust loss bends (``TemporalParams.robust``), chosen on tuning clips only.

    python benchmarks/tune_shot_loss.py [--seeds 11-16] [--frames 120] [--bends 0.5,1,1.5,2,3]

**Protocol.** The seeds are tuning seeds (``bench_clip_edits.TUNING_SEEDS``; any other is refused):
figures printed here chose a setting and are never reported as results. Each seed draws a synthetic
clip (``pnlviz synth --clip``, 960x540), detected with the light default model on one thread;
every frame is calibrated on its own once, then the clip is calibrated temporally
(:func:`pnlviz.calib.temporal.calibrate_clip_frames`) once per bend. Against the true cameras,
per calibration: the median over frames of each frame's median distance (px) between a 5 m grid
of pitch points in view projected by the true camera and by the calibrated one; the share of
frames above 5 px; the frames without a camera; the jitter median (:mod:`pnlviz.metrics.temporal`);
the temporal pass's time.

The default (1.5 noise units) was chosen with it on 2026-12-07, seeds 11-13 and 14-16 run apart:
the smallest bend with no frame left without a camera on either set (below it, shots' solves stop
short and frames of seeds 14-16 lose their camera). The real TS-WorldCup clips and the reported
seeds were not used to choose (see docs/video.md).
"""

from __future__ import annotations

import argparse
import resource
import shutil
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_clip_edits import TUNING_SEEDS, parse_seeds  # noqa: E402


def detected_clips(seeds: list[int], frames: int):
    """The clips of ``seeds`` rendered and detected: per clip its frames' inputs, true cameras and
    image changes, in frame order."""
    from pnlviz.calib.frame import FrameInputs
    from pnlviz.calib.looks import detect_kept
    from pnlviz.calib.temporal import image_change
    from pnlviz.data import open_dataset
    from pnlviz.detect.run import Detector
    from pnlviz.geometry.camera import Camera
    from pnlviz.synth import generate

    det = Detector.from_weights(None, None)
    clips = []
    for seed in seeds:
        tmp = Path(tempfile.mkdtemp())
        try:
            generate(tmp, frames, seed, clip=True, progress=False, force=True)
            ds = open_dataset(tmp)
            inputs, truth, changes, prev = [], [], [], None
            for s in ds.stems:
                img = ds.image(s)
                changes.append(None if prev is None else image_change(prev, img))
                prev = img
                inputs.append(FrameInputs((img.shape[1], img.shape[0]), detections=detect_kept(det, img)))
                truth.append(Camera.from_soccernet(ds.camera_dict(s), 960, 540))
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
        clips.append((inputs, truth, changes[1:]))
    return clips, det.calibration


def frame_errors(cams, truth) -> np.ndarray:
    """Per frame with a camera: the median distance (px, 960x540) between a 5 m grid of pitch points
    in the true camera's view as the true camera and as ``cam`` put them (infinite for a point
    ``cam`` has behind it)."""
    gx, gy = np.meshgrid(np.arange(-50.0, 55.0, 5.0), np.arange(-32.5, 35.0, 5.0))
    grid = np.column_stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)])
    out = []
    for cam, gt in zip(cams, truth):
        if cam is None:
            continue
        a = gt.project(grid)
        seen = np.all(np.isfinite(a), axis=1) & (a[:, 0] >= 0) & (a[:, 0] < 960) & (a[:, 1] >= 0) & (a[:, 1] < 540)
        if seen.any():
            d = np.linalg.norm(cam.scaled(960, 540).project(grid[seen]) - a[seen], axis=1)
            out.append(float(np.median(np.where(np.isfinite(d), d, np.inf))))  # behind the camera: missed
    return np.array(out)


def row(name: str, cams: list, truth: list, seconds: float | None = None) -> str:
    from pnlviz.metrics.temporal import jitter

    e = frame_errors(cams, truth)
    j = jitter(cams)
    j = j[np.isfinite(j)]
    none = sum(c is None for c in cams)
    took = "" if seconds is None else f" {seconds:.2f} |"
    return (f"| {name} | {np.median(e):.3f} | {np.mean(e > 5):.3f} | {none} | {np.median(j):.3f} |{took}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="11-16", help="tuning seeds only (default 11-16)")
    ap.add_argument("--frames", type=int, default=120, help="frames per clip (default 120)")
    ap.add_argument("--bends", default="0.5,1,1.5,2,3", help="bends to try, in noise units")
    args = ap.parse_args(argv)
    seeds = parse_seeds(args.seeds)
    outside = [s for s in seeds if s not in TUNING_SEEDS]
    if outside:
        print(f"seeds {outside} are not tuning seeds ({TUNING_SEEDS.start}-{TUNING_SEEDS.stop - 1}): a setting is "
              "chosen on those only", file=sys.stderr)
        return 2
    import torch

    from pnlviz.calib.frame import FrameSettings, calibrate_frame
    from pnlviz.calib.shot import TemporalParams
    from pnlviz.calib.temporal import calibrate_clip_frames
    from pnlviz.field import load_field_model

    torch.set_num_threads(1)
    cv2.setNumThreads(1)
    t0 = time.perf_counter()
    clips, calibration = detected_clips(seeds, args.frames)
    print(f"tuning seeds {seeds}, {args.frames} frames each: rendered and detected in {time.perf_counter() - t0:.0f} s")
    model, settings = load_field_model(), FrameSettings(detection_settings=calibration)
    own = [[calibrate_frame(i, settings, model).camera for i in inputs] for inputs, _, _ in clips]
    truth = [t for _, gt, _ in clips for t in gt]
    print("| calibration | frame error median (px) | frames > 5 px | no camera | jitter median (px) | seconds |")
    print("|---|---|---|---|---|---|")
    print(row("per frame", [c for cams in own for c in cams], truth))
    for bend in (float(b) for b in args.bends.split(",")):
        t0 = time.perf_counter()
        cams = []
        for (inputs, _, changes), mine in zip(clips, own):
            fit = calibrate_clip_frames(inputs, settings, cameras=mine, changes=changes, model=model,
                                        temporal=TemporalParams(robust=bend))
            cams += fit.result.cameras
        print(row(f"temporal, bend {bend:g}", cams, truth, time.perf_counter() - t0))
    print(f"peak memory (ru_maxrss): {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
