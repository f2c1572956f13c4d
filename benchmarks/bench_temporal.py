"""Temporal calibration against per-frame calibration, on real and synthetic clips.

    python benchmarks/bench_temporal.py [--synthetic 3] [--frames 120] [--seed 101] [--real-only]

1. **Real TS-WorldCup clips** (``../shared/data/tswc_clips/detections_pnlcalib.zip``: the published
   PnLCalib network's detections of 4 clips, 361 frames at 1280x720, no ground truth):
   ``pnlviz calibrate --detections ... --size 1280x720`` with and without ``--temporal``. Prints
   completeness, the jitter (:mod:`pnlviz.metrics.temporal`, 960x540) and the median keypoint
   residual (detected keypoints against their reprojection, 960x540 px): the temporal cameras
   must not lag behind the real motion.
2. **Synthetic clips** (``pnlviz synth --clip``, seeds ``--seed`` .. ``--seed + N - 1``; no
   setting was chosen on them): the light default detector's detections, calibrated per frame and
   temporally; the official metric (FS@5) against the clips' annotations, the jitter, and the
   ground truth's own jitter.

Also the time of the temporal pass and the peak memory. Runs on one core (torch and OpenCV
threads set to 1).
"""

from __future__ import annotations

import argparse
import resource
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def _clip_groups(stems):
    from pnlviz.data.layout import video_clips

    return video_clips(stems)


def per_frame_and_temporal(inputs: dict, size, detection_settings: dict, changes: dict | None = None,
                           temporal=None):
    """``{stem: FrameInputs}`` -> (per-frame cameras, temporal cameras, observations, seconds of the
    temporal pass), all ``{stem: Camera | None}`` at ``size``, clip by clip as ``pnlviz calibrate
    --temporal`` does (:func:`pnlviz.calib.temporal.calibrate_clip_frames`); ``detection_settings``:
    the detector's calibration settings; ``changes``: ``{stem: image change from the previous
    frame}`` (as the command measures when the frames have images); ``temporal``: the shot model's
    :class:`~pnlviz.calib.shot.TemporalParams` (None: its defaults)."""
    from pnlviz.calib.frame import FrameSettings, calibrate_frame
    from pnlviz.calib.shot import TemporalParams
    from pnlviz.calib.temporal import calibrate_clip_frames
    from pnlviz.field import load_field_model

    model = load_field_model()
    settings = FrameSettings(detection_settings=detection_settings)
    per, temp, obs = {}, {}, {}
    seconds = 0.0
    for clip, members in _clip_groups(inputs).items():
        frames = [inputs[s] for s in members]
        cams = []
        for i in frames:  # the per-frame pass, timed apart from the temporal one
            fc = calibrate_frame(i, settings, model)
            cams.append(fc.result.camera if fc.ok else None)
        t0 = time.perf_counter()
        ch = [changes.get(s) for s in members[1:]] if changes else None
        fit = calibrate_clip_frames(frames, settings, cameras=cams, changes=ch, model=model,
                                    temporal=temporal or TemporalParams())
        seconds += time.perf_counter() - t0
        for s, a, b, ob in zip(members, cams, fit.result.cameras, fit.observations):
            per[s], temp[s], obs[s] = a, b, ob
    return per, temp, obs, seconds


def _residual(cams: dict, obs: dict, scale: float) -> float:
    r = []
    for s, cam in cams.items():
        o = obs.get(s)
        if cam is None or o is None or o.n_keypoints == 0:
            continue
        uv = cam.project(o.kp_xyz)
        r.append(np.linalg.norm(uv - o.kp_xy, axis=1) * scale)
    return float(np.median(np.concatenate(r))) if r else float("nan")


def jitter_by_clip(cams: dict) -> np.ndarray:
    """The jitter of ``{stem: Camera | None}``, clip by clip (no triple across two clips)."""
    from pnlviz.metrics.temporal import jitter

    out = []
    for members in _clip_groups(cams).values():
        j = jitter([cams[s] for s in members])
        out.append(j[np.isfinite(j)])
    return np.concatenate(out) if out else np.zeros(0)


def real_clips(shared: Path) -> None:
    from pnlviz.calib.frame import FrameInputs
    from pnlviz.data import read_predictions

    path = shared / "data" / "tswc_clips" / "detections_pnlcalib.zip"
    if not path.is_file():
        print(f"no real clips at {path}", file=sys.stderr)
        return
    preds = read_predictions(path)
    size = (1280, 720)
    inputs = {s: FrameInputs(size, detections=p) for s, p in preds.items()}
    per, temp, obs, seconds = per_frame_and_temporal(inputs, size, {})
    n = len(inputs)
    jp, jt = jitter_by_clip(per), jitter_by_clip(temp)
    print(f"real TS-WorldCup clips: {len(_clip_groups(inputs))} clips, {n} frames (PnLCalib's detections, 1280x720)")
    print("| calibration | CR | jitter median (px) | jitter p90 (px) | keypoint residual median (px) |")
    print("|---|---|---|---|---|")
    for name, cams, j in (("per frame", per, jp), ("temporal", temp, jt)):
        cr = sum(c is not None for c in cams.values()) / n
        print(f"| {name} | {cr:.3f} | {np.median(j):.2f} | {np.percentile(j, 90):.2f} | "
              f"{_residual(cams, obs, 960 / 1280):.2f} |")
    print(f"temporal pass: {seconds:.2f} s for {n} frames ({1e3 * seconds / n:.1f} ms/frame)")


def render_and_detect(root: Path, seeds, frames: int):
    """Synthetic clips of ``seeds`` (``pnlviz synth --clip``, 960x540) made in ``root`` and detected
    with the light default model: (dataset, ``{stem: FrameInputs}``, ``{stem: true Camera}``,
    ``{stem: image change from the previous frame}``, the detector's calibration settings,
    seconds rendering, seconds detecting)."""
    from pnlviz.calib.frame import FrameInputs
    from pnlviz.calib.looks import detect_kept
    from pnlviz.calib.temporal import image_change
    from pnlviz.data import open_dataset
    from pnlviz.detect.run import Detector
    from pnlviz.geometry.camera import Camera
    from pnlviz.synth import generate

    det = Detector.from_weights(None, None)
    inputs, truth, changes = {}, {}, {}
    t0 = time.perf_counter()
    for seed in seeds:
        generate(root, frames, seed, clip=True, progress=False, force=True)
    ds = open_dataset(root)
    render_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    prev = None
    for s in ds.stems:  # clip by clip, in frame order
        img = ds.image(s)
        if prev is not None:
            changes[s] = image_change(prev, img)
        prev = img
        pred = detect_kept(det, img)
        inputs[s] = FrameInputs((img.shape[1], img.shape[0]), detections=pred)
        truth[s] = Camera.from_soccernet(ds.camera_dict(s), 960, 540)
    return ds, inputs, truth, changes, det.calibration, render_s, time.perf_counter() - t0


def synthetic_clips(n_clips: int, frames: int, seed: int) -> None:
    from pnlviz.metrics.soccernet import evaluate_dataset

    tmp = Path(tempfile.mkdtemp())
    ds, inputs, truth, changes, calibration, render_s, detect_s = render_and_detect(
        tmp, range(seed, seed + n_clips), frames)
    per, temp, obs, seconds = per_frame_and_temporal(inputs, (960, 540), calibration, changes)
    print(f"synthetic clips: {n_clips} x {frames} frames (seeds {seed}-{seed + n_clips - 1}), light default detector; "
          f"rendering {render_s:.0f} s, detection {detect_s:.0f} s")
    print("| calibration | FS@5 | JaC@5 | CR | jitter median (px) | jitter p90 (px) |")
    print("|---|---|---|---|---|---|")
    jtrue = jitter_by_clip(truth)
    for name, cams in (("per frame", per), ("temporal", temp)):
        s = evaluate_dataset(ds, {k: v for k, v in cams.items() if v is not None}, progress=False)
        j = jitter_by_clip(cams)
        print(f"| {name} | {s.final_score:.3f} | {s.jac(5):.3f} | {s.completeness:.3f} | {np.median(j):.2f} | "
              f"{np.percentile(j, 90):.2f} |")
    print(f"| ground truth | | | | {np.median(jtrue):.2f} | {np.percentile(jtrue, 90):.2f} |")
    print(f"temporal pass: {seconds:.2f} s for {len(inputs)} frames")
    import shutil

    shutil.rmtree(tmp, ignore_errors=True)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shared", type=Path, default=ROOT.parent / "shared")
    ap.add_argument("--synthetic", type=int, default=3, help="synthetic clips (default 3)")
    ap.add_argument("--frames", type=int, default=120, help="frames per synthetic clip (default 120)")
    ap.add_argument("--seed", type=int, default=201, help="first synthetic clip seed (default 201)")
    ap.add_argument("--real-only", action="store_true")
    args = ap.parse_args(argv)
    import torch

    torch.set_num_threads(1)
    cv2.setNumThreads(1)
    real_clips(args.shared)
    if not args.real_only and args.synthetic > 0:
        synthetic_clips(args.synthetic, args.frames, args.seed)
    print(f"peak memory (ru_maxrss): {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
