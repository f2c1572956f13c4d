"""What one frame of the image view costs the browser, and what of it is the image itself.

    python benchmarks/bench_frame_cost.py [--frames 20] [--seconds 4] [--rounds 2]

viser renders on demand: every change opens a 250 ms window of frames drawn back to back. In
software WebGL (SwiftShader, headless Chromium with the flags of the browser tests, 1600x900) a
frame is filled pixel by pixel and read back for compositing, so a change reaches the screen
one to three frames after it arrives, and the frame's cost sets the latency of every action.
This keeps the page rendering for ``--seconds`` (the server shows and hides the invisible
surface around the frame every 150 ms: a scene change viser draws, as every change of the scene
is; the overlays are the page's since 2026-12-06 and no longer make viser draw) and prints the
mean interval between the page's animation frames: as the app runs, then
with the frame's image hidden (what drawing the image's pixels costs), alternately for
``--rounds`` rounds. The app is served on a ``pnlviz synth`` set with its background pass
working, as ``pnlviz serve`` runs; nothing in the app is changed but the image's visibility (the page's frame layer,
``pnlviz/app/pageframes.js``: since 2026-12-06 the page draws the image behind the canvas).
"""

from __future__ import annotations

import argparse
import resource
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_app_browser import served_page  # noqa: E402

#: the page notes when each animation frame starts (before the page's own callbacks run)
FRAMES = """() => { if (window.__frames) return; window.__frames = [];
  const raf = window.requestAnimationFrame.bind(window);
  window.requestAnimationFrame = (cb) => raf((t) => { window.__frames.push(t); cb(t); });
}"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=20, help="synthetic frames in the set served")
    ap.add_argument("--seconds", type=float, default=4.0, help="rendering time per measurement")
    ap.add_argument("--rounds", type=int, default=2)
    args = ap.parse_args()

    with served_page(args.frames, f"({FRAMES})()") as (app, page, _):
        time.sleep(5)  # the first frame's nodes made
        tab = app.tabs()[0]
        backdrop = tab.workspace._pick["backdrop"]  # the invisible surface around the frame (takes pans)

        def image(visible: bool) -> None:  # the page's frame layer (pnlviz/app/pageframes.js)
            page.evaluate(f"() => {{ document.getElementById('pnlviz-frames').style.visibility = "
                          f"'{'visible' if visible else 'hidden'}'; }}")

        def interval() -> tuple[float, int]:
            page.evaluate("() => { window.__frames = []; }")
            for i in range(int(args.seconds / 0.15)):
                tab.queue.enqueue(lambda on=i % 2 == 0: setattr(backdrop, "visible", on))
                page.wait_for_timeout(150)
            t = np.array(page.evaluate("() => window.__frames"))
            return float(np.mean(np.diff(t))), len(t)

        rows: dict[str, list[tuple[float, int]]] = {"as the app runs": [], "the image hidden": []}
        for _ in range(args.rounds):
            rows["as the app runs"].append(interval())
            image(False)
            page.wait_for_timeout(600)
            rows["the image hidden"].append(interval())
            image(True)
            page.wait_for_timeout(600)
        canvas = tab.view_control.canvas
    with open("/proc/loadavg") as f:
        load = f.read().split()[0]
    print(f"canvas {canvas[0]}x{canvas[1]} CSS px; load average {load}")
    for name, got in rows.items():
        ms = ", ".join(f"{m:.0f}" for m, _ in got)
        print(f"{name}: mean frame interval {np.mean([m for m, _ in got]):.0f} ms (rounds: {ms}; "
              f"{sum(n for _, n in got)} frames)")
    print(f"peak memory of this process (server + benchmark): "
          f"{resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB")


if __name__ == "__main__":
    main()
