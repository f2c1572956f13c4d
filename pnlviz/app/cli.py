"""``pnlviz serve``."""

from __future__ import annotations

import sys
import time
from pathlib import Path


def add_serve_parser(sub) -> None:
    from pnlviz.cli import parse_size

    p = sub.add_parser("serve", help="the web app: inspect calibrations, review frames",
                       description="Serve the pnlviz app (viser) on a dataset; without --data, the bundled "
                                   "sample in examples/sample. Edits and review statuses are saved at once "
                                   "in an edits folder beside the data (never over it).")
    p.add_argument("--data", type=Path, help="dataset folder or zip (default: the bundled sample)")
    p.add_argument("--detections", type=Path, help="PnLCalib 2D prediction zip")
    p.add_argument("--edits", type=Path, help="edits folder (default: <data>.edits beside the data)")
    p.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1: this machine only)")
    p.add_argument("--port", type=int, default=8080)
    p.add_argument("--size", type=parse_size, default=(960, 540), help="image size for frames without an image")
    p.set_defaults(func=run_serve)


def run_serve(args) -> int:
    from pnlviz import EXAMPLES_DIR
    from pnlviz.app.server import PnlvizApp
    from pnlviz.app.state import AppState

    data = args.data or EXAMPLES_DIR / "sample"
    state = AppState(data, detections=args.detections, edits=args.edits, size=args.size)
    app = PnlvizApp(state, host=args.host, port=args.port)
    print(f"pnlviz: {data} ({len(state.stems)} frames), edits in {state.edits.root}")
    print(f"pnlviz: open {app.url}", flush=True)
    try:
        while True:
            time.sleep(1.0)
    except KeyboardInterrupt:
        print("pnlviz: stopped", file=sys.stderr)
    finally:
        app.stop()
    return 0
