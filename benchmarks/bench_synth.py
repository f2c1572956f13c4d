"""Synthetic frame throughput: render + annotate + write (JPEG, JSON, camera) with one worker.

    python benchmarks/bench_synth.py [--frames 20] [--size 960x540] [--seed 0] [--one-thread]

For a strictly one-core figure: ``taskset -c 0 python benchmarks/bench_synth.py --one-thread``.

Prints frames/s, ms per frame, the split between rendering and annotating, and the peak
resident memory (``resource.getrusage(RUSAGE_SELF).ru_maxrss``).
"""

from __future__ import annotations

import argparse
import resource
import sys
import tempfile
import time

import numpy as np

from pnlviz.synth.annotate import annotate
from pnlviz.synth.cameras import sample_camera
from pnlviz.commands.common import parse_size
from pnlviz.synth.render import render_frame
from pnlviz.synth.writer import generate


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=20)
    ap.add_argument("--size", type=parse_size, default=(960, 540))
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--one-thread", action="store_true", help="cv2.setNumThreads(1)")
    args = ap.parse_args(argv)
    import cv2

    if args.one_thread:
        cv2.setNumThreads(1)

    generate(tempfile.mkdtemp(prefix="bench_synth_warm_"), 1, args.seed + 1, size=args.size, progress=False)
    with tempfile.TemporaryDirectory(prefix="bench_synth_") as out:
        summary = generate(out, args.frames, args.seed, size=args.size, progress=False)
    # Where the time goes (same frames, nothing written).
    t_cam = t_render = t_ann = 0.0
    for i in range(args.frames):
        rng = np.random.default_rng([args.seed, i])
        t0 = time.perf_counter()
        camera, _ = sample_camera(rng, *args.size)
        t1 = time.perf_counter()
        render_frame(camera, rng)
        t2 = time.perf_counter()
        annotate(camera, rng)
        t3 = time.perf_counter()
        t_cam, t_render, t_ann = t_cam + t1 - t0, t_render + t2 - t1, t_ann + t3 - t2
    n = max(args.frames, 1)
    maxrss_kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss  # kilobytes on Linux
    w, h = args.size
    print(f"synth {args.frames} frames {w}x{h}, 1 worker ({cv2.getNumThreads()} OpenCV threads): {summary.frames_per_second:.2f} frames/s "
          f"({1000 * summary.seconds / n:.0f} ms/frame incl. JPEG + JSON writes)")
    print(f"  camera sampling {1000 * t_cam / n:.1f} ms, render {1000 * t_render / n:.1f} ms, "
          f"annotate {1000 * t_ann / n:.1f} ms per frame")
    print(f"  peak memory (ru_maxrss): {maxrss_kb / 1024:.0f} MB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
