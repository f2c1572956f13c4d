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
    p.add_argument("--weights-kp", type=Path, help="keypoint network checkpoint: detect in the app (background)")
    p.add_argument("--weights-lines", type=Path, help="line network checkpoint: detect in the app (background)")
    p.add_argument("--no-detect", action="store_true",
                   help="do not run the light default detector (assets/models/light.pt) on frames without detections")
    p.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1: this machine only)")
    p.add_argument("--port", type=int, default=8080)
    p.add_argument("--size", type=parse_size, default=(960, 540), help="image size for frames without an image")
    p.set_defaults(func=run_serve)


def run_serve(args) -> int:
    from pnlviz import EXAMPLES_DIR
    from pnlviz.app.server import PnlvizApp
    from pnlviz.app.state import AppState

    data = args.data or EXAMPLES_DIR / "sample"
    detector, source = None, None
    if args.weights_kp or args.weights_lines:
        from pnlviz.detect.checkpoint import CheckpointError
        from pnlviz.detect.run import Detector

        try:
            detector = Detector.from_weights(args.weights_kp, args.weights_lines)
        except CheckpointError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
    elif not args.no_detect and not args.detections:
        from pnlviz.detect.default import DEFAULT_MODEL, DeferredDetector

        if DEFAULT_MODEL.is_file():  # the light default model: detections to look at, annotations still lead
            detector, source = DeferredDetector(), "annotation"
    state = AppState(data, detections=args.detections, edits=args.edits, size=args.size, detector=detector,
                     source=source)
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


def add_export_parser(sub) -> None:
    from pnlviz.cli import parse_size

    p = sub.add_parser("export", help="export corrected training labels (as the app's export button)",
                       description="Write the corrected labels of a dataset and its edits: SoccerNet annotations, "
                                   "keypoint labels, cameras, COCO keypoints and a manifest of what changed. "
                                   "Only accepted and corrected frames unless --all.")
    p.add_argument("--data", type=Path, help="dataset folder or zip (default: the bundled sample)")
    p.add_argument("--edits", type=Path, help="edits folder (default: <data>.edits beside the data)")
    p.add_argument("--detections", type=Path, help="PnLCalib 2D prediction zip, as given to pnlviz serve")
    p.add_argument("--out", required=True, type=Path, help="output folder, or a .zip")
    p.add_argument("--all", action="store_true", help="export every frame, reviewed or not")
    p.add_argument("--size", type=parse_size, default=(960, 540), help="image size for frames without an image")
    p.set_defaults(func=run_export)


def run_export(args) -> int:
    from pnlviz import EXAMPLES_DIR
    from pnlviz.app.export import write_export
    from pnlviz.app.state import AppState

    data = args.data or EXAMPLES_DIR / "sample"
    if args.out.resolve() == Path(data).resolve():
        print(f"error: --out {args.out} is the dataset itself; export writes beside it, never over it", file=sys.stderr)
        return 2
    state = AppState(data, detections=args.detections, edits=args.edits, size=args.size)
    n = write_export(state, args.out, include_all=args.all)
    which = "frames" if args.all else "accepted/corrected frames"
    print(f"exported {n} {which} of {len(state.stems)} to {args.out}")
    return 0
