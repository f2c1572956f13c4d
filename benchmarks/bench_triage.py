"""Triage on an image-only folder: the app's background pass (the light default model detects,
every frame is calibrated, summaries kept) on the 93 real WC14 test-half images at 1280x720, as
``pnlviz serve --data FOLDER`` runs it.

    python benchmarks/bench_triage.py [--keep DIR]

Prints the pass's time and peak memory (the app's process, and the detector's), checks that
*failed* then lists exactly the frames without a camera (each frame calibrated again here,
independently of the pass), and times a second opening of the folder, which resumes from the
cache beside the edits. Needs ``../shared/data/wc14_real/test_half_256``.
"""

from __future__ import annotations

import argparse
import resource
import shutil
import sys
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_gate import IMAGES, SIZE, resized, work_folder  # noqa: E402

from pnlviz.app.frameorder import visible_order  # noqa: E402
from pnlviz.app.modes import Filter, Sort  # noqa: E402
from pnlviz.app.state import AppState  # noqa: E402
from pnlviz.detect.worker import DetectorProcess  # noqa: E402
from pnlviz.pipeline import frame_view  # noqa: E402


def opened(frames: Path, edits: Path) -> AppState:
    """The folder as ``pnlviz serve`` opens it: the light default model in its process, one thread."""
    detector = DetectorProcess(threads=1)
    detector.warm_up()
    return AppState(frames, edits=edits, detector=detector, source="annotation")


def main() -> None:
    args, tmp = work_folder(argparse.ArgumentParser(description=__doc__.splitlines()[0]), "pnlviz-triage-")
    try:
        frames, edits = tmp / "frames", tmp / "frames.edits"
        shutil.rmtree(edits, ignore_errors=True)
        n = resized(IMAGES, frames) if not frames.is_dir() else len(list(frames.glob("*.jpg")))
        lines: list[str] = []
        st = opened(frames, edits)
        try:
            t0 = time.perf_counter()
            progress = st.triage.run(threading.Event(), lines.append)
            dt = time.perf_counter() - t0
            last_line = lines[-1]
            peak_app = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
            summaries = st.triage.summaries()
            failed = [st.stems[i] for i in visible_order(st.stems, summaries, st.edits.review, Filter.FAILED,
                                                         Sort.INDEX)]
            views_kept = len(st._cache)
            no_camera = []
            for stem in st.stems:  # independently: each frame calibrated again, not through the pass
                view = frame_view(st.reader, stem, st.default_settings, st.model)
                if view.result is None or not view.result.ok:
                    no_camera.append(stem)
        finally:
            st.close()
        peak_detector = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
        st = opened(frames, edits)
        try:
            t0 = time.perf_counter()
            again = st.triage.run(threading.Event(), lines.append)
            dt_again = time.perf_counter() - t0
        finally:
            st.close()
        print(f"{n} real WC14 test-half frames at {SIZE[0]}x{SIZE[1]}, images only; the light default model")
        print(f"background pass: {dt:.1f} s ({1e3 * dt / n:.0f} ms per frame: detection + calibration), "
              f"peak memory: app process {peak_app:.0f} MB, detector process {peak_detector:.0f} MB; "
              f"views kept in memory afterwards: {views_kept}")
        print(f"progress line at the end: {last_line!r}")
        print(f"summaries: {len(summaries)} of {n}; failed: {len(failed)} frames; without a camera (checked "
              f"here): {len(no_camera)}; the same frames: {failed == no_camera}" + (f" {failed}" if failed else ""))
        print(f"second opening (resumed from the cache): {dt_again:.2f} s, {again.detected} frames detected again")
        if failed != no_camera or len(summaries) != n or not progress.finished:
            raise SystemExit("failed does not list exactly the frames without a camera")
    finally:
        if args.keep is None:
            shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
