"""Memory of ``pnlviz serve`` as a tab walks through a large dataset, and after it leaves.

A dataset of N frames (default 2,000: the bundled sample's images and annotations linked under
new names, so each frame is decoded and calibrated for real) is served in this process; a tab
(the app's own session, as a browser tab has) steps through the first V frames (default 1,000).
The resident set size (RSS) is printed every 100 frames, then after the tab leaves. The goal:
at most 150 MB above the start while walking, back near the start once no tab is left.

    python benchmarks/bench_serve_memory.py [--frames 2000] [--visit 1000]

The background pass (triage: every frame calibrated, a small summary kept per frame) runs
meanwhile, as in ``pnlviz serve``; no detector (the frames have annotations).
"""

from __future__ import annotations

import argparse
import gc
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))


def rss_mb() -> float:
    """This process's resident set size, MB (from /proc)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def make_dataset(folder: Path, n: int) -> Path:
    """``n`` frames linked from the bundled sample (image + annotation pairs, cycled)."""
    from pnlviz import SAMPLE_DIR

    pairs = [(p, p.with_suffix(".json")) for p in sorted(SAMPLE_DIR.glob("*.jpg")) if p.with_suffix(".json").exists()]
    folder.mkdir(parents=True)
    for i in range(n):
        image, annotation = pairs[i % len(pairs)]
        for src, ext in ((image, ".jpg"), (annotation, ".json")):
            dst = folder / f"{i:05d}{ext}"
            try:
                os.link(src, dst)
            except OSError:
                dst.write_bytes(src.read_bytes())
    return folder


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, default=2000)
    ap.add_argument("--visit", type=int, default=1000)
    args = ap.parse_args()
    from helpers import running_app

    with tempfile.TemporaryDirectory() as tmp:
        data = make_dataset(Path(tmp) / "set", args.frames)
        with running_app(data) as app:
            before = rss_mb()
            tab = app.session()  # the tab opens on its first frame (the engine's imports are in from here)
            gc.collect()
            start = rss_mb()
            print(f"serve on {args.frames} frames: {before:.0f} MB before a tab, {start:.0f} MB with one tab "
                  f"on its first frame (the start)")
            t0, peak = time.perf_counter(), start
            for k in range(1, args.visit + 1):
                tab.step(1)
                if k % 100 == 0:
                    now = rss_mb()
                    peak = max(peak, now)
                    print(f"  {k:5d} frames visited: {now:6.0f} MB ({now - start:+.0f} MB), "
                          f"{1e3 * (time.perf_counter() - t0) / k:.0f} ms per frame")
            app.close_session(tab)
            gc.collect()
            after = rss_mb()
            print(f"peak {peak:.0f} MB ({peak - start:+.0f} MB above the start; goal: at most +150 MB); "
                  f"after the tab left: {after:.0f} MB ({after - start:+.0f} MB)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
