"""Where the shot model's robust loss bends (``TemporalParams.robust``), chosen on tuning clips only.

    python benchmarks/tune_shot_loss.py [--seeds 11-16] [--frames 120] [--bends 0.5,1,1.5,2,3]

**Protocol.** The seeds are tuning seeds (``bench_clip_edits.TUNING_SEEDS``; any other is refused):
figures printed here chose a setting and are never reported as results. Each seed draws a synthetic
clip (``pnlviz synth --clip``, 960x540), detected with the light default model on one thread
once; for each bend, every frame is calibrated on its own and the clip temporally
(:func:`pnlviz.calib.temporal.calibrate_clip_frames`). Against the true cameras,
per calibration: the median over frames of each frame's view change from its true camera (the
median distance, px, of the 5 m pitch grid points in view: :func:`pnlviz.calib.cuts.view_change`,
the measure shots are cut by); the share of frames above 5 px; the frames without a camera; the
jitter median, clip by clip (:mod:`pnlviz.metrics.temporal`); the temporal pass's time. The clips
are made and calibrated as ``bench_temporal.py`` makes and calibrates its synthetic clips.

The default (1.5 noise units) was chosen with it on 2026-12-07, seeds 11-13 and 14-16 run apart:
the smallest bend with no frame left without a camera on either set (below it, shots' solves stop
short and frames of seeds 14-16 lose their camera). The reported seeds were not used to choose;
the real TS-WorldCup clips had been probed with a bend of 1.5 before (docs/video.md says so).
"""

from __future__ import annotations

import argparse
import resource
import shutil
import sys
import tempfile
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_clip_edits import TUNING_SEEDS, parse_seeds  # noqa: E402
from bench_temporal import jitter_by_clip, per_frame_and_temporal, render_and_detect  # noqa: E402


def row(name: str, cams: dict, truth: dict, seconds: float | None = None) -> str:
    """One line of the table: ``cams`` against ``truth`` (both ``{stem: Camera | None}``)."""
    from pnlviz.calib.cuts import view_change

    e = np.array([view_change(truth[s], cam) for s, cam in cams.items() if cam is not None])
    j = jitter_by_clip(cams)
    none = sum(c is None for c in cams.values())
    took = "" if seconds is None else f" {seconds:.2f} |"
    return f"| {name} | {np.median(e):.3f} | {np.mean(e > 5):.3f} | {none} | {np.median(j):.3f} |{took}"


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

    from pnlviz.calib.shot import TemporalParams

    torch.set_num_threads(1)
    cv2.setNumThreads(1)
    tmp = Path(tempfile.mkdtemp())
    try:
        _, inputs, truth, changes, calibration, render_s, detect_s = render_and_detect(tmp, seeds, args.frames)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    print(f"tuning seeds {seeds}, {args.frames} frames each: rendered in {render_s:.0f} s, "
          f"detected in {detect_s:.0f} s")
    print("| calibration | frame error median (px) | frames > 5 px | no camera | jitter median (px) | seconds |")
    print("|---|---|---|---|---|---|")
    for k, bend in enumerate(float(b) for b in args.bends.split(",")):
        per, temp, _, seconds = per_frame_and_temporal(inputs, (960, 540), calibration, changes,
                                                       TemporalParams(robust=bend))
        if k == 0:
            print(row("per frame", per, truth))
        print(row(f"temporal, bend {bend:g}", temp, truth, seconds))
    print(f"peak memory (ru_maxrss): {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
