"""``pnlviz serve``."""

from __future__ import annotations

import signal
import sys
import time
from pathlib import Path
from pnlviz.commands.common import add_output_options, int_at_least


def add_serve_parser(sub) -> None:
    from pnlviz.commands.common import add_app_data_args

    p = sub.add_parser("serve", help="the web app: inspect calibrations, review frames",
                       description="Serve the pnlviz app (viser) on a dataset; without --data, the bundled "
                                   "sample. Edits and review statuses are saved at once "
                                   "in an edits folder beside the data (never over it).")
    add_app_data_args(p)
    p.add_argument("--video", type=Path, help="a video file (mp4, ...) instead of --data: its frames are decoded when "
                                              "shown, detected and calibrated in the background, and corrected as "
                                              "one clip under its shot model (edits in <video>.edits beside it)")
    p.add_argument("--weights-kp", type=Path, help="keypoint network checkpoint: detect in the app (background)")
    p.add_argument("--weights-lines", type=Path, help="line network checkpoint: detect in the app (background)")
    p.add_argument("--weights", type=Path, default=None,
                   help="a light model from pnlviz train (LightNet checkpoint + sidecar) instead of the shipped one")
    p.add_argument("--no-detect", action="store_true",
                   help="do not run the light default detector (shipped with pnlviz) on frames without detections")
    p.add_argument("--host", default="127.0.0.1",
                   help="address to bind (default 127.0.0.1: this machine only; any other address needs a token)")
    p.add_argument("--port", type=int_at_least(0, 65535), default=8080)
    p.add_argument("--token", help="access token for a non-loopback --host (default: a new random one, printed in "
                                   "the URL)")
    p.add_argument("--allow-host", action="append", default=[], metavar="NAME",
                   help="another host name the browser may use for this server (e.g. behind a proxy); repeatable")
    p.add_argument("--detector-threads", type=int_at_least(1, 256), default=1,
                   help="torch threads of the background detector process (default 1: the app keeps a core)")
    add_output_options(p)
    p.set_defaults(func=run_serve)


def _detector(args):
    """The background detector (in its own process: this one never imports torch), or None."""
    from pnlviz.detect.default import DEFAULT_MODEL, torch_missing
    from pnlviz.detect.worker import DetectorLoadError, DetectorProcess

    missing = torch_missing()
    if args.weights_kp or args.weights_lines or args.weights:
        if missing:
            raise DetectorLoadError(missing)
        return DetectorProcess(args.weights_kp, args.weights_lines, threads=args.detector_threads, light=args.weights)
    if not args.no_detect and not args.detections and DEFAULT_MODEL.is_file():
        if missing:
            print(f"pnlviz: no background detection ({missing}); frames are calibrated from their labels",
                  file=sys.stderr)
            return None
        return DetectorProcess(threads=args.detector_threads)
    return None


def _quiet_handshakes() -> None:
    """A connection that never speaks HTTP (a port scan, a health check, a TLS client) is not an
    error of the app: websockets logs its failed handshake with three chained tracebacks; drop
    those records (everything else the library logs is kept)."""
    import logging

    def keep(record: logging.LogRecord) -> bool:
        return not str(record.msg).startswith(("opening handshake failed", "connection rejected"))

    for name in ("websockets.server", "websockets.asyncio.server", "websockets"):
        logging.getLogger(name).addFilter(keep)


def run_serve(args) -> int:
    from pnlviz.app.server import PnlvizApp
    from pnlviz.app.state import AppState
    from pnlviz.commands.common import app_data
    from pnlviz.data.edits import EditsFolderError
    from pnlviz.detect.worker import DetectorLoadError, DetectorProcessError

    if args.video is not None and args.data is not None:
        print("error: --video goes instead of --data", file=sys.stderr)
        return 2
    data, args.edits = (args.video, args.edits) if args.video is not None else app_data(args)
    signal.signal(signal.SIGTERM, _interrupt)  # `kill` stops it as Ctrl+C does (edits folder released), from now on
    _quiet_handshakes()
    try:
        detector = _detector(args)
    except DetectorLoadError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if detector is not None and (not detector.light or args.weights is not None):
        print("pnlviz: loading the detector's checkpoints...", flush=True)
        try:  # a checkpoint that does not fit is an error now, not on the first frame
            detector.load()
        except (DetectorLoadError, DetectorProcessError) as exc:
            detector.close()
            print(f"error: {exc}", file=sys.stderr)
            return 2
    # the light default model adds detections to look at; annotations stay the source
    source = "annotation" if detector is not None and detector.light else None
    try:
        state = AppState(data, detections=args.detections, edits=args.edits, size=args.size, detector=detector,
                         source=source, force_edits=args.force_edits, detector_settings=args.detector_settings)
    except EditsFolderError as exc:
        if detector is not None:
            detector.close()
        print(f"error: {exc}", file=sys.stderr)
        return 2
    try:
        app = PnlvizApp(state, host=args.host, port=args.port, token=args.token, allowed_hosts=tuple(args.allow_host))
    except BaseException:
        state.close()
        raise
    if detector is not None and detector.light:
        detector.warm_up()  # torch and the weights load in the detector process while the browser connects
    _announce(args, data, state, app)
    try:
        while True:
            time.sleep(1.0)
    except KeyboardInterrupt:
        print("pnlviz: stopped", file=sys.stderr)
    finally:
        app.stop()
        state.close()
    return 0


def _announce(args, data, state, app) -> None:
    """Say what is served, where its edits go, the warnings, and the addresses to open."""
    from pnlviz.app.guard import is_loopback

    urls = app.page_urls()  # the canvas at the page's device pixel ratio, never lowered
    state.edits.describe_holder(urls[0])
    print(f"pnlviz: {data} ({len(state.stems)} frames), edits in {state.edits.root}")
    for warning in state.problems + state.edits.warnings:
        print(f"pnlviz: warning: {warning}", file=sys.stderr)
    if app.policy.port != args.port:
        print(f"pnlviz: port {args.port} is busy, using {app.policy.port}")
    if not is_loopback(args.host):
        print(f"pnlviz: warning: listening on {args.host}: anyone who can reach this machine and has the token can "
              f"read and edit these labels", file=sys.stderr)
    print(f"pnlviz: open {urls[0]}" + "".join(f"\npnlviz:   or {u}" for u in urls[1:]), flush=True)


#: seconds a stop asked by SIGTERM may take before the process ends anyway
STOP_WITHIN_S = 5.0


def _interrupt(signum, frame) -> None:
    """SIGTERM: stop as Ctrl+C does, and end the process anyway after :data:`STOP_WITHIN_S`
    should the stop hang (records are written atomically and the folder's lock goes with the
    process: nothing is lost)."""
    import os
    import threading

    timer = threading.Timer(STOP_WITHIN_S, lambda: os._exit(143))
    timer.daemon = True
    timer.start()
    raise KeyboardInterrupt
