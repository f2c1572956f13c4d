"""How soon the page shows a change, by the path it takes: a panel element against a scene node.

    python benchmarks/bench_page_paths.py [--frames 120] [--changes 20]

viser applies a batch of panel-only messages as it arrives, and a batch that touches the 3D scene
inside the next render frame (software WebGL on this machine: 70-200 ms a frame). This measures
both paths in the app as it runs (``pnlviz serve`` on a synthetic set, its background pass
working, headless Chromium at 1600x900 with the flags of the browser tests): the server changes
either a panel HTML block's colour or the visibility of the frame's pitch overlay, alternately,
and the time runs from the server's change to the first frame Chromium composites showing it as
it ends up (its screencast, as ``bench_app_browser.py`` measures). It says what a layer drawn by
the page itself (fed through a panel element, as the busy cue is) would cost against a scene
layer; nothing in the app is changed. Prints p50/p95 of each and the load average. A third kind
changes both in one message batch and says whether the page shows them in the same frame (what
a layer drawn by the page needs to stay on the scene's image).
"""

from __future__ import annotations

import argparse
import os
import resource
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_app_browser import Screencast, percentiles, served_page  # noqa: E402

BLOCK = '<div id="bench-block" style="width:300px;height:40px;background:{}"></div>'


def shown_after(cast: Screencast, n0: int, t0: float, region) -> float | None:
    """ms from ``t0`` (wall clock, s) to the first frame after it showing ``region`` as it ends up."""
    frames = [f for f in cast.frames[n0:] if f[0] >= t0 - 0.001]
    if not frames:
        return None
    final = cast.crop(frames[-1][1], region)
    return next((1e3 * (t - t0) for t, d in frames if np.mean(np.abs(cast.crop(d, region) - final)) < 1.5), None)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=120, help="synthetic frames in the set served")
    ap.add_argument("--changes", type=int, default=20, help="changes of each kind")
    args = ap.parse_args()

    with served_page(args.frames) as (app, page, _):
        time.sleep(3)
        session = app.tabs()[0]
        block = session.client.gui.add_html(BLOCK.format("#ff0000"))
        page.locator("#bench-block").scroll_into_view_if_needed()
        time.sleep(1)
        box = page.locator("#bench-block").bounding_box()
        canvas = max((c.bounding_box() for c in page.locator("canvas[data-engine]").all()),
                     key=lambda b: b["width"] * b["height"])  # the viewer's (three.js marks it)
        regions = {"panel": (box["x"], box["y"], box["width"], box["height"]),
                   "scene": (canvas["x"], canvas["y"], canvas["width"], canvas["height"])}
        layer = session.workspace._lines.get("refined_pitch")
        if layer is None:
            raise SystemExit("the first frame shows no pitch overlay to toggle")
        cast = Screencast(page)
        cast.wait(1.0)
        times: dict[str, list[float | None]] = {"panel": [], "scene": []}
        lags: list[float] = []  # both in one batch: the scene's first frame minus the panel's, ms
        blue = False
        for i in range(3 * args.changes):
            kind = ("panel", "scene", "both")[i % 3]
            n0, t0 = len(cast.frames), time.time()
            with session.client.atomic():
                if kind in ("panel", "both"):
                    blue = not blue
                    block.content = BLOCK.format("#0000ff" if blue else "#ff0000")
                if kind in ("scene", "both"):
                    layer.visible = not layer.visible
            cast.wait(1.2)
            if kind == "both":
                panel, scene = (shown_after(cast, n0, t0, regions[k]) for k in ("panel", "scene"))
                if panel is not None and scene is not None:
                    lags.append(scene - panel)
            else:
                times[kind].append(shown_after(cast, n0, t0, regions[kind]))
    print(f"{args.frames} synthetic frames served, background pass running; load average {os.getloadavg()[0]:.1f}")
    for kind, label in (("panel", "a panel element changed"), ("scene", "a pitch layer shown/hidden")):
        print(f"{label} -> on screen: {percentiles(times[kind])}")
    same = sum(abs(v) < 1.0 for v in lags)
    print(f"both in one message batch: shown in the same frame {same} of {len(lags)} times; scene after panel by "
          f"{', '.join(f'{v:.0f}' for v in sorted(lags))} ms")
    print(f"peak memory of this process (server included): "
          f"{resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB")


if __name__ == "__main__":
    main()
