"""Server-side latency of an edit in the app: keypoint moved -> frame recalibrated -> overlay
geometry computed (what happens between a drag's release and the update sent to the browser;
``benchmarks/bench_app_browser.py`` measures the whole way to the screen).

    python benchmarks/bench_app.py [--data examples/sample]

Edits go to a temporary folder. Prints median and p90 in ms, and the peak memory.
"""

from __future__ import annotations

import argparse
import resource
import tempfile
import time
from pathlib import Path

import numpy as np

from pnlviz import EXAMPLES_DIR
from pnlviz.app.overlay import Layers, overlay_geometry
from pnlviz.app.state import AppState


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=EXAMPLES_DIR / "sample")
    ap.add_argument("--open-frames", type=int, default=23000,
                    help="also time opening a folder of this many annotation files (SN23-sized)")
    args = ap.parse_args()
    if args.open_frames:
        big = Path(tempfile.mkdtemp()) / "big"
        big.mkdir()
        text = (EXAMPLES_DIR / "sample" / "sn22_00004.json").read_text()
        for i in range(args.open_frames):
            (big / f"{i:05d}.json").write_text(text)
        t0 = time.perf_counter()
        big_state = AppState(big, edits=big.parent / "edits")
        t1 = time.perf_counter()
        big_state.view(big_state.stems[big_state.first_index])
        print(f"open a {args.open_frames}-frame folder: {1e3 * (t1 - t0):.0f} ms, first frame shown "
              f"{1e3 * (time.perf_counter() - t1):.0f} ms later; peak memory so far "
              f"{resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB")
    t0 = time.perf_counter()
    st = AppState(args.data, edits=Path(tempfile.mkdtemp()) / "edits")
    print(f"open {args.data}: {1e3 * (time.perf_counter() - t0):.1f} ms ({len(st.stems)} frames)")
    calib, total = [], []
    rng = np.random.default_rng(0)
    for stem in st.stems:
        v = st.view(stem)
        if v.observations is None or not v.observations.n_keypoints or v.result is None or not v.result.ok:
            continue
        i = int(rng.integers(v.observations.n_keypoints))
        kid, (x, y) = int(v.observations.kp_ids[i]), v.observations.kp_xy[i]
        t0 = time.perf_counter()
        st.move_keypoint(stem, kid, x + 3.0, y - 2.0)  # autosave included
        t1 = time.perf_counter()
        view = st.view(stem)
        t2 = time.perf_counter()
        overlay_geometry(view, Layers(), st.model)
        t3 = time.perf_counter()
        calib.append(1e3 * (t2 - t0))
        total.append(1e3 * (t3 - t0))
    print(f"edit + autosave + recalibration: median {np.median(calib):.1f} ms, p90 {np.percentile(calib, 90):.1f} ms "
          f"({len(calib)} edits)")
    print(f"... + overlay geometry: median {np.median(total):.1f} ms, p90 {np.percentile(total, 90):.1f} ms")
    print(f"peak memory (ru_maxrss): {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB")


if __name__ == "__main__":
    main()
